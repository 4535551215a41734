#pragma once

namespace animspace::server {

// Semantic version of animspaced, reported by GetServerInfo and --version.
inline constexpr const char* kServerVersion = "0.1.0";

}  // namespace animspace::server
