#pragma once

#include <time.h>

#include <cstdint>

namespace laserline::hal {

inline std::int64_t now_ns(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}
inline std::int64_t monotonic_ns() {
  return now_ns(CLOCK_MONOTONIC);
}
inline std::int64_t wall_ns() {
  return now_ns(CLOCK_REALTIME);
}

}  // namespace laserline::hal
