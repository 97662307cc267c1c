#pragma once

#include <sys/resource.h>

#include <cstdint>

#include "hal/clock.hpp"

namespace laserline::daemon {

// CPU time of the whole process (all threads, user + system) over wall time since the previous
// call, in percent of one core (200 = two cores busy). Thread context: one thread per instance.
class CpuUsage {
 public:
  CpuUsage() { sample(&last_cpu_ns_, &last_wall_ns_); }

  double percent_since_last() {
    std::int64_t cpu = 0, wall = 0;
    sample(&cpu, &wall);
    const std::int64_t dwall = wall - last_wall_ns_;
    const double percent =
        dwall > 0 ? 100.0 * static_cast<double>(cpu - last_cpu_ns_) / static_cast<double>(dwall)
                  : 0.0;
    last_cpu_ns_ = cpu;
    last_wall_ns_ = wall;
    return percent;
  }

 private:
  static void sample(std::int64_t* cpu_ns, std::int64_t* wall_ns) {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    auto ns = [](const timeval& t) {
      return static_cast<std::int64_t>(t.tv_sec) * 1'000'000'000 +
             static_cast<std::int64_t>(t.tv_usec) * 1000;
    };
    *cpu_ns = ns(usage.ru_utime) + ns(usage.ru_stime);
    *wall_ns = hal::monotonic_ns();
  }

  std::int64_t last_cpu_ns_ = 0;
  std::int64_t last_wall_ns_ = 0;
};

}  // namespace laserline::daemon
