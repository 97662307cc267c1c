// laserlined: the laser line scanner daemon. Grabs frames, switches the laser, extracts the
// laser line and publishes profiles, raw frames and status over LCM until a stop signal.
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "daemon/backends.hpp"
#include "daemon/command_server.hpp"
#include "daemon/config.hpp"
#include "daemon/cpu_usage.hpp"
#include "daemon/frame_path.hpp"
#include "daemon/lcm_publisher.hpp"
#include "daemon/log.hpp"
#include "daemon/service_notifier.hpp"
#include "daemon/thread_priorities.hpp"
#include "hal/clock.hpp"
#include "hal/exposure_strobe.hpp"
#include "tools/cli.hpp"

namespace {

using laserline::daemon::Backends;
using laserline::daemon::DaemonConfig;
using laserline::daemon::log;
using laserline::daemon::LogLevel;

constexpr const char* kUsage =
    "usage: laserlined [--config FILE] [--duration SECONDS] [--check-config [--probe]]\n"
    "                  [--laser-off] [--print-default-config] [--help] [--version]\n"
    "  --config FILE          YAML configuration (default: built-in, the simulated scanner)\n"
    "  --duration SECONDS     stop by itself after this long, 0.001 to 1e9 (default: until a\n"
    "                         stop signal)\n"
    "  --check-config         validate the configuration and its backends' options, then exit\n"
    "  --probe                with --check-config: also open the camera and the laser's GPIO\n"
    "                         line and report what was found (the laser stays as it is)\n"
    "  --laser-off            drive the configured laser line to off, release it and exit (for\n"
    "                         a supervisor once the daemon is gone: the unit's ExecStopPost=)\n"
    "  --print-default-config print the built-in configuration and exit\n";

// --duration's range: less than a millisecond is below the main loop's 50 ms look at the clock
// anyway; beyond 1e9 s (31 years) the count of nanoseconds nears its limit.
constexpr double kMinDurationS = 1e-3;
constexpr double kMaxDurationS = 1e9;

struct Options {
  std::optional<std::string> config_path;
  double duration_s = 0;  // 0 = run until signalled
  bool check_only = false;
  bool probe = false;    // --check-config also looks for the hardware
  bool offline = false;  // accepted for compatibility: the file alone, the default
  bool laser_off = false;
};

// The laser of this process, for the fatal-signal handler: a crash must not leave it on.
laserline::hal::Laser* g_laser = nullptr;

void fatal_signal_handler(int sig) {
  if (g_laser != nullptr) g_laser->set(false, 0, nullptr);
  signal(sig, SIG_DFL);
  raise(sig);
}

// What each signal of `kill -l` 1-31 does. SIGKILL and SIGSTOP cannot be caught: the unit's
// ExecStopPost= (laserlined --laser-off) and the watchdogs answer them (docs/operations.md).
//
// Faults: the kernel sends them to the thread that faulted and, were they blocked there, would
// kill the process without running anything; so they are never blocked, and their handler
// switches the laser off before the default action (a core dump) ends the process. SIGABRT is
// also what an uncaught exception ends in and systemd's WatchdogSignal; SIGTRAP is a breakpoint,
// SIGSYS a system call a seccomp filter forbids.
constexpr int kCrashSignals[] = {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS};
// Ignored on purpose:
//   SIGPIPE: a closed socket or pipe is an error of the write that met it (a counted publish
//            error), not a reason to stop;
//   SIGTTIN, SIGTTOU: a background job touching its terminal; their default action would freeze
//            the whole process, the laser's frame watchdog with it. The daemon never reads its
//            terminal, and its writes to it go through.
constexpr int kIgnoredSignals[] = {SIGPIPE, SIGTTIN, SIGTTOU};
// Ignored by their default action and needed by nothing here (SIGCONT also resumes a stopped
// process): left unblocked, so that they are never queued.
constexpr int kDefaultIgnoredSignals[] = {SIGCHLD, SIGCONT, SIGURG, SIGWINCH};

// Every other signal, 1-31 and the real-time ones, stops the daemon the orderly way (frame path
// stopped, laser off, line released, the "stopped" line): SIGINT, SIGTERM and SIGHUP exit 0, being
// the ways to ask it to stop; any other exits 128 + its number, so that a supervisor sees a
// failure (SIGQUIT, SIGUSR1, SIGXCPU of RLIMIT_RTTIME, ...). SIGTSTP stops it too: a suspended
// daemon could not switch its laser off. Blocked in every thread, taken by the signal thread.
sigset_t stop_signal_set() {
  sigset_t set;
  sigfillset(&set);  // glibc leaves out the real-time signals it keeps for itself
  for (int sig : kCrashSignals)
    sigdelset(&set, sig);
  for (int sig : kIgnoredSignals)
    sigdelset(&set, sig);
  for (int sig : kDefaultIgnoredSignals)
    sigdelset(&set, sig);
  sigdelset(&set, SIGKILL);
  sigdelset(&set, SIGSTOP);
  return set;
}

int exit_status_for(int sig) {
  return sig == SIGINT || sig == SIGTERM || sig == SIGHUP ? 0 : 128 + sig;
}

std::string signal_name(int sig) {
  if (sig >= SIGRTMIN && sig <= SIGRTMAX) return "SIGRTMIN+" + std::to_string(sig - SIGRTMIN);
  if (const char* abbrev = sigabbrev_np(sig); abbrev != nullptr) return std::string("SIG") + abbrev;
  return "signal " + std::to_string(sig);
}

// Between the signal thread and the main thread.
struct StopRequest {
  std::mutex mutex;
  std::condition_variable wake;
  int signal = 0;        // the first stop signal taken once running
  bool running = false;  // from here on the frame path may switch the laser on
};
// Never destroyed: the signal thread is detached and may still be in notify_all() while exit()
// runs the static destructors.
StopRequest& g_stop = *new StopRequest;

// The signal thread: takes every stop signal with sigwaitinfo. While the daemon is still
// starting (opening a camera may take seconds) nothing can have switched the laser on: it ends
// the process at once, and the kernel releases the line at the "off" level it was requested at.
// Once running, it hands the signal to the main loop.
void take_stop_signals(sigset_t set) {
  while (true) {
    const int sig = sigwaitinfo(&set, nullptr);
    if (sig <= 0) continue;  // EINTR
    std::unique_lock lock(g_stop.mutex);
    if (!g_stop.running) {
      log(LogLevel::kInfo, "laserlined: stopped (%s) while starting, the laser never switched on",
          signal_name(sig).c_str());
      _exit(exit_status_for(sig));
    }
    if (g_stop.signal == 0) g_stop.signal = sig;
    lock.unlock();
    g_stop.wake.notify_all();
  }
}

// Waits up to `timeout` for a stop signal; returns it, or 0.
int wait_for_stop_signal(std::chrono::milliseconds timeout) {
  std::unique_lock lock(g_stop.mutex);
  g_stop.wake.wait_for(lock, timeout, [] { return g_stop.signal != 0; });
  return g_stop.signal;
}

Options parse_args(int argc, char** argv) {
  Options o;
  laserline::cli::Arguments args(argc, argv, "laserlined", kUsage,
                                 {{"config", true},
                                  {"duration", true},
                                  {"check-config", false},
                                  {"probe", false},
                                  {"offline", false},
                                  {"laser-off", false},
                                  {"print-default-config", false}});
  args.set_error_writer([](const std::string& line) { log(LogLevel::kError, "%s", line.c_str()); });
  // A flag's value that cannot be used: one line naming the flag.
  auto value_error = [](const std::string& message) {
    log(LogLevel::kError, "laserlined: %s", message.c_str());
    throw laserline::cli::Exit(2);
  };
  while (args.next()) {
    const std::string& arg = args.name();
    if (arg == "--config") {
      o.config_path = args.value();
    } else if (arg == "--duration") {
      const std::string& text = args.value();
      char* end = nullptr;
      o.duration_s = std::strtod(text.c_str(), &end);
      // Written so that NaN fails it too.
      const bool in_range = o.duration_s >= kMinDurationS && o.duration_s <= kMaxDurationS;
      if (end == text.c_str() || *end != '\0' || !in_range) {
        value_error("--duration: expected a number of seconds from 0.001 to 1e9, got '" + text +
                    "'");
      }
    } else if (arg == "--check-config") {
      o.check_only = true;
    } else if (arg == "--probe") {
      o.probe = true;
    } else if (arg == "--offline") {
      o.offline = true;
    } else if (arg == "--laser-off") {
      o.laser_off = true;
    } else if (arg == "--print-default-config") {
      std::fputs(laserline::daemon::builtin_config_text(), stdout);
      throw laserline::cli::Exit(0);
    } else {
      args.fail("unexpected argument '" + args.value() + "'");
    }
  }
  if (o.probe && !o.check_only) value_error("--probe goes with --check-config");
  if (o.offline && !o.check_only) value_error("--offline goes with --check-config");
  if (o.offline && o.probe) value_error("--offline and --probe contradict each other");
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
    const std::int64_t matched = c.strobe_matched.load(std::memory_order_relaxed);
    const std::int64_t unmatched = c.strobe_unmatched.load(std::memory_order_relaxed);
    char strobe[256];
    path.describe_strobe(now_ns, matched - last_matched_, unmatched - last_unmatched_, strobe,
                         sizeof strobe);
    last_matched_ = matched;
    last_unmatched_ = unmatched;
    char line[700];
    std::snprintf(
        line, sizeof line,
        "camera %s, %.1f frames/s, %lld processed, %lld dropped, %lld over budget, %lld grab "
        "timeouts, %lld grab errors, laser %s, CPU %.0f%%, raw frames %lld published, %lld "
        "dropped%s%s",
        laserline::daemon::to_string(c.camera_state.load(std::memory_order_relaxed)), rate,
        static_cast<long long>(processed),
        static_cast<long long>(c.frames_dropped.load(std::memory_order_relaxed)),
        static_cast<long long>(c.frames_over_budget.load(std::memory_order_relaxed)),
        static_cast<long long>(c.grab_timeouts.load(std::memory_order_relaxed)),
        static_cast<long long>(c.grab_errors.load(std::memory_order_relaxed)),
        laser_on ? "on" : "off", cpu_.percent_since_last(),
        static_cast<long long>(path.images_published()),
        static_cast<long long>(c.images_dropped.load(std::memory_order_relaxed)),
        strobe[0] != '\0' ? ", strobe " : "", strobe);
    return line;
  }

 private:
  std::int64_t last_ns_ = laserline::hal::monotonic_ns();
  std::int64_t last_processed_ = 0;
  std::int64_t last_matched_ = 0;
  std::int64_t last_unmatched_ = 0;
  laserline::daemon::CpuUsage cpu_;
};

// --laser-off: the line requested at its off level, as the daemon's own start does, then
// released (the kernel keeps that level). For a supervisor once the daemon is gone, however it
// went; refused while another process holds the line.
int switch_laser_off(const DaemonConfig& config, laserline::hal::Laser& laser) {
  std::string error;
  if (!laser.open(&error) || !laser.set(false, 0, nullptr)) {
    log(LogLevel::kError, "laserlined: laser (%s): %s", config.laser_backend.c_str(),
        error.empty() ? "cannot be switched off" : error.c_str());
    return 1;
  }
  log(LogLevel::kInfo, "laserlined: laser %s: off", config.laser_backend.c_str());
  return 0;
}

// --check-config: the file and every backend option were validated when the backends were
// created; with --probe the camera and the laser line are then found and read, neither
// configured nor driven. Exit status 2: the file; 1: the hardware; 0: both good.
int check_config(const DaemonConfig& config, Backends& backends, bool probe) {
  if (!probe) {
    log(LogLevel::kInfo, "laserlined: %s: configuration is valid", config.source.c_str());
    return 0;
  }
  bool found_all = true;
  auto report = [&](const char* part, const std::string& backend, bool ok, const std::string& found,
                    const std::string& error) {
    if (!ok) {
      log(LogLevel::kError, "laserlined: %s (%s): %s", part, backend.c_str(), error.c_str());
      found_all = false;
    } else if (!found.empty()) {
      log(LogLevel::kInfo, "laserlined: %s (%s): %s", part, backend.c_str(), found.c_str());
    }
  };
  std::string found;
  std::string error;
  bool ok = backends.camera->probe(&found, &error);
  report("camera", config.camera_backend, ok, found, error);
  found.clear();
  error.clear();
  ok = backends.laser->probe(&found, &error);
  report("laser", config.laser_backend, ok, found, error);
  if (!found_all) {
    log(LogLevel::kError, "laserlined: %s: configuration is valid, its hardware is not all there",
        config.source.c_str());
    return 1;
  }
  log(LogLevel::kInfo, "laserlined: %s: configuration is valid, its hardware is there",
      config.source.c_str());
  return 0;
}

int run_daemon(int argc, char** argv) {
  // Stop signals are blocked before any thread exists, so every thread inherits the mask and no
  // frame-path thread is ever interrupted by them; the signal thread takes them.
  const sigset_t stop_signals = stop_signal_set();
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  for (int sig : kIgnoredSignals)
    signal(sig, SIG_IGN);
  for (int sig : kDefaultIgnoredSignals)
    signal(sig, SIG_DFL);

  const Options options = parse_args(argc, argv);
  setvbuf(stdout, nullptr, _IOLBF, 0);
  // --laser-off leaves the signals blocked: it is over in milliseconds and must not be cut short.
  if (!options.laser_off) std::thread(take_stop_signals, stop_signals).detach();

  DaemonConfig config;
  Backends backends;
  try {
    config = options.config_path ? laserline::daemon::load_config_file(*options.config_path)
                                 : laserline::daemon::builtin_config();
    backends = laserline::daemon::create_backends(config);
  } catch (const laserline::hal::ConfigError& e) {
    log(LogLevel::kError, "laserlined: %s", e.what());
    return 2;
  } catch (const std::exception& e) {
    log(LogLevel::kError, "laserlined: %s: %s", config.source.c_str(), e.what());
    return 2;
  }
  if (options.laser_off) return switch_laser_off(config, *backends.laser);
  if (options.check_only) return check_config(config, backends, options.probe);

  std::string error;
  const std::unique_ptr<lcm::LCM> lcm = laserline::daemon::open_lcm(config.lcm_url, &error);
  if (!lcm) {
    log(LogLevel::kError, "laserlined: %s: lcm.url: %s", config.source.c_str(), error.c_str());
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
  for (int sig : kCrashSignals)
    signal(sig, fatal_signal_handler);

  if (!backends.laser->open(&error)) {
    log(LogLevel::kError, "laserlined: laser (%s): %s", config.laser_backend.c_str(),
        error.c_str());
    return 1;
  }
  // The strobe before the camera: its first exposure is the first frame's (matched by order).
  if (laserline::hal::ExposureStrobe* strobe = backends.laser->strobe();
      strobe != nullptr && !strobe->open(&error)) {
    log(LogLevel::kError, "laserlined: laser (%s): %s", config.laser_backend.c_str(),
        error.c_str());
    return 1;
  }
  if (!backends.camera->open(&error)) {
    log(LogLevel::kError, "laserlined: camera (%s): %s", config.camera_backend.c_str(),
        error.c_str());
    return 1;
  }
  laserline::daemon::FramePath path(config, *backends.camera, *backends.laser, *backends.detector,
                                    *lcm);
  {
    // From here a stop signal goes to the main loop: the frame path is about to run the laser.
    const std::lock_guard lock(g_stop.mutex);
    g_stop.running = true;
  }
  if (!path.start(&error)) {
    log(LogLevel::kError, "laserlined: %s: %s", config.source.c_str(), error.c_str());
    return 1;
  }
  laserline::daemon::CommandServer commands(config, *lcm, path, *backends.camera);
  const bool takes_commands = commands.start();
  const auto format = backends.camera->format();
  log(LogLevel::kInfo,
      "laserlined: running %s camera %dx%d at %.1f Hz, detector %s, laser %s, LCM %s",
      config.camera_backend.c_str(), format.width, format.height, path.frame_rate_hz(),
      config.detector.c_str(), config.laser_backend.c_str(), config.lcm_url.c_str());
  if (takes_commands) {
    log(LogLevel::kInfo, "laserlined: commands on %s, answers on %s%s",
        config.command_channel.c_str(), config.command_ack_channel.c_str(),
        config.command_token.empty() ? "" : " (token required)");
  } else {
    log(LogLevel::kInfo, "laserlined: %s writes a log: no commands", config.lcm_url.c_str());
  }

  const std::int64_t start = laserline::hal::monotonic_ns();
  const auto duration_ns = static_cast<std::int64_t>(options.duration_s * 1e9);
  const char* reason = "duration elapsed";
  laserline::daemon::ServiceNotifier notifier;
  HealthLine health;
  std::int64_t next_status = start + kStatusPeriodNs;
  std::int64_t next_journal = start + kJournalPeriodNs;
  std::string signal_reason;
  int exit_status = 0;
  bool warned_image_drop = false;
  while (true) {
    if (const int sig = wait_for_stop_signal(std::chrono::milliseconds(50)); sig != 0) {
      signal_reason = signal_name(sig);
      reason = signal_reason.c_str();
      exit_status = exit_status_for(sig);
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
    if (!warned_image_drop && path.counters().images_dropped.load(std::memory_order_relaxed) > 0) {
      // Once; the periodic line then carries the count. Raw frames lost make a recording that
      // does not replay whole.
      warned_image_drop = true;
      log(LogLevel::kWarning,
          "laserlined: raw frames dropped: the image ring (pipeline.image_slots %d) is full, "
          "encoding and publishing (lcm.image_compression) does not keep up with the frame "
          "rate; a recording of them will not replay whole (none or zlib at level 1 is fastest)",
          config.image_slots);
    }
    if (now >= next_status) {
      const std::string line = health.update(path, backends.laser->is_on(), now);
      notifier.status(line);
      if (now >= next_journal) {
        log(LogLevel::kInfo, "laserlined: %s", line.c_str());
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
  commands.stop();
  path.stop();
  backends.laser->set(false, 0, nullptr);

  const auto s = path.summary();
  // A stop by a signal that asks for no stop (exit status non-zero) is worth a warning.
  log(exit_status == 0 ? LogLevel::kInfo : LogLevel::kWarning,
      "laserlined: stopped (%s) after %.1f s: %lld frames captured, %lld processed, %lld dropped, "
      "%lld profiles published, %lld raw frames published, %lld raw frames dropped; latency "
      "exposure->published p50 %.2f ms p99 %.2f ms max %.2f ms, arrival->published p50 %.2f ms "
      "p99 %.2f ms max %.2f ms, over %lld frames",
      reason, static_cast<double>(laserline::hal::monotonic_ns() - start) * 1e-9,
      static_cast<long long>(s.frames_captured), static_cast<long long>(s.frames_processed),
      static_cast<long long>(s.frames_dropped), static_cast<long long>(s.profiles_published),
      static_cast<long long>(s.images_published), static_cast<long long>(s.images_dropped),
      s.latency.p50_ms, s.latency.p99_ms, s.latency.max_ms, s.pipeline.p50_ms, s.pipeline.p99_ms,
      s.pipeline.max_ms, static_cast<long long>(s.latency.samples));
  log(LogLevel::kInfo,
      "laserlined: laser %s: %lld switches, %lld came after their frame's exposure began, %lld "
      "forced off because frames stopped",
      config.laser_backend.c_str(), static_cast<long long>(s.laser_switches),
      static_cast<long long>(s.laser_late_switches), static_cast<long long>(s.laser_safety_offs));
  if (laserline::hal::ExposureStrobe* strobe = backends.laser->strobe(); strobe != nullptr) {
    log(LogLevel::kInfo,
        "laserlined: strobe %s: %lld frames matched to their exposure, %lld not (their laser "
        "state estimated)",
        strobe->describe().c_str(), static_cast<long long>(s.strobe_matched),
        static_cast<long long>(s.strobe_unmatched));
  }
  g_laser = nullptr;
  if (path.source_ended() && s.frames_captured == 0 && exit_status == 0) {
    // A replay that replayed nothing failed, even though it ended as recordings do.
    log(LogLevel::kError, "laserlined: %s: the recording gave no frame to process",
        config.camera_backend.c_str());
    exit_status = 1;
  }
  return exit_status;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_daemon);
}
