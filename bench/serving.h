// What the suites that drive a real animspaced share: waiting until it serves.
#pragma once

#include <chrono>
#include <string>

namespace animspace::bench {

// Polls the daemon's health until it reports SERVING (its repository is loaded) or `timeout`
// passes; true when it serves.
bool wait_until_serving(const std::string& address, std::chrono::seconds timeout = std::chrono::seconds(60));

}  // namespace animspace::bench
