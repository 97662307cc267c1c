// The camera's strobe on a GPIO input (laser.strobe_line) through the real libgpiod 1.6 and the
// stand-in chip of tests/standins/gpiochip_shim.cpp, linked in: the test drives the strobe line's
// edges with exact timestamps (laserline_gpio_shim_drive_input), as the kernel stamps them. The
// reader's timestamps, the frame path's laser state and late switches decided from them, and
// laserlined with a strobe wire that stays silent (LD_PRELOADed shim).
#include <gtest/gtest.h>
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "allocation_counter.hpp"
#include "daemon/backends.hpp"
#include "daemon/frame_path.hpp"
#include "hal/clock.hpp"
#include "hal/gpio_laser.hpp"
#include "hal/gpio_strobe.hpp"
#include "hal/registry.hpp"
#include "hal/yaml_reader.hpp"
#include "run_command.hpp"

extern "C" int laserline_gpio_shim_drive_input(unsigned offset, int physical_level,
                                               long long mono_ns);

namespace laserline {
namespace {

constexpr std::int64_t kUs = 1'000;
constexpr std::int64_t kMs = 1'000'000;
constexpr unsigned kStrobeOffset = 3;  // SPARE0,SPARE1,LASER_EN,STROBE
const char* const kLines = "SPARE0,SPARE1,LASER_EN,STROBE";

std::filesystem::path g_dir;

// Each test its own pin log; the shim reads it when the chip is next opened.
std::filesystem::path use_log(const std::string& name) {
  const std::filesystem::path log = g_dir / (name + ".pins");
  setenv("LASERLINE_GPIO_SHIM_LOG", log.c_str(), 1);
  return log;
}

hal::GpioStrobeOptions strobe_options(const std::string& chip, const std::string& name,
                                      bool active_low = false) {
  hal::GpioStrobeOptions o;
  o.line = hal::GpioLineAddress{chip, -1, name};
  o.active_low = active_low;
  return o;
}

bool wait_for_exposures(const hal::ExposureHistory& history, std::uint64_t count) {
  for (int i = 0; i < 2000 && history.completed() < count; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  return history.completed() >= count;
}

TEST(GpioStrobe, ReadsEachEdgeWithItsKernelTimestamp) {
  use_log("timestamps");
  for (bool active_low : {false, true}) {
    hal::GpioStrobe strobe(strobe_options("gpiochip0", "STROBE", active_low));
    std::string error;
    ASSERT_TRUE(strobe.open(&error)) << error;
    EXPECT_EQ(strobe.describe(), "line 'STROBE' of gpiochip0 (laserline-shim)");
    const int active = active_low ? 0 : 1;
    if (active_low) {
      ASSERT_EQ(laserline_gpio_shim_drive_input(kStrobeOffset, 1, 1), 0);  // idle high
    }
    // Times chosen by the test, some in the past: the kernel's stamps, not the reading's.
    const std::int64_t t0 = hal::monotonic_ns() - 50 * kMs;
    std::vector<std::pair<std::int64_t, std::int64_t>> sent;
    for (int i = 0; i < 40; ++i) {  // more than the kernel's queue of 16 between two reads
      const std::int64_t start = t0 + i * 1234 * kUs + i;
      const std::int64_t end = start + 345 * kUs + 7 * i;
      ASSERT_EQ(laserline_gpio_shim_drive_input(kStrobeOffset, active, start), 0);
      ASSERT_EQ(laserline_gpio_shim_drive_input(kStrobeOffset, 1 - active, end), 0);
      sent.emplace_back(start, end);
    }
    ASSERT_TRUE(wait_for_exposures(strobe.history(), sent.size()))
        << strobe.history().completed() << " of " << sent.size();
    for (std::size_t i = 0; i < sent.size(); ++i) {
      hal::ExposureInterval interval;
      if (i + strobe.history().capacity() < sent.size()) continue;  // overwritten
      ASSERT_TRUE(strobe.history().get(i, &interval)) << i;
      EXPECT_EQ(interval.start_mono_ns, sent[i].first) << i << " active_low " << active_low;
      EXPECT_EQ(interval.end_mono_ns, sent[i].second) << i << " active_low " << active_low;
    }
    EXPECT_EQ(strobe.history().last_edge_mono_ns(), sent.back().second);
    EXPECT_EQ(strobe.read_errors(), 0);
    strobe.close();
    if (active_low) laserline_gpio_shim_drive_input(kStrobeOffset, 0, 0);
  }
}

// Steady state: the reader thread takes edges into the history without allocating (counted on
// every thread while edges are driven and read).
TEST(GpioStrobe, ReadingEdgesAllocatesNothing) {
  use_log("allocations");
  hal::GpioStrobe strobe(strobe_options("gpiochip0", "STROBE"));
  std::string error;
  ASSERT_TRUE(strobe.open(&error)) << error;
  std::int64_t t = hal::monotonic_ns();
  laserline_gpio_shim_drive_input(kStrobeOffset, 1, t);  // warm-up: the first read
  laserline_gpio_shim_drive_input(kStrobeOffset, 0, t + 100 * kUs);
  ASSERT_TRUE(wait_for_exposures(strobe.history(), 1));
  ASSERT_TRUE(testing::allocation_counter_works());
  testing::start_counting_allocations();
  for (int i = 1; i <= 200; ++i) {
    t += 1 * kMs;
    laserline_gpio_shim_drive_input(kStrobeOffset, 1, t);
    laserline_gpio_shim_drive_input(kStrobeOffset, 0, t + 100 * kUs);
    if (i % 8 == 0) wait_for_exposures(strobe.history(), static_cast<std::uint64_t>(i) + 1);
  }
  const bool all = wait_for_exposures(strobe.history(), 201);
  const testing::Allocations counted = testing::stop_counting_allocations();
  ASSERT_TRUE(all) << strobe.history().completed();
  EXPECT_EQ(counted.count, 0) << counted.bytes << " bytes allocated over 200 exposures";
}

TEST(GpioStrobe, MissingChipLineOrBusyLineIsOneLineNamingThem) {
  use_log("errors");
  std::string error;
  hal::GpioStrobe no_chip(strobe_options("gpiochip9", "STROBE"));
  EXPECT_FALSE(no_chip.open(&error));
  EXPECT_EQ(error,
            "strobe line 'STROBE' on chip 'gpiochip9': cannot open: No such file or directory");
  hal::GpioStrobe no_line(strobe_options("gpiochip0", "STROBE2"));
  EXPECT_FALSE(no_line.open(&error));
  EXPECT_EQ(error, "strobe line 'STROBE2' of gpiochip0 (laserline-shim): no line of that name");
  hal::GpioStrobeOptions by_offset = strobe_options("gpiochip0", "");
  by_offset.line.offset = 7;
  hal::GpioStrobe no_offset(by_offset);
  EXPECT_FALSE(no_offset.open(&error));
  EXPECT_EQ(error, "strobe line 7 of gpiochip0 (laserline-shim): the chip has only 4 lines (0..3)");

  hal::GpioStrobe holder(strobe_options("gpiochip0", "STROBE"));
  ASSERT_TRUE(holder.open(&error)) << error;
  hal::GpioStrobe second(strobe_options("gpiochip0", "STROBE"));
  EXPECT_FALSE(second.open(&error));
  EXPECT_EQ(error,
            "strobe line 'STROBE' of gpiochip0 (laserline-shim): cannot request its edge events: "
            "Device or resource busy (held by 'laserlined')");
  std::string found;
  EXPECT_FALSE(second.probe(&found, &error));
  EXPECT_EQ(error, "strobe line 'STROBE' of gpiochip0 (laserline-shim): in use by 'laserlined'");
  holder.close();
  EXPECT_TRUE(second.probe(&found, &error)) << error;
  EXPECT_EQ(found, "strobe line 'STROBE' of gpiochip0 (laserline-shim): free");
}

hal::YamlMap laser_section(const std::string& text) {
  return hal::YamlMap(hal::load_yaml_text(text, "c.yaml"), "c.yaml", "laser");
}

TEST(GpioStrobe, OptionsAreCheckedLikeTheLasersAndAbsentMeansNone) {
  auto make = [](const std::string& text) {
    hal::YamlMap map = laser_section(text);
    auto laser = hal::make_laser("gpiod", map);
    map.finish();
    return laser;
  };
  EXPECT_EQ(make("{chip: gpiochip0, line: LASER_EN}")->strobe(), nullptr);
  auto with = make("{chip: gpiochip0, line: LASER_EN, strobe_line: STROBE}");
  ASSERT_NE(with->strobe(), nullptr);
  EXPECT_EQ(with->strobe()->describe(), "line 'STROBE' of chip 'gpiochip0'");
  EXPECT_NE(make("{chip: gpiochip0, line: 2, strobe_line: 3, strobe_chip: gpiochip1, "
                 "strobe_active_low: true}")
                ->strobe(),
            nullptr);
  const std::vector<std::pair<std::string, std::string>> refused = {
      {"{chip: gpiochip0, line: 2, strobe_line: 2}",
       "laser.strobe_line: is the laser's own line (laser.line)"},
      {"{chip: gpiochip0, line: 2, strobe_line: 600}", "laser.strobe_line: offset must be 0..511"},
      {"{chip: gpiochip0, line: 2, strobe_line: ''}", "laser.strobe_line: must not be empty"},
      {"{chip: gpiochip0, line: 2, strobe_active_low: true}",
       "laser.strobe_active_low: goes with laser.strobe_line, which is not given"},
      {"{chip: gpiochip0, line: 2, strobe_chip: gpiochip1}",
       "laser.strobe_chip: goes with laser.strobe_line, which is not given"},
  };
  for (const auto& [text, expected] : refused) {
    try {
      make(text);
      ADD_FAILURE() << text << " accepted";
    } catch (const hal::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
}

// ---- The frame path deciding each frame's laser state from the strobe --------------------------

constexpr std::int64_t kCameraAhead = 7'000 * kMs;  // the camera's clock against the host's

// Where a frame's exposure lies against its laser switch (made by the frame path after the
// previous frame arrived, before this grab).
enum class Exposure {
  kAfterSwitch,   // wholly after: the laser is as the frame asked
  kAcrossSwitch,  // begins before the switch, ends after: mixed, a late switch
  kBeforeSwitch,  // wholly before: the laser still as for the previous frame, a late switch
};

// A camera that plays a script of exposures on the stand-in's strobe line and returns a frame
// for each once the strobe's reader has its edges (when it has a reader). Its own timestamp is
// exact on its clock; the host-time estimate (exposure_mono_ns) is late by 3 ms, as the mapping
// of a camera's clock is by the shortest transfer delay.
class StrobedCamera final : public hal::Camera {
 public:
  StrobedCamera(std::vector<Exposure> script, const hal::ExposureHistory* history)
      : script_(std::move(script)), history_(history) {}

  bool open(std::string*) override { return true; }
  hal::FrameFormat format() const override { return {320, 240, 320}; }
  void stop() override { stopped_ = true; }

  hal::GrabStatus grab(std::span<std::uint8_t>, hal::FrameInfo& info,
                       std::chrono::milliseconds) override {
    if (stopped_ || next_ >= script_.size()) return hal::GrabStatus::kStopped;
    const std::int64_t entry = hal::monotonic_ns();
    if (last_return_ == 0) last_return_ = entry - 5 * kMs;
    std::int64_t start = 0;
    std::int64_t end = 0;
    switch (script_[next_]) {
      case Exposure::kAfterSwitch:
        start = entry + 300 * kUs;
        end = start + 1 * kMs;
        break;
      case Exposure::kAcrossSwitch:
        start = last_return_ - 50 * kUs;  // the switch came after the previous frame returned
        end = entry + 1 * kMs;
        break;
      case Exposure::kBeforeSwitch:
        start = last_return_ - 1500 * kUs;  // after the previous exposure, which ended >= 2.5 ms
        end = last_return_ - 500 * kUs;     // before the previous frame returned
        break;
    }
    // Readout and transfer: the frame arrives 2.5 ms after its exposure ended.
    while (hal::monotonic_ns() < end + 2500 * kUs)
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    laserline_gpio_shim_drive_input(kStrobeOffset, 1, start);
    laserline_gpio_shim_drive_input(kStrobeOffset, 0, end);
    if (history_ != nullptr && !wait_for_exposures(*history_, next_ + 1)) {
      return hal::GrabStatus::kError;
    }
    info.sequence = next_;
    info.camera_ns = start + kCameraAhead;
    info.exposure_mono_ns = start + 3 * kMs;
    info.arrival_mono_ns = hal::monotonic_ns();
    info.arrival_wall_ns = hal::wall_ns();
    last_return_ = hal::monotonic_ns();
    ++next_;
    return hal::GrabStatus::kOk;
  }

 private:
  std::vector<Exposure> script_;
  const hal::ExposureHistory* history_;
  std::size_t next_ = 0;
  std::int64_t last_return_ = 0;
  std::atomic<bool> stopped_{false};
};

struct PathRun {
  std::map<std::int64_t, bool> laser_on;  // by frame sequence, from the profiles
  std::vector<laserline::status_t> statuses;
  daemon::FramePathSummary summary;
};

// Alternate mode (frame n asks for on when n is even) over the script, with or without the
// strobe line; what the published profiles and status say.
PathRun run_path(const std::vector<Exposure>& script, bool with_strobe, const std::string& name) {
  use_log(name);
  const std::filesystem::path lcm_log = g_dir / (name + ".lcm");
  const std::string text =
      "camera: {frame_rate_hz: 100}\n"
      "calibration: {camera: {width: 320, height: 240, fx: 350, fy: 350}}\n"
      "detector: {name: maxvalue}\n"
      "laser: {backend: gpiod, chip: gpiochip0, line: LASER_EN, mode: alternate" +
      std::string(with_strobe ? ", strobe_line: STROBE" : "") +
      "}\n"
      "lcm: {url: \"file://" +
      lcm_log.string() + "?mode=w\", image_every_n: 0, status_period_s: 0.05}\n";
  daemon::DaemonConfig config =
      daemon::parse_config(hal::load_yaml_text(text, name + ".yaml"), name + ".yaml");
  daemon::Backends backends = daemon::create_backends(config);
  PathRun run;
  std::string error;
  EXPECT_TRUE(backends.laser->open(&error)) << error;
  hal::ExposureStrobe* strobe = backends.laser->strobe();
  EXPECT_EQ(strobe != nullptr, with_strobe);
  if (strobe != nullptr) {
    EXPECT_TRUE(strobe->open(&error)) << error;
  }
  StrobedCamera camera(script, strobe != nullptr ? &strobe->history() : nullptr);
  {
    lcm::LCM lcm(config.lcm_url);
    daemon::FramePath path(config, camera, *backends.laser, *backends.detector, lcm);
    EXPECT_TRUE(path.start(&error)) << error;
    for (int i = 0; i < 500 && !path.source_ended(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // a status after the last frame
    path.stop();
    run.summary = path.summary();
  }
  lcm::LogFile log(lcm_log.string(), "r");
  while (const lcm::LogEvent* event = log.readNextEvent()) {
    if (event->channel == "LASERLINE_PROFILE") {
      laserline::profile_t p;
      if (p.decode(event->data, 0, static_cast<int>(event->datalen)) > 0) {
        run.laser_on[p.sequence] = p.laser_on;
      }
    } else if (event->channel == "LASERLINE_STATUS") {
      laserline::status_t s;
      if (s.decode(event->data, 0, static_cast<int>(event->datalen)) > 0) {
        run.statuses.push_back(s);
      }
    }
  }
  return run;
}

const std::vector<Exposure> kScript = {Exposure::kAfterSwitch,  Exposure::kAfterSwitch,
                                       Exposure::kAfterSwitch,  Exposure::kAfterSwitch,
                                       Exposure::kAcrossSwitch, Exposure::kAfterSwitch,
                                       Exposure::kBeforeSwitch, Exposure::kAfterSwitch,
                                       Exposure::kAfterSwitch,  Exposure::kAfterSwitch};

// With the strobe, frame 4 (switched on during its exposure) and frame 6 (switched on only after
// its exposure ended) are the late switches, exactly, and frame 6 was exposed with the laser off
// although it asked for on. The estimate (the camera's timestamp mapped to the host clock, late
// by the transfer delay) sees neither.
TEST(StrobeFramePath, ExposuresAcrossOrBeforeTheirSwitchAreLateSwitchesExactly) {
  const PathRun strobed = run_path(kScript, true, "strobed");
  ASSERT_EQ(strobed.summary.frames_captured, 10);
  EXPECT_EQ(strobed.summary.strobe_matched, 10);
  EXPECT_EQ(strobed.summary.strobe_unmatched, 0);
  EXPECT_EQ(strobed.summary.laser_late_switches, 2);
  const std::map<std::int64_t, bool> expected = {
      {0, true},  {1, false}, {2, true},  {3, false}, {4, true},  // partly lit counts as lit
      {5, false}, {6, false}, {7, false}, {8, true},  {9, false}};
  EXPECT_EQ(strobed.laser_on, expected);
  ASSERT_FALSE(strobed.statuses.empty());
  EXPECT_EQ(strobed.statuses.back().strobe_state, "ok");
  EXPECT_EQ(strobed.statuses.back().laser_late_switches, 2);
  EXPECT_EQ(strobed.statuses.back().strobe_unmatched_frames, 0);

  const PathRun estimated = run_path(kScript, false, "estimated");
  ASSERT_EQ(estimated.summary.frames_captured, 10);
  EXPECT_EQ(estimated.summary.laser_late_switches, 0) << "the estimate misses both";
  EXPECT_TRUE(estimated.laser_on.at(6)) << "the estimate claims what frame 6 asked for";
  ASSERT_FALSE(estimated.statuses.empty());
  EXPECT_EQ(estimated.statuses.back().strobe_state, "") << "no strobe configured";
}

// ---- laserlined with the shim preloaded, its strobe wire silent --------------------------------

struct PinEvent {
  std::int64_t mono_ns = 0;
  unsigned offset = 0;
  int level = 0;
  std::string event;
};

std::vector<PinEvent> read_pins(const std::filesystem::path& path) {
  std::vector<PinEvent> events;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream words(line);
    PinEvent e;
    std::int64_t wall = 0;
    std::string consumer;
    if (words >> e.mono_ns >> wall >> e.offset >> e.level >> e.event >> consumer) {
      events.push_back(e);
    }
  }
  return events;
}

laserline::test_support::CommandResult run_daemon(const std::string& config,
                                                  const std::filesystem::path& pins,
                                                  const std::string& args) {
  const std::filesystem::path path = g_dir / (pins.stem().string() + ".yaml");
  std::ofstream(path) << config;
  return laserline::test_support::run_command(
      std::string("LD_PRELOAD=") + GPIOCHIP_SHIM_PATH +
      " LASERLINE_GPIO_SHIM_LOG=" + pins.string() + " LASERLINE_GPIO_SHIM_LINES=" + kLines +
      " ASAN_OPTIONS=verify_asan_link_order=0 " + LASERLINED_PATH + " --config " + path.string() +
      " " + args);
}

std::string daemon_config(const std::string& strobe, const std::filesystem::path& lcm_log) {
  return "camera: {frame_rate_hz: 100, timeout_ms: 200, sim: {tilt_y_deg: 8, stall_after_s: 0.5, "
         "stall_for_s: 1}}\n"
         "calibration: {camera: {width: 320, height: 240, fx: 350, fy: 350}}\n"
         "detector: {name: maxvalue}\n"
         "laser: {backend: gpiod, chip: gpiochip0, line: LASER_EN, mode: alternate, "
         "frame_timeout_ms: 100, " +
         strobe + "}\nlcm: {url: \"file://" + lcm_log.string() +
         "?mode=w\", image_every_n: 0, status_period_s: 0.2}\n";
}

// No edge ever comes: every status says so in one line, every frame falls back to the estimate
// (alternate mode still alternates the profiles' laser_on), and the laser still goes off while
// frames stop and is left off at the end.
TEST(StrobeDaemon, ASilentStrobeIsOneReasonInTheStatusAndTheEstimateIsUsed) {
  const std::filesystem::path pins = g_dir / "silent.pins";
  const std::filesystem::path lcm_log = g_dir / "silent.lcm";
  const auto r = run_daemon(daemon_config("strobe_line: STROBE", lcm_log), pins, "--duration 2.5");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("laserlined: strobe line 'STROBE' of gpiochip0 (laserline-shim): 0 frames "
                       "matched to their exposure, "),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("forced off because frames stopped"), std::string::npos) << r.out;
  std::vector<laserline::status_t> statuses;
  std::vector<laserline::profile_t> profiles;
  lcm::LogFile log(lcm_log.string(), "r");
  ASSERT_TRUE(log.good());
  while (const lcm::LogEvent* event = log.readNextEvent()) {
    if (event->channel == "LASERLINE_STATUS") {
      laserline::status_t s;
      ASSERT_GT(s.decode(event->data, 0, static_cast<int>(event->datalen)), 0);
      statuses.push_back(s);
    } else if (event->channel == "LASERLINE_PROFILE") {
      laserline::profile_t p;
      ASSERT_GT(p.decode(event->data, 0, static_cast<int>(event->datalen)), 0);
      profiles.push_back(p);
    }
  }
  ASSERT_GE(statuses.size(), 5u);
  for (const auto& s : statuses) {
    EXPECT_EQ(s.strobe_state,
              "silent: no edge on line 'STROBE' of gpiochip0 (laserline-shim) since start; laser "
              "state from the camera's timestamps (estimate)");
  }
  EXPECT_EQ(statuses.back().strobe_unmatched_frames, statuses.back().frames_captured);
  ASSERT_GT(profiles.size(), 10u);
  // Before the stall (0.5 s at 100 Hz): the first frame after it asks for off whatever it is.
  for (std::size_t i = 1; i < 20; ++i) {
    if (profiles[i].sequence == profiles[i - 1].sequence + 1) {
      EXPECT_NE(profiles[i].laser_on, profiles[i - 1].laser_on) << "alternate: frame " << i;
    }
  }
  // The laser's line: requested off, off for the stall, left off.
  std::vector<PinEvent> laser;
  for (const auto& e : read_pins(pins))
    if (e.offset == 2) laser.push_back(e);
  ASSERT_GE(laser.size(), 2u);
  EXPECT_EQ(laser.front().event, "request");
  EXPECT_EQ(laser.front().level, 0);
  EXPECT_EQ(laser.back().level, 0);
  std::int64_t longest_off_ns = 0;
  for (std::size_t i = 1; i + 1 < laser.size(); ++i) {
    if (laser[i].level == 0 && laser[i + 1].level == 1) {
      longest_off_ns = std::max(longest_off_ns, laser[i + 1].mono_ns - laser[i].mono_ns);
    }
  }
  EXPECT_GT(longest_off_ns, 800 * kMs) << "off while frames stopped for 1 s";
}

// A strobe line that is not there stops the start in one line naming the chip and the line; the
// laser's line was requested off and is released off. --check-config --probe says the same.
TEST(StrobeDaemon, AMissingStrobeChipOrLineIsOneLineAndTheLaserStaysOff) {
  const std::filesystem::path lcm_log = g_dir / "missing.lcm";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"strobe_line: NOPE",
       "laserlined: laser (gpiod): strobe line 'NOPE' of gpiochip0 (laserline-shim): no line of "
       "that name\n"},
      {"strobe_line: STROBE, strobe_chip: gpiochip4",
       "laserlined: laser (gpiod): strobe line 'STROBE' on chip 'gpiochip4': cannot open: No such "
       "file or directory\n"},
  };
  int n = 0;
  for (const auto& [strobe, expected] : cases) {
    const std::filesystem::path pins = g_dir / ("missing" + std::to_string(++n) + ".pins");
    const auto r = run_daemon(daemon_config(strobe, lcm_log), pins, "--duration 1");
    EXPECT_EQ(r.exit_code, 1) << r.out;
    EXPECT_EQ(r.out, expected);
    const auto events = read_pins(pins);
    ASSERT_EQ(events.size(), 2u) << r.out;
    EXPECT_EQ(events[0].event, "request");
    EXPECT_EQ(events[0].level, 0);
    EXPECT_EQ(events[1].event, "release");
    EXPECT_EQ(events[1].level, 0);
    const auto check = run_daemon(daemon_config(strobe, lcm_log), pins, "--check-config --probe");
    EXPECT_EQ(check.exit_code, 1) << check.out;
    EXPECT_EQ(check.out.substr(0, check.out.find('\n') + 1), expected) << check.out;
  }
}

}  // namespace
}  // namespace laserline

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  laserline::g_dir =
      std::filesystem::temp_directory_path() / ("laserline_strobe_" + std::to_string(getpid()));
  std::filesystem::create_directories(laserline::g_dir);
  setenv("LASERLINE_GPIO_SHIM_LINES", laserline::kLines, 1);
  const int result = RUN_ALL_TESTS();
  std::filesystem::remove_all(laserline::g_dir);
  return result;
}
