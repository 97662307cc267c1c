// The gpiod laser backend against the real libgpiod 1.6 library, through the stand-in chip of
// tests/standins/gpiochip_shim.cpp: linked into this test for the in-process tests, LD_PRELOADed
// into laserlined for the daemon's safety paths and the alternate-mode timing. The shim's log is
// the "oscilloscope": every level change on the pin with its host time.
// Over 600 lines: one backend, on one stand-in chip and its log.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <laserline/profile_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "hal/clock.hpp"
#include "hal/gpio_laser.hpp"
#include "hal/registry.hpp"
#include "hal/yaml_reader.hpp"
#include "run_command.hpp"
#include "thread_allocations.hpp"

namespace {

using laserline::hal::GpioLaser;
using laserline::hal::GpioLaserOptions;
using laserline::hal::LaserSwitch;

std::filesystem::path g_dir;

// One line of the shim's log.
struct PinEvent {
  std::int64_t mono_ns = 0;
  std::int64_t wall_ns = 0;
  unsigned offset = 0;
  int level = 0;
  std::string event;
  std::string consumer;
};

std::vector<PinEvent> read_pin_log(const std::filesystem::path& path) {
  std::vector<PinEvent> events;
  std::ifstream in(path);
  PinEvent e;
  while (in >> e.mono_ns >> e.wall_ns >> e.offset >> e.level >> e.event >> e.consumer)
    events.push_back(e);
  return events;
}

std::string describe(const std::vector<PinEvent>& events) {
  std::ostringstream out;
  for (const auto& e : events)
    out << e.mono_ns << " line " << e.offset << " level " << e.level << " " << e.event << "\n";
  return out.str();
}

class GpioLaserTest : public ::testing::Test {
 protected:
  void SetUp() override {
    log_ = g_dir /
           (std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + ".pins");
  }
  std::vector<PinEvent> pins() const { return read_pin_log(log_); }
  std::filesystem::path log_;
};

// ---- In process: the shim is linked into this executable
// -----------------------------------------

// The shim reads its environment when the chip is opened; each test gets its own log.
void use_log(const std::filesystem::path& path) {
  setenv("LASERLINE_GPIO_SHIM_LOG", path.c_str(), 1);
}

TEST_F(GpioLaserTest, OpensOffSwitchesWithRecordsAndLeavesOff) {
  use_log(log_);
  {
    GpioLaser laser(GpioLaserOptions{"gpiochip0", 0, "", false, "test-laser", {}});
    std::string error;
    ASSERT_TRUE(laser.open(&error)) << error;
    EXPECT_FALSE(laser.is_on());
    LaserSwitch record;
    const std::int64_t before = laserline::hal::monotonic_ns();
    ASSERT_TRUE(laser.set(true, 42, &record));
    const std::int64_t after = laserline::hal::monotonic_ns();
    EXPECT_TRUE(laser.is_on());
    EXPECT_TRUE(record.on);
    EXPECT_EQ(record.for_frame, 42u);
    EXPECT_GE(record.mono_ns, before);
    EXPECT_LE(record.mono_ns, after);
    ASSERT_TRUE(laser.set(false, 43, &record));
    EXPECT_FALSE(record.on);
    ASSERT_TRUE(laser.set(true, 44, nullptr));
    {
      laserline::test::ThreadAllocationCount probe_count;
      void* volatile probe = std::malloc(64);
      std::free(probe);
      ASSERT_EQ(probe_count.count(), 1) << "the allocation counter does not count";
    }
    laserline::test::ThreadAllocationCount allocations;
    laser.set(true, 45, &record);  // no change: the same ioctl, no edge
    EXPECT_EQ(allocations.count(), 0) << "switching the laser allocated";
  }  // destroyed while on
  const auto events = pins();
  ASSERT_EQ(events.size(), 6u) << describe(events);
  EXPECT_EQ(events[0].event, "request");
  EXPECT_EQ(events[0].level, 0) << "the line must be requested already off";
  EXPECT_EQ(events[0].consumer, "test-laser");
  EXPECT_EQ(events[1].level, 1);
  EXPECT_EQ(events[2].level, 0);
  EXPECT_EQ(events[3].level, 1);
  EXPECT_EQ(events[4].level, 0) << "destroyed while on: the destructor must switch it off";
  EXPECT_EQ(events[4].event, "set");
  EXPECT_EQ(events[5].event, "release");
  EXPECT_EQ(events[5].level, 0);
}

TEST_F(GpioLaserTest, ActiveLowDrivesTheInvertedLevelAndFindsLinesByName) {
  use_log(log_);
  {
    GpioLaser laser(GpioLaserOptions{"0", -1, "LASER_EN", true, "laserlined", {}});
    std::string error;
    ASSERT_TRUE(laser.open(&error)) << error;
    ASSERT_TRUE(laser.set(true, 0, nullptr));
  }
  const auto events = pins();
  ASSERT_EQ(events.size(), 4u) << describe(events);
  EXPECT_EQ(events[0].offset, 2u) << "LASER_EN is line 2 of the stand-in chip";
  EXPECT_EQ(events[0].level, 1) << "active-low off is a high level";
  EXPECT_EQ(events[1].level, 0);
  EXPECT_EQ(events[2].level, 1);
  EXPECT_EQ(events[3].event, "release");
  EXPECT_EQ(events[3].level, 1);
}

TEST_F(GpioLaserTest, MissingChipLineOrBusyLineIsAClearError) {
  use_log(log_);
  std::string error;
  GpioLaser no_chip(GpioLaserOptions{"gpiochip7", 0, "", false, "laserlined", {}});
  EXPECT_FALSE(no_chip.open(&error));
  EXPECT_EQ(error, "chip 'gpiochip7': cannot open: No such file or directory");

  GpioLaser no_offset(GpioLaserOptions{"gpiochip0", 9, "", false, "laserlined", {}});
  EXPECT_FALSE(no_offset.open(&error));
  EXPECT_EQ(error, "line 9 of gpiochip0 (laserline-shim): the chip has only 4 lines (0..3)");

  GpioLaser no_name(GpioLaserOptions{"gpiochip0", -1, "LASER", false, "laserlined", {}});
  EXPECT_FALSE(no_name.open(&error));
  EXPECT_EQ(error, "line 'LASER' of gpiochip0 (laserline-shim): no line of that name");

  GpioLaser holder(GpioLaserOptions{"gpiochip0", 1, "", false, "other-daemon", {}});
  ASSERT_TRUE(holder.open(&error)) << error;
  GpioLaser second(GpioLaserOptions{"gpiochip0", 1, "", false, "laserlined", {}});
  EXPECT_FALSE(second.open(&error));
  EXPECT_EQ(error,
            "line 1 of gpiochip0 (laserline-shim): cannot request it as an output: Device or "
            "resource busy (held by 'other-daemon')");
  EXPECT_FALSE(second.is_on());
}

// --check-config's look at the line: found by offset or name, never requested, so its level
// cannot change; a missing chip or line and a held line are one line each, as open() says them.
TEST_F(GpioLaserTest, ProbeFindsTheLineWithoutRequestingIt) {
  use_log(log_);
  std::string found;
  std::string error;
  GpioLaser by_name(GpioLaserOptions{"gpiochip0", -1, "LASER_EN", false, "laserlined", {}});
  ASSERT_TRUE(by_name.probe(&found, &error)) << error;
  EXPECT_EQ(found,
            "line 'LASER_EN' of gpiochip0 (laserline-shim): free, now an input (not requested)");
  GpioLaser by_offset(GpioLaserOptions{"gpiochip0", 2, "", false, "laserlined", {}});
  ASSERT_TRUE(by_offset.probe(&found, &error)) << error;
  EXPECT_EQ(found,
            "line 2 of gpiochip0 (laserline-shim) ('LASER_EN'): free, now an input (not "
            "requested)");
  EXPECT_TRUE(pins().empty()) << "probing requested or drove the line:\n" << describe(pins());
  EXPECT_FALSE(by_name.is_on());

  GpioLaser no_chip(GpioLaserOptions{"gpiochip7", 0, "", false, "laserlined", {}});
  EXPECT_FALSE(no_chip.probe(&found, &error));
  EXPECT_EQ(error, "chip 'gpiochip7': cannot open: No such file or directory");
  GpioLaser no_offset(GpioLaserOptions{"gpiochip0", 9, "", false, "laserlined", {}});
  EXPECT_FALSE(no_offset.probe(&found, &error));
  EXPECT_EQ(error, "line 9 of gpiochip0 (laserline-shim): the chip has only 4 lines (0..3)");
  GpioLaser no_name(GpioLaserOptions{"gpiochip0", -1, "LASER", false, "laserlined", {}});
  EXPECT_FALSE(no_name.probe(&found, &error));
  EXPECT_EQ(error, "line 'LASER' of gpiochip0 (laserline-shim): no line of that name");

  GpioLaser holder(GpioLaserOptions{"gpiochip0", 1, "", false, "other-daemon", {}});
  ASSERT_TRUE(holder.open(&error)) << error;
  ASSERT_TRUE(holder.set(true, 0, nullptr));
  const std::size_t held_events = pins().size();
  GpioLaser second(GpioLaserOptions{"gpiochip0", 1, "", false, "laserlined", {}});
  EXPECT_FALSE(second.probe(&found, &error));
  EXPECT_EQ(error,
            "line 1 of gpiochip0 (laserline-shim) ('SPARE1'): in use by 'other-daemon' (laserlined "
            "could not request it)");
  EXPECT_EQ(pins().size(), held_events) << describe(pins());
  EXPECT_EQ(pins().back().level, 1) << "the holder's level must stay";

  GpioLaser running(GpioLaserOptions{"gpiochip0", -1, "STROBE", false, "laserlined", {}});
  ASSERT_TRUE(running.open(&error)) << error;
  GpioLaser checked(GpioLaserOptions{"gpiochip0", -1, "STROBE", false, "laserlined", {}});
  EXPECT_FALSE(checked.probe(&found, &error));
  EXPECT_EQ(error,
            "line 'STROBE' of gpiochip0 (laserline-shim): in use by 'laserlined' (another "
            "laserlined runs with it: stop that one first)");
}

TEST_F(GpioLaserTest, ConfigurationNamesTheMissingKey) {
  auto make = [](const std::string& text) {
    laserline::hal::YamlMap map(laserline::hal::load_yaml_text(text, "c.yaml"), "c.yaml", "laser");
    return laserline::hal::make_laser("gpiod", map);
  };
  try {
    make("{line: 3}");
    FAIL() << "no chip accepted";
  } catch (const laserline::hal::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("laser.chip: required"), std::string::npos) << e.what();
  }
  try {
    make("{chip: gpiochip0}");
    FAIL() << "no line accepted";
  } catch (const laserline::hal::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("laser.line: required"), std::string::npos) << e.what();
  }
  EXPECT_NE(make("{chip: gpiochip0, line: LASER_EN, active_low: true}"), nullptr);
}

// ---- laserlined with the shim preloaded --------------------------------------------------------

struct Daemon {
  pid_t pid = -1;
  std::filesystem::path output;
  std::filesystem::path config;
};

// The environment that gives a command the stand-in chip, its pin log at `pins`.
std::string shim_environment(const std::filesystem::path& pins) {
  return std::string("LD_PRELOAD=") + GPIOCHIP_SHIM_PATH +
         " LASERLINE_GPIO_SHIM_LOG=" + pins.string() +
         " LASERLINE_GPIO_SHIM_LINES=SPARE0,SPARE1,LASER_EN,STROBE" +
         " ASAN_OPTIONS=verify_asan_link_order=0";
}

// Starts laserlined on `config` with the stand-in chip preloaded, its pin log at `pins`.
Daemon start_daemon(const std::string& config, const std::filesystem::path& pins,
                    const std::string& duration_s) {
  static int counter = 0;
  Daemon d;
  d.output = g_dir / ("daemon" + std::to_string(++counter) + ".out");
  const std::filesystem::path config_path = g_dir / ("daemon" + std::to_string(counter) + ".yaml");
  d.config = config_path;
  std::ofstream(config_path) << config;
  std::fflush(stdout);  // or the child's freopen() writes the parent's pending output again
  d.pid = fork();
  if (d.pid == 0) {
    const rlimit no_core{0, 0};  // the crash signals below need no core file
    setrlimit(RLIMIT_CORE, &no_core);
    freopen(d.output.c_str(), "w", stdout);
    dup2(fileno(stdout), 2);
    setenv("LD_PRELOAD", GPIOCHIP_SHIM_PATH, 1);
    setenv("LASERLINE_GPIO_SHIM_LOG", pins.c_str(), 1);
    // A sanitized laserlined loads its runtime after the shim; that order is harmless here.
    setenv("ASAN_OPTIONS", "verify_asan_link_order=0", 1);
    std::vector<const char*> argv = {LASERLINED_PATH, "--config", config_path.c_str()};
    if (!duration_s.empty()) {
      argv.push_back("--duration");
      argv.push_back(duration_s.c_str());
    }
    argv.push_back(nullptr);
    execv(LASERLINED_PATH, const_cast<char* const*>(argv.data()));
    _exit(127);
  }
  return d;
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

int wait_status(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return status;
}

// Waits until the daemon's laser line has been switched on (frames are flowing).
bool wait_for_laser_on(const std::filesystem::path& pins) {
  for (int i = 0; i < 3000; ++i) {
    for (const auto& e : read_pin_log(pins))
      if (e.event == "set" && e.level == 1) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

// How many times the pin was switched so far.
std::size_t count_switches(const std::filesystem::path& pins) {
  std::size_t n = 0;
  for (const auto& e : read_pin_log(pins))
    n += e.event == "set";
  return n;
}

std::string daemon_config(const std::string& laser, const std::string& camera,
                          const std::filesystem::path& lcm_log, const std::string& sim = "") {
  return "camera: {frame_rate_hz: 100, " + camera + " sim: {tilt_y_deg: 8" + sim +
         "}}\n"
         "calibration: {camera: {width: 320, height: 240, fx: 350, fy: 350}}\n"
         // The cheapest detector: these tests are about the laser, and every frame must be
         // processed even in sanitized builds.
         "detector: {name: maxvalue}\n"
         "laser: {backend: gpiod, chip: gpiochip0, line: LASER_EN, " +
         laser + "}\nlcm: {url: \"file://" + lcm_log.string() +
         "?mode=w\", image_every_n: 0, status_period_s: 0.2}\n";
}

// The last events of a run: the laser is off when the line is released.
void expect_left_off(const std::vector<PinEvent>& events) {
  ASSERT_GE(events.size(), 2u) << describe(events);
  EXPECT_EQ(events.front().event, "request");
  EXPECT_EQ(events.front().level, 0) << "off at start";
  EXPECT_EQ(events.back().level, 0) << "must end off:\n" << describe(events);
}

TEST_F(GpioLaserTest, DaemonAlternateSwitchesOncePerFrame) {
  const auto lcm_log = g_dir / "alternate.lcm";
  Daemon d = start_daemon(daemon_config("mode: alternate", "", lcm_log), log_, "3");
  const int status = wait_status(d.pid);
  const std::string out = read_text(d.output);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;
  const auto events = pins();
  expect_left_off(events);
  if (HasFailure()) return;

  // Profiles in order of the frames that were grabbed (one per frame: the status says none was
  // dropped anywhere, checked below).
  std::vector<laserline::profile_t> profiles;
  lcm::LogFile log(lcm_log.string(), "r");
  ASSERT_TRUE(log.good());
  while (const lcm::LogEvent* event = log.readNextEvent()) {
    if (event->channel != "LASERLINE_PROFILE") continue;
    laserline::profile_t p;
    ASSERT_GT(p.decode(event->data, 0, static_cast<int>(event->datalen)), 0);
    profiles.push_back(p);
  }
#ifdef LASERLINE_SANITIZED
  ASSERT_GT(profiles.size(), 20u) << out;  // sanitized, the daemon runs several times slower
#else
  ASSERT_GT(profiles.size(), 100u) << out;
#endif
  ASSERT_NE(out.find(std::to_string(profiles.size()) + " frames captured, " +
                     std::to_string(profiles.size()) + " processed, 0 dropped"),
            std::string::npos)
      << "every grabbed frame must have its profile:\n"
      << out;

  // Switches between the request and the release: one per grabbed frame (frame i asks for on
  // when i is even), plus at stop at most two: the one for the frame the camera thread was
  // waiting for when it was stopped, and the final off.
  std::vector<PinEvent> switches;
  for (const auto& e : events)
    if (e.event == "set") switches.push_back(e);
  ASSERT_GE(switches.size(), profiles.size()) << describe(events);
  ASSERT_LE(switches.size(), profiles.size() + 2) << describe(events);
  std::vector<double> margins_ms;  // exposure start - switch: > 0 when the switch came first
  int late = 0;
  for (std::size_t i = 0; i < profiles.size(); ++i) {
    EXPECT_EQ(switches[i].level, i % 2 == 0 ? 1 : 0) << "frame " << i;
    EXPECT_EQ(profiles[i].laser_on, i % 2 == 0) << "frame " << i;
    const double margin_ms =
        static_cast<double>(profiles[i].utime * 1000 - switches[i].wall_ns) * 1e-6;
    margins_ms.push_back(margin_ms);
    late += margin_ms < 0;
    // The switch for frame i+1 comes after frame i arrived: never two switches in one frame.
    if (i + 1 < profiles.size()) {
      EXPECT_GT(switches[i + 1].wall_ns, profiles[i].utime * 1000) << "frame " << i;
    }
  }
  std::sort(margins_ms.begin(), margins_ms.end());
  std::printf(
      "alternate mode, %zu frames at 100 Hz: %zu switches; switch -> exposure start min %.3f ms, "
      "median %.3f ms, max %.3f ms; %d frames whose exposure began before their switch\n",
      profiles.size(), switches.size(), margins_ms.front(), margins_ms[margins_ms.size() / 2],
      margins_ms.back(), late);
  EXPECT_NE(out.find("came after their frame's exposure began"), std::string::npos) << out;
}

TEST_F(GpioLaserTest, DaemonPatternModeSwitchesWhereThePatternChanges) {
  const auto lcm_log = g_dir / "pattern.lcm";
  Daemon d = start_daemon(daemon_config("mode: pattern, pattern: \"110\"", "", lcm_log), log_, "2");
  const int status = wait_status(d.pid);
  const std::string out = read_text(d.output);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;
  const auto events = pins();
  expect_left_off(events);
  std::vector<bool> claimed;
  lcm::LogFile log(lcm_log.string(), "r");
  ASSERT_TRUE(log.good());
  while (const lcm::LogEvent* event = log.readNextEvent()) {
    if (event->channel != "LASERLINE_PROFILE") continue;
    laserline::profile_t p;
    ASSERT_GT(p.decode(event->data, 0, static_cast<int>(event->datalen)), 0);
    claimed.push_back(p.laser_on);
  }
  ASSERT_GT(claimed.size(), 15u) << out;
  // Frame i asks for on when i % 3 != 2; the pin changes exactly where the pattern does.
  std::vector<int> expected_levels;
  bool level = false;
  for (std::size_t i = 0; i < claimed.size(); ++i) {
    const bool want = i % 3 != 2;
    EXPECT_EQ(claimed[i], want) << "frame " << i;
    if (want != level) expected_levels.push_back(want ? 1 : 0);
    level = want;
  }
  std::vector<int> levels;
  for (const auto& e : events)
    if (e.event == "set") levels.push_back(e.level);
  ASSERT_GE(levels.size(), expected_levels.size()) << describe(events);
  ASSERT_LE(levels.size(), expected_levels.size() + 2) << describe(events);  // as in alternate
  levels.resize(expected_levels.size());
  EXPECT_EQ(levels, expected_levels);
}

TEST_F(GpioLaserTest, DaemonLeavesLaserOffOnSigterm) {
  Daemon d = start_daemon(daemon_config("mode: on", "", g_dir / "term.lcm"), log_, "");
  ASSERT_TRUE(wait_for_laser_on(log_)) << read_text(d.output);
  kill(d.pid, SIGTERM);
  const int status = wait_status(d.pid);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << read_text(d.output);
  expect_left_off(pins());
}

TEST_F(GpioLaserTest, DaemonLeavesLaserOffWhenItCrashes) {
  for (int sig : {SIGSEGV, SIGABRT}) {
    std::filesystem::remove(log_);
    Daemon d = start_daemon(daemon_config("mode: on", "", g_dir / "crash.lcm"), log_, "");
    ASSERT_TRUE(wait_for_laser_on(log_)) << read_text(d.output);
    kill(d.pid, sig);
    const int status = wait_status(d.pid);
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == sig) << "signal " << sig;
    const auto events = pins();
    expect_left_off(events);
    // A crash does not release the line: the off came from the fatal-signal handler.
    EXPECT_EQ(events.back().event, "set") << describe(events);
  }
}

TEST_F(GpioLaserTest, DaemonSwitchesLaserOffWhileFramesStop) {
  // Frames stop for 1 s after 0.5 s (a pulled cable); the laser must go off within the frame
  // timeout and stay off until frames return.
  Daemon d =
      start_daemon(daemon_config("mode: on, frame_timeout_ms: 100", "timeout_ms: 200,",
                                 g_dir / "stall.lcm", ", stall_after_s: 0.5, stall_for_s: 1"),
                   log_, "2.5");
  const int status = wait_status(d.pid);
  const std::string out = read_text(d.output);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;
  const auto events = pins();
  expect_left_off(events);
  // The longest time the pin stayed low between two "on" periods is the outage.
  std::int64_t longest_off_ns = 0;
  for (std::size_t i = 1; i + 1 < events.size(); ++i) {
    if (events[i].event == "set" && events[i].level == 0 && events[i + 1].level == 1) {
      longest_off_ns = std::max(longest_off_ns, events[i + 1].mono_ns - events[i].mono_ns);
    }
  }
  std::printf("stall of 1 s: laser off for %.3f s\n", static_cast<double>(longest_off_ns) * 1e-9);
  EXPECT_GT(longest_off_ns, 800'000'000) << describe(events);
  EXPECT_NE(out.find("forced off because frames stopped"), std::string::npos) << out;
}

// What laserlined does with each signal (daemon/laserlined.cpp says why).
enum class SignalOutcome { kStop, kCrash, kIgnore };

SignalOutcome outcome_of(int sig) {
  switch (sig) {
    case SIGSEGV:
    case SIGBUS:
    case SIGFPE:
    case SIGILL:
    case SIGABRT:
    case SIGTRAP:
    case SIGSYS:
      return SignalOutcome::kCrash;
    case SIGPIPE:
    case SIGTTIN:
    case SIGTTOU:
    case SIGCHLD:
    case SIGCONT:
    case SIGURG:
    case SIGWINCH:
      return SignalOutcome::kIgnore;
    default:
      return SignalOutcome::kStop;
  }
}

std::string signal_name(int sig) {
  if (sig >= SIGRTMIN && sig <= SIGRTMAX) return "SIGRTMIN+" + std::to_string(sig - SIGRTMIN);
  return std::string("SIG") + sigabbrev_np(sig);
}

// Every signal of `kill -l` 1-31 but SIGKILL and SIGSTOP (the supervisor's test below), and one
// real-time signal, each sent to its own daemon while its laser is on: a stop signal ends it the
// orderly way (exit 0 for SIGINT, SIGTERM and SIGHUP, 128 + the signal otherwise, the "stopped"
// line, the line released off); a crash signal ends it by that signal with the line switched off
// by the handler; an ignored one leaves it switching its laser until SIGTERM.
struct SignalRun {
  int sig = 0;
  std::filesystem::path pins;
  Daemon daemon;
};

// Starts a daemon per signal, all at once, sends each its signal once its laser is on and checks
// how each ended.
void run_signals(std::vector<SignalRun>& runs) {
  for (SignalRun& r : runs) {
    r.pins = g_dir / ("signal" + std::to_string(r.sig) + ".pins");
    std::filesystem::remove(r.pins);
    const auto lcm_log = g_dir / ("signal" + std::to_string(r.sig) + ".lcm");
    r.daemon = start_daemon(daemon_config("mode: alternate", "", lcm_log), r.pins, "");
  }
  for (SignalRun& r : runs)
    ASSERT_TRUE(wait_for_laser_on(r.pins)) << signal_name(r.sig) << read_text(r.daemon.output);
  std::vector<std::size_t> switches_before;
  for (SignalRun& r : runs) {
    switches_before.push_back(count_switches(r.pins));
    kill(r.daemon.pid, r.sig);
  }
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const SignalRun& r = runs[i];
    if (outcome_of(r.sig) != SignalOutcome::kIgnore) continue;
    // Still running: the laser keeps switching, once per frame.
    bool switching = false;
    for (int wait = 0; wait < 300 && !switching; ++wait) {
      switching = count_switches(r.pins) >= switches_before[i] + 10;
      if (!switching) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_TRUE(switching) << signal_name(r.sig) << " stopped the laser's switching";
    kill(r.daemon.pid, SIGTERM);
  }
  for (const SignalRun& r : runs) {
    const std::string name = signal_name(r.sig);
    const int status = wait_status(r.daemon.pid);
    const std::string out = read_text(r.daemon.output);
    const auto events = read_pin_log(r.pins);
    expect_left_off(events);
    switch (outcome_of(r.sig)) {
      case SignalOutcome::kStop: {
        const int code = r.sig == SIGINT || r.sig == SIGTERM || r.sig == SIGHUP ? 0 : 128 + r.sig;
        EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == code)
            << name << ": status " << status << "\n"
            << out;
        EXPECT_NE(out.find("laserlined: stopped (" + name + ")"), std::string::npos) << out;
        EXPECT_EQ(events.back().event, "release") << name << "\n" << describe(events);
        break;
      }
      case SignalOutcome::kCrash:
        EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == r.sig)
            << name << ": status " << status << "\n"
            << out;
        EXPECT_EQ(events.back().event, "set") << name << ": the handler switches it off\n"
                                              << describe(events);
        break;
      case SignalOutcome::kIgnore:
        EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
            << name << ": status " << status << "\n"
            << out;
        EXPECT_NE(out.find("laserlined: stopped (SIGTERM)"), std::string::npos) << name << out;
        EXPECT_EQ(events.back().event, "release") << name << "\n" << describe(events);
        break;
    }
  }
}

// Every signal of `kill -l` 1-31 but SIGKILL and SIGSTOP (the supervisor's test below), and one
// real-time signal, each sent to its own daemon while its laser is on: a stop signal ends it the
// orderly way (exit 0 for SIGINT, SIGTERM and SIGHUP, 128 + the signal otherwise, the "stopped"
// line, the line released off); a crash signal ends it by that signal with the line switched off
// by the handler; an ignored one leaves it switching its laser until SIGTERM.
TEST_F(GpioLaserTest, DaemonStopsOrIgnoresEverySignalWithTheLaserOff) {
  std::vector<int> signals;
  for (int sig = 1; sig <= 31; ++sig)
    if (sig != SIGKILL && sig != SIGSTOP) signals.push_back(sig);
  signals.push_back(SIGRTMIN + 3);
  // Eight daemons at a time: each takes a fraction of a CPU at 100 frames/s of 320x240, and a
  // sanitized one much memory.
  constexpr std::size_t kBatch = 8;
  const auto begin = std::chrono::steady_clock::now();
  for (std::size_t first = 0; first < signals.size(); first += kBatch) {
    std::vector<SignalRun> runs;
    for (std::size_t i = first; i < std::min(signals.size(), first + kBatch); ++i)
      runs.push_back(SignalRun{signals[i], {}, {}});
    run_signals(runs);
    if (HasFatalFailure()) return;
  }
  std::printf("%zu signals, a daemon each: %.2f s\n", signals.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count());
}

// The unit's ExecStopPost= command, with this build's laserlined and `config` in place of the
// installed paths.
std::string unit_laser_off_command(const std::filesystem::path& config) {
  std::ifstream unit(LASERLINE_UNIT_PATH);
  std::string line;
  while (std::getline(unit, line)) {
    if (line.rfind("ExecStopPost=", 0) != 0) continue;
    std::istringstream words(line.substr(std::strlen("ExecStopPost=")));
    std::string program;
    words >> program;
    EXPECT_EQ(std::filesystem::path(program).filename(), "laserlined") << line;
    std::string command = LASERLINED_PATH;
    for (std::string word; words >> word;) {
      command += " " + word;
      if (word == "--config" && words >> word) command += " " + config.string();
    }
    EXPECT_NE(command.find(" --laser-off"), std::string::npos) << line;
    EXPECT_NE(command.find(" --config " + config.string()), std::string::npos) << line;
    return command;
  }
  ADD_FAILURE() << "no ExecStopPost= in " << LASERLINE_UNIT_PATH;
  return "false";
}

std::string read_unit(const std::string& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// laserlined@NAME.service is laserlined.service reading NAME.yaml: the same daemon, the same
// hardening and the same ExecStopPost= that switches the laser off, for the instance's own file.
TEST(ServiceUnits, TheTemplateIsTheUnitWithTheInstancesConfiguration) {
  std::string unit_path = LASERLINE_UNIT_PATH;
  const std::string unit = read_unit(unit_path);
  std::string template_path = unit_path;
  template_path.replace(template_path.rfind("laserlined.service"), 18, "laserlined@.service");
  std::string instance = read_unit(template_path);
  ASSERT_FALSE(unit.empty()) << unit_path;
  ASSERT_FALSE(instance.empty()) << template_path;
  EXPECT_NE(instance.find("\nExecStopPost="), std::string::npos);
  EXPECT_NE(instance.find(" --laser-off --config "), std::string::npos);
  std::size_t configs = 0;
  for (std::size_t at; (at = instance.find("/%i.yaml")) != std::string::npos; ++configs)
    instance.replace(at, 8, "/laserline.yaml");
  EXPECT_EQ(configs, 2u) << "ExecStart= and ExecStopPost= read the instance's file";
  const std::size_t description = instance.find(" daemon (%i)\n");
  ASSERT_NE(description, std::string::npos);
  instance.erase(description + 7, 5);
  EXPECT_EQ(instance, unit);
}

// The pin's level as libgpiod's own gpioget reads it (a new process: the shim keeps the level
// the last holder left, as the kernel does).
std::string gpioget(const std::filesystem::path& pins) {
  return laserline::test_support::run_command(shim_environment(pins) + " gpioget gpiochip0 2").out;
}

// What no process can catch: SIGKILL, and SIGSTOP, which freezes the frame watchdog with the
// daemon. The kernel keeps the killed daemon's "on"; the unit's ExecStopPost= command (run here
// as systemd would after the kill) drives the line off.
TEST_F(GpioLaserTest, SupervisorCommandSwitchesTheLaserOffAfterKillOrStop) {
  if (laserline::test_support::run_command("command -v gpioget").exit_code != 0) {
    GTEST_SKIP() << "no gpioget (Debian package gpiod)";
  }
  for (int sig : {SIGKILL, SIGSTOP}) {
    std::filesystem::remove(log_);
    Daemon d = start_daemon(daemon_config("mode: on", "", g_dir / "supervisor.lcm"), log_, "");
    ASSERT_TRUE(wait_for_laser_on(log_)) << read_text(d.output);
    kill(d.pid, sig);
    if (sig == SIGSTOP) {
      // Frozen: nothing of the daemon acts any more, its frame watchdog included.
      std::this_thread::sleep_for(std::chrono::milliseconds(400));
      EXPECT_EQ(pins().back().level, 1) << describe(pins());
      kill(d.pid, SIGKILL);  // systemd's last step, TimeoutAbortSec= after its watchdog fired
    }
    const int status = wait_status(d.pid);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << status;
    EXPECT_EQ(pins().back().level, 1) << "the test needs the laser left on\n" << describe(pins());
    EXPECT_EQ(gpioget(log_), "1\n") << "a killed holder leaves its level on the pin";

    const std::size_t before = pins().size();
    const auto started = std::chrono::steady_clock::now();
    const auto off = laserline::test_support::run_command(shim_environment(log_) + " " +
                                                          unit_laser_off_command(d.config));
    const double took_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    EXPECT_EQ(off.exit_code, 0) << off.out;
    EXPECT_EQ(off.out, "laserlined: laser gpiod: off\n");
    const auto events = pins();
    ASSERT_GT(events.size(), before) << describe(events);
    EXPECT_EQ(events[before].event, "request");
    EXPECT_EQ(events[before].level, 0) << "requested at its off level\n" << describe(events);
    EXPECT_EQ(events.back().event, "release");
    EXPECT_EQ(events.back().level, 0) << describe(events);
    EXPECT_EQ(gpioget(log_), "0\n");
    std::printf("after %s: laserlined --laser-off drove the pin low in %.3f s\n",
                signal_name(sig).c_str(), took_s);
  }
}

// A stop signal while the camera is still being opened (Aravis asking an address where no
// camera answers, several seconds) ends the daemon at once; the laser was never switched on.
TEST_F(GpioLaserTest, DaemonStopsAtOnceWhileStarting) {
  const std::string config =
      "camera: {backend: aravis, device: 127.0.0.2}\n"
      "calibration: {camera: {width: 320, height: 240, fx: 350, fy: 350}}\n"
      "detector: {name: maxvalue}\n"
      "laser: {backend: gpiod, chip: gpiochip0, line: LASER_EN, mode: on}\n"
      "lcm: {url: 'memq://'}\n";
  const auto begin = std::chrono::steady_clock::now();
  Daemon d = start_daemon(config, log_, "");
  // The laser's line is requested before the camera is opened.
  bool requested = false;
  for (int i = 0; i < 1000 && !requested; ++i) {
    requested = !pins().empty();
    if (!requested) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(requested) << read_text(d.output);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  int status = 0;
  if (waitpid(d.pid, &status, WNOHANG) == d.pid) {
    GTEST_SKIP() << "the camera failed within 0.3 s, no slow start to interrupt: "
                 << read_text(d.output);
  }
  const auto signalled = std::chrono::steady_clock::now();
  kill(d.pid, SIGTERM);
  status = wait_status(d.pid);
  const double took_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - signalled).count();
  const std::string out = read_text(d.output);
  std::printf("SIGTERM %.2f s into a slow start: ended %.3f s later\n",
              std::chrono::duration<double>(signalled - begin).count(), took_s);
  EXPECT_LT(took_s, 1.0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status << "\n" << out;
  EXPECT_EQ(out, "laserlined: stopped (SIGTERM) while starting, the laser never switched on\n");
  const auto events = pins();
  ASSERT_FALSE(events.empty());
  for (const auto& e : events)
    EXPECT_EQ(e.level, 0) << describe(events);
}
// laserlined --check-config --probe with the stand-in chip: the line is reported found and is
// left alone (no request, no level); a chip that does not exist fails the check in one line.
// Without --probe (or with --offline, kept for old scripts) the file alone is checked.
TEST_F(GpioLaserTest, CheckConfigLooksTheLineUpAndLeavesItAlone) {
  const std::string config = daemon_config("mode: on", "", g_dir / "check.lcm");
  const std::filesystem::path path = g_dir / "check.yaml";
  std::ofstream(path) << config;
  const auto check =
      laserline::test_support::run_command(shim_environment(log_) + " " + LASERLINED_PATH +
                                           " --check-config --probe --config " + path.string());
  EXPECT_EQ(check.exit_code, 0) << check.out;
  EXPECT_EQ(
      check.out,
      "laserlined: laser (gpiod): line 'LASER_EN' of gpiochip0 (laserline-shim): free, now an "
      "input (not requested)\n"
      "laserlined: " +
          path.string() + ": configuration is valid, its hardware is there\n");
  EXPECT_TRUE(pins().empty()) << describe(pins());

  std::string missing = config;
  missing.replace(missing.find("chip: gpiochip0"), 15, "chip: gpiochip9");
  std::ofstream(path) << missing;
  const auto no_chip =
      laserline::test_support::run_command(shim_environment(log_) + " " + LASERLINED_PATH +
                                           " --check-config --probe --config " + path.string());
  EXPECT_EQ(no_chip.exit_code, 1) << no_chip.out;
  EXPECT_EQ(no_chip.out,
            "laserlined: laser (gpiod): chip 'gpiochip9': cannot open: No such file or directory\n"
            "laserlined: " +
                path.string() + ": configuration is valid, its hardware is not all there\n");
  for (const char* file_alone :
       {" --check-config --config ", " --check-config --offline --config "}) {
    const auto r = laserline::test_support::run_command(
        shim_environment(log_) + " " + LASERLINED_PATH + file_alone + path.string());
    EXPECT_EQ(r.exit_code, 0) << file_alone << r.out;
    EXPECT_EQ(r.out, "laserlined: " + path.string() + ": configuration is valid\n") << file_alone;
  }
  EXPECT_TRUE(pins().empty()) << describe(pins());
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  g_dir = std::filesystem::temp_directory_path() / ("laserline_gpio_" + std::to_string(getpid()));
  std::filesystem::create_directories(g_dir);
  // The stand-in chip of the in-process tests (read when the chip is first opened).
  setenv("LASERLINE_GPIO_SHIM_LINES", "SPARE0,SPARE1,LASER_EN,STROBE", 1);
  const int result = RUN_ALL_TESTS();
  std::filesystem::remove_all(g_dir);
  return result;
}
