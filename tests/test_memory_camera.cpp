// The `memory` camera backend: frames rendered by the simulator or loaded from an LCM log, held in
// memory and delivered at a set rate, alone and through the daemon's frame path (its LCM output
// written to a log, file://, and read back).
// Counts and content only: nothing here depends on how fast this machine is.
#include "hal/memory_camera.hpp"

#include <gtest/gtest.h>
#include <unistd.h>
#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <filesystem>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "allocation_counter.hpp"
#include "daemon/backends.hpp"
#include "daemon/config.hpp"
#include "daemon/frame_path.hpp"
#include "daemon/lcm_camera.hpp"
#include "hal/calibration.hpp"
#include "hal/registry.hpp"
#include "hal/sim/sim_camera.hpp"
#include "hal/sim/sim_laser.hpp"
#include "hal/sim/sim_options.hpp"
#include "hal/yaml_reader.hpp"
#include "lcmtypes/checked_decode.hpp"
#include "lcmtypes/lcm_log.hpp"

namespace laserline {
namespace {

daemon::DaemonConfig make_config(const std::string& text) {
  return daemon::parse_config(hal::load_yaml_text(text, "test.yaml"), "test.yaml");
}

constexpr const char* kSmallCamera = R"(
calibration:
  camera: {width: 320, height: 240, fx: 350, fy: 350}
)";

std::vector<std::uint8_t> grab_ok(hal::Camera& camera, hal::FrameInfo& info) {
  std::vector<std::uint8_t> pixels(camera.format().bytes());
  EXPECT_EQ(camera.grab(pixels, info, std::chrono::milliseconds(1000)), hal::GrabStatus::kOk);
  return pixels;
}

TEST(MemoryCamera, DeliversTheRenderedFramesLitAsTheLaserIsThenEndsAfterItsLoops) {
  daemon::DaemonConfig config = make_config(std::string(R"(
camera: {backend: memory, memory: {frames: 3, loops: 2, rate_hz: 0}, sim: {seed: 4}}
)") + kSmallCamera);
  hal::SimLaser laser;
  std::string error;
  ASSERT_TRUE(laser.open(&error));
  hal::CameraRequest request{&config.camera_options, &config.calibration, &laser,
                             config.laser_channel};
  std::unique_ptr<hal::Camera> camera = hal::make_camera("memory", request);
  ASSERT_TRUE(camera);
  EXPECT_TRUE(camera->paced_by_consumer()) << "rate_hz 0: as fast as the frame path takes them";
  ASSERT_TRUE(camera->open(&error)) << error;

  // The reference: the simulator's own camera on the same section, rendering frame by frame.
  daemon::DaemonConfig same = make_config(std::string(R"(
camera: {backend: sim, sim: {seed: 4}}
)") + kSmallCamera);
  hal::CameraRequest sim_request{&same.camera_options, &same.calibration, nullptr,
                                 same.laser_channel};
  std::unique_ptr<hal::SimCamera> sim = hal::make_sim_camera(sim_request);
  std::vector<std::uint8_t> expected(sim->format().bytes());

  for (std::uint64_t k = 0; k < 6; ++k) {
    const bool on = k % 3 != 1;  // lit, unlit, lit, ...: each frame is held both ways
    laser.set(on, k, nullptr);
    hal::FrameInfo info;
    const std::vector<std::uint8_t> pixels = grab_ok(*camera, info);
    hal::FrameInfo expected_info;
    sim->render_frame(k % 3, on, expected, expected_info);
    EXPECT_EQ(info.sequence, k) << "numbered in the order due, across loops";
    EXPECT_EQ(info.laser_on, on) << "frame " << k;
    EXPECT_TRUE(pixels == expected)
        << "frame " << k << " is not rendered frame " << k % 3 << (on ? " lit" : " unlit");
    EXPECT_EQ(info.exposure_us, expected_info.exposure_us);
  }
  hal::FrameInfo info;
  std::vector<std::uint8_t> pixels(camera->format().bytes());
  EXPECT_EQ(camera->grab(pixels, info, std::chrono::milliseconds(100)), hal::GrabStatus::kStopped)
      << "two loops of three frames, then the source ends";
  EXPECT_EQ(camera->health().skipped_frames, 0);
}

TEST(MemoryCamera, RefusesARateTooLowToPace) {
  daemon::DaemonConfig config = make_config(std::string(R"(
camera: {backend: memory, memory: {rate_hz: 0.01}}
)") + kSmallCamera);
  hal::CameraRequest request{&config.camera_options, &config.calibration, nullptr,
                             config.laser_channel};
  try {
    hal::make_camera("memory", request);
    FAIL() << "rate_hz 0.01 accepted";
  } catch (const hal::ConfigError& e) {
    EXPECT_EQ(std::string(e.what()),
              "test.yaml:2: camera.memory.rate_hz: must be 0 (as fast as the frame path takes "
              "them) or 0.1 to 1000000");
  }
}

TEST(MemoryCamera, AGrabAllocatesNothing) {
  daemon::DaemonConfig config = make_config(std::string(R"(
camera: {backend: memory, memory: {frames: 3, rate_hz: 0}}
)") + kSmallCamera);
  hal::SimLaser laser;
  hal::CameraRequest request{&config.camera_options, &config.calibration, &laser,
                             config.laser_channel};
  std::unique_ptr<hal::Camera> camera = hal::make_camera("memory", request);
  std::string error;
  ASSERT_TRUE(camera->open(&error)) << error;
  std::vector<std::uint8_t> pixels(camera->format().bytes());
  hal::FrameInfo info;
  ASSERT_TRUE(testing::allocation_counter_works());
  testing::start_counting_allocations();
  int delivered = 0;
  for (int k = 0; k < 20; ++k) {
    laser.set(k % 2 == 0, static_cast<std::uint64_t>(k), nullptr);
    delivered += camera->grab(pixels, info, std::chrono::milliseconds(100)) == hal::GrabStatus::kOk;
  }
  const testing::Allocations counted = testing::stop_counting_allocations();
  EXPECT_EQ(delivered, 20);
  EXPECT_EQ(counted.count, 0) << counted.bytes << " bytes allocated over 20 grabs";
}

TEST(MemoryCamera, ALateCallerGetsTheBufferedFramesAndLosesOlderOnes) {
  // 10 frames/s and a queue of two: after 5.5 periods away, the frames due in the last two
  // periods are still there and come at once; the ones before them are lost and counted.
  daemon::DaemonConfig config = make_config(std::string(R"(
camera: {backend: memory, memory: {frames: 4, rate_hz: 10, buffers: 2}}
)") + kSmallCamera);
  hal::CameraRequest request{&config.camera_options, &config.calibration, nullptr,
                             config.laser_channel};
  std::unique_ptr<hal::Camera> camera = hal::make_camera("memory", request);
  std::string error;
  ASSERT_TRUE(camera->open(&error)) << error;
  hal::FrameInfo first, late, next;
  grab_ok(*camera, first);
  EXPECT_EQ(first.sequence, 0u);
  std::this_thread::sleep_for(std::chrono::milliseconds(550));
  grab_ok(*camera, late);
  grab_ok(*camera, next);
  EXPECT_GE(late.sequence, 3u) << "frames 1 and 2 were overwritten in a queue of two";
  EXPECT_EQ(camera->health().skipped_frames, static_cast<std::int64_t>(late.sequence) - 1)
      << "every frame not delivered is counted";
  EXPECT_GE(late.arrival_mono_ns - late.exposure_mono_ns, 100'000'000)
      << "the oldest frame of the queue comes first: one due at least a period before";
  EXPECT_EQ(next.sequence, late.sequence + 1) << "the next frame was queued too";
  EXPECT_EQ(late.camera_ns, static_cast<std::int64_t>(late.sequence) * 100'000'000)
      << "a queued frame keeps the time it was due";
}

// An LCM log of `count` 32x16 frames: frame s has pixels s * 7 + i and the laser on when s is even.
void write_log(const std::string& path, int count) {
  lcm::LogFile log(path, "w");
  ASSERT_TRUE(log.good());
  for (int s = 0; s < count; ++s) {
    laserline::image_t m;
    m.utime = 1'700'000'000'000'000 + s * 50'000;
    m.sequence = 100 + s;
    m.camera_timestamp_ns = s * 50'000'000;
    m.laser_on = s % 2 == 0;
    m.width = 32;
    m.height = 16;
    m.row_stride = 32;
    m.pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
    m.compression = laserline::image_t::COMPRESSION_NONE;
    m.roi_x = 0;
    m.roi_y = 0;
    m.downscale = 1;
    m.exposure_us = 500 + s;
    m.size = 32 * 16;
    m.data.resize(32 * 16);
    for (int i = 0; i < m.size; ++i)
      m.data[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(s * 7 + i);
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize()));
    m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
    lcm::LogEvent e;
    e.timestamp = m.utime;
    e.channel = "LASERLINE_IMAGE";
    e.datalen = static_cast<std::int32_t>(bytes.size());
    e.data = bytes.data();
    ASSERT_EQ(log.writeEvent(&e), 0);
  }
}

class MemoryCameraLog : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = std::filesystem::temp_directory_path() /
            ("laserline_memory_" + std::to_string(getpid()) + ".lcmlog");
    write_log(path_.string(), 5);
  }
  void TearDown() override { std::filesystem::remove(path_); }

  // The memory camera on the log with the `camera.memory` options given.
  std::unique_ptr<hal::Camera> make(const std::string& memory) {
    config_ = make_config("camera: {backend: memory, memory: " + memory + ", lcm: {url: \"file://" +
                          path_.string() + "\"}}\n" +
                          "calibration:\n  camera: {width: 32, height: 16, fx: 40, fy: 40}\n");
    hal::CameraRequest request{&config_.camera_options, &config_.calibration, nullptr,
                               config_.laser_channel};
    std::unique_ptr<hal::Camera> camera = hal::make_camera("memory", request);
    config_.camera_options.finish();
    return camera;
  }

  std::filesystem::path path_;
  daemon::DaemonConfig config_;
};

TEST_F(MemoryCameraLog, HoldsTheLogsFirstFramesWithTheirLaserStateAndLoopsOverThem) {
  std::unique_ptr<hal::Camera> camera = make("{source: lcm, frames: 3, loops: 2, rate_hz: 0}");
  ASSERT_TRUE(camera);
  std::string error;
  ASSERT_TRUE(camera->open(&error)) << error;
  EXPECT_EQ(dynamic_cast<hal::MemoryCamera&>(*camera).frames(), 3);
  for (std::uint64_t k = 0; k < 6; ++k) {
    hal::FrameInfo info;
    const std::vector<std::uint8_t> pixels = grab_ok(*camera, info);
    const auto s = static_cast<int>(k % 3);
    EXPECT_EQ(info.sequence, k);
    EXPECT_EQ(info.laser_on, s % 2 == 0) << "the laser as recorded, frame " << k;
    EXPECT_EQ(info.exposure_us, 500 + s);
    ASSERT_EQ(pixels.size(), 32u * 16u);
    for (std::size_t i = 0; i < pixels.size(); ++i) {
      ASSERT_EQ(pixels[i], static_cast<std::uint8_t>(s * 7 + static_cast<int>(i)))
          << "frame " << k << " pixel " << i;
    }
  }
  hal::FrameInfo info;
  std::vector<std::uint8_t> pixels(32 * 16);
  EXPECT_EQ(camera->grab(pixels, info, std::chrono::milliseconds(100)), hal::GrabStatus::kStopped);
}

TEST_F(MemoryCameraLog, HoldsAllOfAShorterLog) {
  std::unique_ptr<hal::Camera> camera = make("{source: lcm, frames: 50}");
  std::string error;
  ASSERT_TRUE(camera->open(&error)) << error;
  EXPECT_EQ(dynamic_cast<hal::MemoryCamera&>(*camera).frames(), 5);
}

TEST_F(MemoryCameraLog, RefusesALiveSourceAndItself) {
  try {
    make("{source: memory}");
    FAIL() << "source: memory accepted";
  } catch (const hal::ConfigError& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("camera.memory.source"), std::string::npos) << e.what();
  }
  config_ = make_config(
      "camera: {backend: memory, memory: {source: lcm}, lcm: {url: \"udpm://239.255.76.67:7667\"}}"
      "\ncalibration:\n  camera: {width: 32, height: 16, fx: 40, fy: 40}\n");
  hal::CameraRequest request{&config_.camera_options, &config_.calibration, nullptr,
                             config_.laser_channel};
  try {
    hal::make_camera("memory", request);
    FAIL() << "a live LCM source accepted";
  } catch (const hal::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("camera.memory.source"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("live"), std::string::npos) << e.what();
  }
}

// The frame path's per-frame budget and latency windows follow the rate the memory camera
// delivers at (rate_hz), not camera.frame_rate_hz; as fast as the frame path takes them (rate_hz
// 0), camera.frame_rate_hz stays the nominal rate.
TEST(MemoryCameraFramePath, TakesTheCamerasOwnRateAsTheNominalRate) {
  for (const auto& [memory, nominal] : {std::pair{"{frames: 2, rate_hz: 400}", 400.0},
                                        std::pair{"{frames: 2, rate_hz: 0}", 25.0}}) {
    SCOPED_TRACE(memory);
    daemon::DaemonConfig config =
        make_config(std::string("camera:\n  backend: memory\n"
                                "  frame_rate_hz: 25\n  memory: ") +
                    memory + "\nlcm: {url: \"memq://\", image_every_n: 0}\n" + kSmallCamera);
    daemon::Backends backends = daemon::create_backends(config);
    std::string error;
    ASSERT_TRUE(backends.laser->open(&error)) << error;
    ASSERT_TRUE(backends.camera->open(&error)) << error;
    lcm::LCM lcm(config.lcm_url);
    ASSERT_TRUE(lcm.good());
    daemon::FramePath path(config, *backends.camera, *backends.laser, *backends.detector, lcm);
    ASSERT_TRUE(path.start(&error)) << error;
    EXPECT_EQ(path.frame_rate_hz(), nominal);
    path.stop();
    EXPECT_FALSE(backends.laser->is_on());
  }
}

TEST(MemoryCameraFramePath, DeliversItsFramesAtTheSetRateThroughTheDaemon) {
  // 100 frames/s: frame n is due 10 ms after frame 0, which its camera timestamp says exactly.
  // Laser alternating: the unlit frames are the ones held without the laser (maxvalue finds
  // almost nothing in them, and a line in the lit ones).
  // Published into an LCM log (one writer, the publisher thread), read back once stopped.
  const std::filesystem::path log_path =
      std::filesystem::temp_directory_path() /
      ("laserline_memory_path_" + std::to_string(getpid()) + ".lcmlog");
  daemon::DaemonConfig config = make_config(std::string(R"(
camera:
  backend: memory
  frame_rate_hz: 100
  memory: {frames: 4, loops: 10}
  sim: {ambient: 20, texture_contrast: 0.3, laser_peak: 150, noise_sigma: 1, tilt_y_deg: 8}
laser: {mode: alternate}
detector: {name: maxvalue}
lcm: {url: "file://)") + log_path.string() + R"(?mode=w", image_every_n: 0}
)" + kSmallCamera);
  daemon::Backends backends = daemon::create_backends(config);
  std::string error;
  ASSERT_TRUE(backends.laser->open(&error));
  ASSERT_TRUE(backends.camera->open(&error)) << error;
  EXPECT_FALSE(backends.camera->paced_by_consumer()) << "a set rate: a free-running camera";
  daemon::FramePathSummary s;
  std::int64_t skipped = 0;
  {
    lcm::LCM lcm(config.lcm_url);
    ASSERT_TRUE(lcm.good());
    daemon::FramePath path(config, *backends.camera, *backends.laser, *backends.detector, lcm);
    ASSERT_TRUE(path.start(&error)) << error;
    while (!path.source_ended())
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    path.stop();
    s = path.summary();
    skipped = backends.camera->health().skipped_frames;
  }
  std::vector<laserline::profile_t> profiles;
  messages::LcmLogReader reader;
  ASSERT_TRUE(reader.open(log_path.string(), &error)) << error;
  messages::LcmLogReader::Event event;
  messages::LcmLogReader::Damage damage;
  messages::Limits limits;
  while (reader.next(&event, &damage)) {
    if (event.channel != config.profile_channel) continue;
    profiles.emplace_back();
    ASSERT_TRUE(
        messages::decode(event.data.data(), event.data.size(), &profiles.back(), limits, &error))
        << error;
  }
  std::filesystem::remove(log_path);
  EXPECT_EQ(s.frames_captured + skipped, 40) << "ten loops of four frames, each delivered or lost";
  EXPECT_EQ(s.frames_processed, s.frames_captured - s.frames_dropped);
  EXPECT_FALSE(backends.laser->is_on());

  ASSERT_EQ(static_cast<std::int64_t>(profiles.size()), s.profiles_published);
  ASSERT_GE(profiles.size(), 20u) << "most of the 40 frames arrive on any machine";
  std::int64_t previous = -1;
  int lit = 0, unlit = 0;
  for (const laserline::profile_t& p : profiles) {
    EXPECT_GT(p.sequence, previous);
    EXPECT_LT(p.sequence, 40);
    previous = p.sequence;
    EXPECT_EQ(p.camera_timestamp_ns, p.sequence * 10'000'000) << "frame " << p.sequence;
    EXPECT_EQ(p.width, 320);
    (p.laser_on ? lit : unlit) += 1;
    if (p.laser_on) {
      EXPECT_GT(p.num_points, 250) << "lit frame " << p.sequence;
    } else {
      EXPECT_LT(p.num_points, 30) << "unlit frame " << p.sequence;
    }
  }
  EXPECT_GT(lit, 5);
  EXPECT_GT(unlit, 5);
}

}  // namespace
}  // namespace laserline
