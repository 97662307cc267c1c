#pragma once

#include <time.h>

#include <algorithm>
#include <atomic>
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

// Sleeps until an absolute CLOCK_MONOTONIC time, in slices so that `stopped` is noticed quickly
// (a camera's stop() from another thread). False when stopped first.
inline bool sleep_until(std::int64_t deadline_ns, const std::atomic<bool>& stopped) {
  constexpr std::int64_t kSlice = 20'000'000;
  while (!stopped.load(std::memory_order_acquire)) {
    const std::int64_t now = monotonic_ns();
    if (now >= deadline_ns) return true;
    const std::int64_t until = std::min(deadline_ns, now + kSlice);
    const timespec ts{static_cast<time_t>(until / 1'000'000'000),
                      static_cast<long>(until % 1'000'000'000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
  }
  return false;
}

}  // namespace laserline::hal
