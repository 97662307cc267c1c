// The daemon's frame path in-process: no allocation once running (counted over a steady-state
// run), and the laser goes off when frames stop.
#include "daemon/frame_path.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <thread>
#include <vector>

#include "allocation_counter.hpp"
#include "daemon/backends.hpp"
#include "hal/clock.hpp"
#include "private_network.hpp"

namespace laserline::daemon {
namespace {

std::string g_namespace_problem = "not tried";

// Frames the path must at least get through in the measured windows below.
#ifdef LASERLINE_SANITIZED
constexpr int kMinFrames = 20;    // sanitized code runs several times slower...
constexpr int kCountSeconds = 5;  // ...so it is watched for longer
#else
constexpr int kMinFrames = 100;
constexpr int kCountSeconds = 2;
#endif

DaemonConfig make_config(const std::string& text) {
  return parse_config(hal::load_yaml_text(text, "test.yaml"), "test.yaml");
}

TEST(FramePath, SteadyStateAllocatesNothingOnAnyThread) {
  if (!g_namespace_problem.empty()) {
    GTEST_SKIP() << "no private network namespace for LCM over UDP: " << g_namespace_problem;
  }
  // High frame rate, raw frames (zlib, which claims no allocation either) and status often, so
  // every publishing path runs in the window.
  DaemonConfig config = make_config(R"(
camera: {frame_rate_hz: 200, sim: {tilt_y_deg: 8}}
calibration:
  camera: {width: 640, height: 480, fx: 700, fy: 700}
laser: {mode: alternate}
lcm: {url: "udpm://239.255.76.67:7667?ttl=0", image_every_n: 5, image_compression: zlib,
      status_period_s: 0.2}
)");
  Backends backends = create_backends(config);
  std::string error;
  ASSERT_TRUE(backends.laser->open(&error));
  ASSERT_TRUE(backends.camera->open(&error));
  lcm::LCM lcm(config.lcm_url);
  ASSERT_TRUE(lcm.good());
  FramePath path(config, *backends.camera, *backends.laser, *backends.detector, lcm);
  // The counter must see allocations, or a zero below would prove nothing.
  ASSERT_TRUE(testing::allocation_counter_works()) << "allocation counting does not work";

  ASSERT_TRUE(path.start(&error)) << error;
  std::this_thread::sleep_for(std::chrono::seconds(1));  // warm-up: first status, first image
  const auto processed_before = path.counters().frames_processed.load();
  testing::start_counting_allocations();
  std::this_thread::sleep_for(std::chrono::seconds(kCountSeconds));
  const testing::Allocations counted = testing::stop_counting_allocations();
  const auto processed = path.counters().frames_processed.load() - processed_before;
  const long allocations = counted.count;
  const long bytes = counted.bytes;
  path.stop();
  const FramePathSummary s = path.summary();
  EXPECT_GT(processed, kMinFrames) << "the frame path must have been busy while counting";
  EXPECT_GT(s.images_published, kMinFrames / 10) << "every 5th frame is published raw";
  EXPECT_EQ(s.publish_errors, 0);
  EXPECT_EQ(allocations, 0) << bytes << " bytes allocated over " << processed << " frames";
}

// Commands are carried out by the camera thread (the detector's region by the worker) between
// grabs without allocating: parsed beforehand (as the command thread does), then submitted and
// their results taken while every allocation of the process is counted.
TEST(FramePath, CommandsAreCarriedOutBetweenGrabsWithoutAllocating) {
  if (!g_namespace_problem.empty()) {
    GTEST_SKIP() << "no private network namespace for LCM over UDP: " << g_namespace_problem;
  }
  DaemonConfig config = make_config(R"(
camera: {frame_rate_hz: 100, sim: {tilt_y_deg: 8}}
calibration:
  camera: {width: 320, height: 240, fx: 350, fy: 350}
laser: {mode: on}
detector: {name: maxvalue}
lcm: {url: "udpm://239.255.76.67:7667?ttl=0", image_every_n: 0, status_period_s: 0.2}
)");
  Backends backends = create_backends(config);
  std::string error;
  ASSERT_TRUE(backends.laser->open(&error));
  ASSERT_TRUE(backends.camera->open(&error));
  lcm::LCM lcm(config.lcm_url);
  ASSERT_TRUE(lcm.good());
  FramePath path(config, *backends.camera, *backends.laser, *backends.detector, lcm);
  std::vector<Command> commands;
  for (auto [name, value] : {std::pair{"exposure_us", "2500"}, std::pair{"gain_db", "6"},
                             std::pair{"laser.mode", "alternate"},
                             std::pair{"detector.roi", "10,20,100,50"}, std::pair{"get", ""}}) {
    laserline::command_t message;
    message.id = static_cast<std::int64_t>(commands.size()) + 1;
    message.name = name;
    message.value = value;
    Command command;
    pipeline::DetectorOptions options;
    ASSERT_TRUE(parse_command(message, config, *backends.camera, config.detector_options, &command,
                              &options, &error))
        << error;
    commands.push_back(command);
  }
  Command done;
  ASSERT_TRUE(testing::allocation_counter_works()) << "allocation counting does not work";
  ASSERT_TRUE(path.start(&error)) << error;
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // warm-up: first status
  testing::start_counting_allocations();
  std::vector<Command>::size_type answered = 0;
  for (const Command& command : commands) {
    ASSERT_TRUE(path.submit_command(command));
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(2);
    while (!path.take_command_result(&done) && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    if (done.id != command.id) break;
    ++answered;
    EXPECT_TRUE(done.result.accepted) << command.setting.name << ": " << done.result.reason;
  }
  const testing::Allocations counted = testing::stop_counting_allocations();
  path.stop();
  EXPECT_EQ(answered, commands.size());
  EXPECT_STREQ(done.result.in_force,
               "exposure_us=2500 gain_db=6 frame_rate_hz=100 laser.mode=alternate");
  EXPECT_EQ(counted.count, 0) << counted.bytes << " bytes allocated";
  // The worker set the region on the detector in place.
  EXPECT_EQ(backends.detector->region(), (pipeline::DetectionRegion{10, 20, 100, 50}));
}

TEST(FramePath, LaserGoesOffWhenFramesStopAndBackOnWhenTheyReturn) {
  DaemonConfig config = make_config(R"(
camera: {frame_rate_hz: 50, timeout_ms: 1000, sim: {stall_after_s: 0.6, stall_for_s: 1.5}}
calibration:
  camera: {width: 320, height: 240, fx: 350, fy: 350}
laser: {mode: on, frame_timeout_ms: 150}
lcm: {url: "memq://", image_every_n: 0}
)");
  Backends backends = create_backends(config);
  std::string error;
  ASSERT_TRUE(backends.laser->open(&error));
  EXPECT_FALSE(backends.laser->is_on()) << "off at start";
  ASSERT_TRUE(backends.camera->open(&error));
  lcm::LCM lcm(config.lcm_url);
  FramePath path(config, *backends.camera, *backends.laser, *backends.detector, lcm);
  ASSERT_TRUE(path.start(&error)) << error;

  // Play the main thread's role: enforce safety every 10 ms and watch the laser.
  std::int64_t worst_on_without_frames_ns = 0;
  bool was_off_in_stall = false, back_on_after = false;
  const std::int64_t t0 = hal::monotonic_ns();
  while (hal::monotonic_ns() - t0 < 3'000'000'000) {
    path.enforce_laser_safety();
    const std::int64_t now = hal::monotonic_ns();
    const std::int64_t since_frame = now - path.counters().last_frame_mono_ns.load();
    const bool on = backends.laser->is_on();
    if (on) worst_on_without_frames_ns = std::max(worst_on_without_frames_ns, since_frame);
    const double t = static_cast<double>(now - t0) * 1e-9;
    if (t > 1.0 && t < 2.0 && !on) was_off_in_stall = true;
    if (t > 2.5 && on) back_on_after = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  path.stop();
  EXPECT_FALSE(backends.laser->is_on()) << "off after stop";
  EXPECT_TRUE(was_off_in_stall);
  EXPECT_TRUE(back_on_after) << "frames came back, so the laser must too";
  // Off within the frame timeout (150 ms) plus this loop's 10 ms tick and scheduling slack.
  EXPECT_LT(worst_on_without_frames_ns, 250'000'000);
  const FramePathSummary s = path.summary();
  EXPECT_GE(s.grab_timeouts, 1);
  EXPECT_GE(path.counters().laser_safety_offs.load() + s.grab_timeouts, 1);
  EXPECT_GT(s.profiles_published, kMinFrames / 5) << "frames flowed before and after the stall";
}

}  // namespace
}  // namespace laserline::daemon

int main(int argc, char** argv) {
  laserline::daemon::g_namespace_problem = laserline::test::enter_private_network();
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
