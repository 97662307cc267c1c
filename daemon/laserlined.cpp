// laserlined: the laser line scanner daemon. Grabs frames, switches the laser, extracts the
// laser line and publishes profiles, raw frames and status over LCM until SIGINT/SIGTERM.
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>

#include "daemon/backends.hpp"
#include "daemon/config.hpp"
#include "daemon/cpu_usage.hpp"
#include "daemon/frame_path.hpp"
#include "daemon/service_notifier.hpp"
#include "daemon/thread_priorities.hpp"
#include "hal/clock.hpp"

namespace {

using laserline::daemon::Backends;
using laserline::daemon::DaemonConfig;

constexpr const char* kUsage =
    "usage: laserlined [--config FILE] [--duration SECONDS] [--check-config]\n"
    "                  [--print-default-config] [--help] [--version]\n"
    "  --config FILE          YAML configuration (default: built-in, the simulated scanner)\n"
    "  --duration SECONDS     stop by itself after this long (default: until SIGINT/SIGTERM)\n"
    "  --check-config         validate the configuration and backends, then exit\n"
    "  --print-default-config print the built-in configuration and exit\n";

struct Options {
  std::optional<std::string> config_path;
  double duration_s = 0;  // 0 = run until signalled
  bool check_only = false;
};

// The laser of this process, for the fatal-signal handler: a crash must not leave it on.
laserline::hal::Laser* g_laser = nullptr;

void fatal_signal_handler(int sig) {
  if (g_laser != nullptr) g_laser->set(false, 0, nullptr);
  signal(sig, SIG_DFL);
  raise(sig);
}

[[noreturn]] void usage_error(const std::string& message) {
  std::fprintf(stderr, "laserlined: %s\n%s", message.c_str(), kUsage);
  std::exit(2);
}

Options parse_args(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](const char* flag) -> std::string {
      if (i + 1 >= argc) usage_error(std::string(flag) + ": missing value");
      return argv[++i];
    };
    if (arg == "--config") {
      o.config_path = value("--config");
    } else if (arg == "--duration") {
      const std::string text = value("--duration");
      char* end = nullptr;
      errno = 0;
      o.duration_s = std::strtod(text.c_str(), &end);
      if (errno != 0 || end == text.c_str() || *end != '\0' || !std::isfinite(o.duration_s) ||
          o.duration_s <= 0) {
        usage_error("--duration: expected a number of seconds > 0, got '" + text + "'");
      }
    } else if (arg == "--check-config") {
      o.check_only = true;
    } else if (arg == "--print-default-config") {
      std::fputs(laserline::daemon::builtin_config_text(), stdout);
      std::exit(0);
    } else if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    } else if (arg == "--version") {
      std::puts("laserlined " LASERLINE_VERSION);
      std::exit(0);
    } else {
      usage_error("unknown argument '" + arg + "'");
    }
  }
  return o;
}

// How often the human health line goes to stdout (the journal, under systemd).
constexpr std::int64_t kJournalPeriodNs = 5'000'000'000;
constexpr std::int64_t kStatusPeriodNs = 1'000'000'000;

// One line of health for people: systemd's STATUS= and, every few seconds, the journal.
class HealthLine {
 public:
  std::string update(const laserline::daemon::FramePath& path, bool laser_on, std::int64_t now_ns) {
    const auto& c = path.counters();
    const std::int64_t processed = c.frames_processed.load(std::memory_order_relaxed);
    const double seconds = static_cast<double>(now_ns - last_ns_) * 1e-9;
    const double rate =
        seconds > 0 ? static_cast<double>(processed - last_processed_) / seconds : 0;
    last_ns_ = now_ns;
    last_processed_ = processed;
    char line[320];
    std::snprintf(
        line, sizeof line,
        "camera %s, %.1f frames/s, %lld processed, %lld dropped, %lld over budget, %lld grab "
        "timeouts, %lld grab errors, laser %s, CPU %.0f%%",
        laserline::daemon::to_string(c.camera_state.load(std::memory_order_relaxed)), rate,
        static_cast<long long>(processed),
        static_cast<long long>(c.frames_dropped.load(std::memory_order_relaxed)),
        static_cast<long long>(c.frames_over_budget.load(std::memory_order_relaxed)),
        static_cast<long long>(c.grab_timeouts.load(std::memory_order_relaxed)),
        static_cast<long long>(c.grab_errors.load(std::memory_order_relaxed)),
        laser_on ? "on" : "off", cpu_.percent_since_last());
    return line;
  }

 private:
  std::int64_t last_ns_ = laserline::hal::monotonic_ns();
  std::int64_t last_processed_ = 0;
  laserline::daemon::CpuUsage cpu_;
};

}  // namespace

int main(int argc, char** argv) {
  // Stop signals are taken synchronously by the main thread; every thread started later inherits
  // the mask, so no frame-path thread is ever interrupted by them.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  signal(SIGPIPE, SIG_IGN);

  const Options options = parse_args(argc, argv);
  setvbuf(stdout, nullptr, _IOLBF, 0);

  DaemonConfig config;
  Backends backends;
  try {
    config = options.config_path ? laserline::daemon::load_config_file(*options.config_path)
                                 : laserline::daemon::builtin_config();
    backends = laserline::daemon::create_backends(config);
  } catch (const laserline::hal::ConfigError& e) {
    std::fprintf(stderr, "laserlined: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "laserlined: %s: %s\n", config.source.c_str(), e.what());
    return 2;
  }
  if (options.check_only) {
    std::printf("laserlined: %s: configuration is valid\n", config.source.c_str());
    return 0;
  }

  lcm::LCM lcm(config.lcm_url);
  if (!lcm.good()) {
    std::fprintf(stderr, "laserlined: %s: lcm.url: cannot open '%s'\n", config.source.c_str(),
                 config.lcm_url.c_str());
    return 2;
  }

  if (config.realtime && mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
    // Page faults on the frame path would defeat the priorities.
    std::fprintf(stderr,
                 "laserlined: %s: realtime.enabled: cannot lock memory: %s (needs "
                 "LimitMEMLOCK=infinity or CAP_IPC_LOCK)\n",
                 config.source.c_str(), std::strerror(errno));
    return 1;
  }
  if (config.realtime) {
    // Ask for the highest priority of the table once, here, so that a refusal stops us before
    // any hardware is opened; the main thread then returns to normal scheduling.
    sched_param rt{};
    rt.sched_priority = laserline::daemon::kCameraThread.fifo_priority;
    if (const int e = pthread_setschedparam(pthread_self(), SCHED_FIFO, &rt); e != 0) {
      std::fprintf(stderr,
                   "laserlined: %s: realtime.enabled: SCHED_FIFO priority %d refused: %s (needs "
                   "CAP_SYS_NICE or LimitRTPRIO)\n",
                   config.source.c_str(), rt.sched_priority, std::strerror(e));
      return 1;
    }
    const sched_param normal{};
    pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);
  }

  g_laser = backends.laser.get();
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT})
    signal(sig, fatal_signal_handler);

  std::string error;
  if (!backends.laser->open(&error)) {
    std::fprintf(stderr, "laserlined: laser (%s): %s\n", config.laser_backend.c_str(),
                 error.c_str());
    return 1;
  }
  if (!backends.camera->open(&error)) {
    std::fprintf(stderr, "laserlined: camera (%s): %s\n", config.camera_backend.c_str(),
                 error.c_str());
    return 1;
  }
  laserline::daemon::FramePath path(config, *backends.camera, *backends.laser, *backends.detector,
                                    lcm);
  if (!path.start(&error)) {
    std::fprintf(stderr, "laserlined: %s: %s\n", config.source.c_str(), error.c_str());
    return 1;
  }
  const auto format = backends.camera->format();
  std::printf("laserlined: running %s camera %dx%d at %.1f Hz, detector %s, laser %s, LCM %s\n",
              config.camera_backend.c_str(), format.width, format.height, config.frame_rate_hz,
              config.detector.c_str(), config.laser_backend.c_str(), config.lcm_url.c_str());

  const std::int64_t start = laserline::hal::monotonic_ns();
  const auto duration_ns = static_cast<std::int64_t>(options.duration_s * 1e9);
  const char* reason = "duration elapsed";
  laserline::daemon::ServiceNotifier notifier;
  HealthLine health;
  std::int64_t next_status = start + kStatusPeriodNs;
  std::int64_t next_journal = start + kJournalPeriodNs;
  while (true) {
    const timespec tick{0, 50'000'000};
    const int sig = sigtimedwait(&stop_signals, nullptr, &tick);
    if (sig > 0) {
      reason = sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "SIGHUP";
      break;
    }
    path.enforce_laser_safety();
    // systemd: ready once the camera streams and a frame went through; the watchdog is fed only
    // while frames keep being processed.
    const std::int64_t now = laserline::hal::monotonic_ns();
    const std::int64_t processed = path.counters().frames_processed.load(std::memory_order_relaxed);
    if (processed > 0) {
      notifier.ready("streaming, " + std::to_string(processed) + " frames processed");
    }
    notifier.progress(processed, now);
    if (now >= next_status) {
      const std::string line = health.update(path, backends.laser->is_on(), now);
      notifier.status(line);
      if (now >= next_journal) {
        std::printf("laserlined: %s\n", line.c_str());
        next_journal = now + kJournalPeriodNs;
      }
      next_status = now + kStatusPeriodNs;
    }
    if (path.source_ended()) {
      reason = "end of recording";
      break;
    }
    if (duration_ns > 0 && laserline::hal::monotonic_ns() - start >= duration_ns) break;
  }
  notifier.stopping(std::string("stopping (") + reason + ")");
  path.stop();
  backends.laser->set(false, 0, nullptr);

  const auto s = path.summary();
  std::printf(
      "laserlined: stopped (%s) after %.1f s: %lld frames captured, %lld processed, %lld dropped, "
      "%lld profiles published, %lld raw frames published; latency exposure->published p50 %.2f "
      "ms p99 %.2f ms max %.2f ms, arrival->published p50 %.2f ms p99 %.2f ms max %.2f ms, over "
      "%lld frames\n",
      reason, static_cast<double>(laserline::hal::monotonic_ns() - start) * 1e-9,
      static_cast<long long>(s.frames_captured), static_cast<long long>(s.frames_processed),
      static_cast<long long>(s.frames_dropped), static_cast<long long>(s.profiles_published),
      static_cast<long long>(s.images_published), s.latency.p50_ms, s.latency.p99_ms,
      s.latency.max_ms, s.pipeline.p50_ms, s.pipeline.p99_ms, s.pipeline.max_ms,
      static_cast<long long>(s.latency.samples));
  std::printf(
      "laserlined: laser %s: %lld switches, %lld came after their frame's exposure began, %lld "
      "forced off because frames stopped\n",
      config.laser_backend.c_str(), static_cast<long long>(s.laser_switches),
      static_cast<long long>(s.laser_late_switches), static_cast<long long>(s.laser_safety_offs));
  g_laser = nullptr;
  return 0;
}
