// Wall-clock seconds for reports and benchmarks (steady clock: immune to clock changes).
#pragma once

#include <chrono>

namespace animspace {

inline double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace animspace
