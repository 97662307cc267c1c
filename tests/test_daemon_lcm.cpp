// End-to-end: the real laserlined process on the simulated scanner, received over real UDP
// multicast LCM on loopback inside a private network namespace made by this test binary.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "hal/clock.hpp"
#include "hal/sim/sim_options.hpp"
#include "hal/sim/sim_scene.hpp"
#include "hal/yaml_reader.hpp"
#include "private_network.hpp"
#include "run_command.hpp"

namespace {

std::string g_namespace_problem;  // empty when the private namespace is up

#ifdef LASERLINE_SANITIZED
constexpr int kSlowdown = 5;  // sanitized code is this much slower: fewer frames get through
#else
constexpr int kSlowdown = 1;
#endif

constexpr const char* kUrl = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304";

std::string test_config(const std::string& extra_laser = "mode: on") {
  return std::string(R"(camera:
  backend: sim
  frame_rate_hz: 50
  sim: {seed: 7, distance_m: 1.0, tilt_y_deg: 10, texture_contrast: 0.4, ambient: 25,
        laser_peak: 190, noise_sigma: 1.5, sway_m: 0.02, sway_deg: 0.5}
calibration:
  camera: {width: 640, height: 480, fx: 700, fy: 700, cx: 319.5, cy: 239.5}
  laser: {baseline_m: 0.2, angle_deg: 80, sheet_width_m: 0.003}
laser: {)") +
         extra_laser + R"(}
detector: {name: maxvalue, maxvalue: {threshold: 60}}
lcm: {url: ")" +
         kUrl + R"(", image_every_n: 10, status_period_s: 1.0}
)";
}

// The simulated scene a configuration runs, rebuilt for its exact ground truth.
laserline::hal::SimScene scene_of(const std::string& config_text) {
  laserline::daemon::DaemonConfig config = laserline::daemon::parse_config(
      laserline::hal::load_yaml_text(config_text, "test.yaml"), "test.yaml");
  laserline::hal::YamlMap sim = config.camera_options.map("sim");
  return laserline::hal::SimScene(
      laserline::hal::read_sim_options(sim, config.calibration, config.frame_rate_hz));
}

// Subscribed with plain functions (subscribeFunction): GCC 12's UBSan misreports LCM's
// member-function-pointer dispatch as a misaligned access.
struct Received {
  std::vector<laserline::profile_t> profiles;
  std::vector<std::int64_t> profile_recv_utime;
  std::vector<laserline::status_t> statuses;

  static void on_profile(const lcm::ReceiveBuffer* rbuf, const std::string&,
                         const laserline::profile_t* p, Received* self) {
    self->profiles.push_back(*p);
    self->profile_recv_utime.push_back(rbuf->recv_utime);
  }
  static void on_status(const lcm::ReceiveBuffer*, const std::string&, const laserline::status_t* s,
                        Received* self) {
    self->statuses.push_back(*s);
  }
  void subscribe(lcm::LCM& lcm) {
    lcm.subscribeFunction("LASERLINE_PROFILE", &Received::on_profile, this);
    lcm.subscribeFunction("LASERLINE_STATUS", &Received::on_status, this);
  }
};

class DaemonOverLcm : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!g_namespace_problem.empty()) {
      GTEST_SKIP() << "no private network namespace: " << g_namespace_problem;
    }
    dir_ = std::filesystem::temp_directory_path() /
           ("laserline_it_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
  }

  std::string write_config(const std::string& text) {
    const auto path = (dir_ / "laserline.yaml").string();
    std::ofstream(path) << text;
    return path;
  }

  void start_daemon(const std::string& config_path) {
    // The daemon must not outlive this test, even when the test dies (a sanitizer abort skips
    // TearDown).
    pid_ = laserline::test_support::spawn_tied_child({LASERLINED_PATH, "--config", config_path},
                                                     (dir_ / "daemon.log").string());
    ASSERT_GE(pid_, 0);
  }

  // Sends `sig` and returns the seconds until the daemon exited; *status gets its wait status.
  double stop_daemon(int sig, int* status) {
    const std::int64_t t0 = laserline::hal::monotonic_ns();
    kill(pid_, sig);
    int st = 0;
    while (waitpid(pid_, &st, WNOHANG) == 0) {
      if (laserline::hal::monotonic_ns() - t0 > 10'000'000'000) {
        kill(pid_, SIGKILL);
        waitpid(pid_, &st, 0);
        break;
      }
      usleep(2000);
    }
    pid_ = -1;
    *status = st;
    return static_cast<double>(laserline::hal::monotonic_ns() - t0) * 1e-9;
  }

  std::string daemon_log() const {
    std::ifstream in(dir_ / "daemon.log");
    return std::string(std::istreambuf_iterator<char>(in), {});
  }

  void receive_for(lcm::LCM& lcm, double seconds) {
    const std::int64_t end =
        laserline::hal::monotonic_ns() + static_cast<std::int64_t>(seconds * 1e9);
    while (laserline::hal::monotonic_ns() < end)
      lcm.handleTimeout(50);
  }

  // Runs the daemon on `config_text` for `seconds` while receiving, stops it with `sig`, and
  // checks it exited cleanly within one second. Returns what was received (incl. the last status).
  Received run_daemon(const std::string& config_text, double seconds, int sig) {
    const std::string config_path = write_config(config_text);
    lcm::LCM lcm(kUrl);
    EXPECT_TRUE(lcm.good());
    Received rx;
    rx.subscribe(lcm);
    start_daemon(config_path);
    // The window starts at the first profile, so that a slow start (sanitizers) costs nothing.
    const std::int64_t give_up = laserline::hal::monotonic_ns() + 30'000'000'000;
    while (rx.profiles.empty() && laserline::hal::monotonic_ns() < give_up)
      lcm.handleTimeout(50);
    EXPECT_FALSE(rx.profiles.empty()) << "no profile within 30 s: " << daemon_log();
    receive_for(lcm, seconds);
    stop_utime_ = laserline::hal::wall_ns() / 1000;
    int status = 0;
    const double stop_s = stop_daemon(sig, &status);
    receive_for(lcm, 0.3);  // the final status
    // (Sanitized code runs several times slower: a frame in the detector then takes longer.)
    EXPECT_LT(stop_s, 1.0 * kSlowdown) << "SIGINT/SIGTERM must stop the daemon within one second";
    EXPECT_TRUE(WIFEXITED(status)) << daemon_log();
    EXPECT_EQ(WEXITSTATUS(status), 0) << daemon_log();
    return rx;
  }

  std::filesystem::path dir_;
  pid_t pid_ = -1;
  std::int64_t stop_utime_ = 0;
};

TEST_F(DaemonOverLcm, ProfilesMatchTheSimulatorGroundTruth) {
  const std::string config_text = test_config();
  const Received rx = run_daemon(config_text, 3.5, SIGTERM);
  const std::int64_t now_utime = stop_utime_;

  // 50 Hz for ~3.5 s, minus start-up.
  ASSERT_GE(rx.profiles.size(), 100u / kSlowdown) << daemon_log();

  // Sequence numbers and timestamps.
  std::int64_t missing = 0;
  for (std::size_t i = 1; i < rx.profiles.size(); ++i) {
    const auto& a = rx.profiles[i - 1];
    const auto& b = rx.profiles[i];
    ASSERT_GT(b.sequence, a.sequence) << "sequence numbers must increase";
    missing += b.sequence - a.sequence - 1;
    const double dt_ms = static_cast<double>(b.utime - a.utime) / 1000.0;
    EXPECT_NEAR(dt_ms, 20.0 * static_cast<double>(b.sequence - a.sequence), 2.0)
        << "utime must follow the frame period, sequence " << b.sequence;
    EXPECT_GT(b.camera_timestamp_ns, a.camera_timestamp_ns);
  }
#ifndef LASERLINE_SANITIZED
  // Sanitized builds cannot render and process 50 frames a second; the simulated camera then
  // skips frames as a real one would, which the sequence numbers show.
  EXPECT_LE(missing, 2) << "no frames should be lost on an idle machine";
#endif
  for (std::size_t i = 0; i < rx.profiles.size(); ++i) {
    const auto& p = rx.profiles[i];
    EXPECT_LT(std::llabs(now_utime - p.utime), 5'000'000)
        << "utime is microseconds since the epoch";
    EXPECT_GT(rx.profile_recv_utime[i], p.utime) << "received after the exposure";
    EXPECT_TRUE(p.laser_on);
    EXPECT_EQ(p.width, 640);
    EXPECT_EQ(p.height, 480);
    EXPECT_EQ(p.detector, "maxvalue");
  }

  // Points against the exact ground truth of the same scene, rebuilt from the same file.
  laserline::hal::SimScene scene = scene_of(config_text);
  laserline::hal::SimGroundTruth truth;
  std::int64_t points = 0, far = 0, truth_columns = 0;
  double worst = 0, sum_sq = 0;
  std::int64_t matched = 0, not_triangulated = 0;
  double worst_depth_m = 0;
  for (const auto& p : rx.profiles) {
    scene.ground_truth(static_cast<std::uint64_t>(p.sequence), true, truth);
    for (float row : truth.position)
      truth_columns += std::isfinite(row) ? 1 : 0;
    for (const auto& pt : p.points) {
      ASSERT_GE(pt.u, 0);
      ASSERT_LT(pt.u, 640);
      const float expected = truth.position[static_cast<std::size_t>(pt.u)];
      ++points;
      const double err = std::isfinite(expected) ? std::abs(pt.v - expected) : 1e9;
      if (err > 0.5) ++far;
      if (std::isfinite(expected)) {
        worst = std::max(worst, err);
        sum_sq += err * err;
        ++matched;
        // Triangulated by the daemon: Z is the depth of the lit surface (0.5 px is 4 mm here).
        const double depth = truth.depth_m[static_cast<std::size_t>(pt.u)];
        if (std::isfinite(pt.xyz[0]) && std::isfinite(pt.xyz[1]) && std::isfinite(pt.xyz[2])) {
          worst_depth_m = std::max(worst_depth_m, std::abs(pt.xyz[2] - depth));
        } else {
          ++not_triangulated;
        }
      }
    }
  }
  EXPECT_EQ(far, 0) << "of " << points << " points, worst error " << worst << " px";
  EXPECT_EQ(not_triangulated, 0) << "every valid point arrives with finite xyz";
  EXPECT_LT(worst_depth_m, 0.005);
  RecordProperty("worst_depth_error_m", std::to_string(worst_depth_m));
  EXPECT_GE(static_cast<double>(points), 0.95 * static_cast<double>(truth_columns))
      << "the line should be found in nearly every column where it is visible";
  RecordProperty("worst_error_px", std::to_string(worst));
  RecordProperty(
      "rms_error_px",
      std::to_string(std::sqrt(sum_sq / static_cast<double>(std::max<std::int64_t>(matched, 1)))));
  RecordProperty("points", std::to_string(points));

  // Status at 1 Hz, and a final one saying the camera stopped with the laser off.
  ASSERT_GE(rx.statuses.size(), 3u);
  for (std::size_t i = 1; i + 1 < rx.statuses.size(); ++i) {
    const double dt = static_cast<double>(rx.statuses[i].utime - rx.statuses[i - 1].utime) * 1e-6;
    EXPECT_NEAR(dt, 1.0, 0.25);
  }
  const auto& last = rx.statuses.back();
  EXPECT_EQ(last.camera_state, "stopped");
  EXPECT_FALSE(last.laser_on);
  EXPECT_EQ(last.frames_dropped, 0);
  EXPECT_EQ(last.laser_errors, 0);
  EXPECT_GE(last.laser_switches, 2) << "on at start, off at stop";
  EXPECT_GE(last.profiles_published, static_cast<std::int64_t>(rx.profiles.size()));
  EXPECT_GT(rx.statuses[1].latency_samples, 0);
  EXPECT_GT(rx.statuses[1].latency_p99_ms, 0.0f);
  EXPECT_GT(rx.statuses[1].pipeline_p50_ms, 0.0f);
  EXPECT_LE(rx.statuses[1].pipeline_p50_ms, rx.statuses[1].latency_p50_ms)
      << "arrival comes after exposure";
}

// The paper's background detector in the daemon: a pan-tilt unit sweeping a wall lit as brightly
// as the laser, where the maximum-value assumption fails.
// lcm.profile_points: by default only the accepted points go out; `all` adds the rejected
// candidates (point_t.valid false), and the accepted points are the same either way.
TEST_F(DaemonOverLcm, ProfilesCarryTheAcceptedPointsUnlessAllAreAskedFor) {
  auto count = [](const Received& rx, std::int64_t* valid, std::int64_t* rejected) {
    *valid = *rejected = 0;
    for (const auto& p : rx.profiles) {
      for (const auto& pt : p.points)
        ++(pt.valid ? *valid : *rejected);
    }
  };
  // The background detector rejects candidates on this textured wall; maxvalue hardly does.
  std::string base = test_config();
  const std::string maxvalue = "detector: {name: maxvalue, maxvalue: {threshold: 60}}";
  ASSERT_NE(base.find(maxvalue), std::string::npos);
  base.replace(base.find(maxvalue), maxvalue.size(), "detector: {name: background}");
  std::int64_t valid = 0, rejected = 0;
  const Received accepted = run_daemon(base, 1.5, SIGTERM);
  count(accepted, &valid, &rejected);
  EXPECT_GT(valid, 0);
  EXPECT_EQ(rejected, 0) << "the default sends only accepted points";
  const double valid_per_profile =
      static_cast<double>(valid) / static_cast<double>(accepted.profiles.size());

  std::string all_config = base;
  const std::size_t at = all_config.find("image_every_n: 10");
  ASSERT_NE(at, std::string::npos);
  all_config.insert(at, "profile_points: all, ");
  const Received all = run_daemon(all_config, 1.5, SIGTERM);
  count(all, &valid, &rejected);
  EXPECT_GT(rejected, 0) << "profile_points: all keeps the rejected candidates";
  EXPECT_NEAR(static_cast<double>(valid) / static_cast<double>(all.profiles.size()),
              valid_per_profile, 0.1 * valid_per_profile)
      << "the same accepted points either way";
  RecordProperty("rejected_per_profile", std::to_string(static_cast<double>(rejected) /
                                                        static_cast<double>(all.profiles.size())));
}

TEST_F(DaemonOverLcm, BackgroundDetectorFindsTheLineUnderStrongAmbientLight) {
  std::string config_text = test_config();
  config_text.replace(config_text.find("ambient: 25"), 11, "ambient: 150");
  config_text.replace(config_text.find("laser_peak: 190"), 15,
                      "laser_peak: 110, scan_rate_deg_s: 10, scan_amplitude_deg: 10");
  config_text.replace(config_text.find("detector: {name: maxvalue, maxvalue: {threshold: 60}}"), 53,
                      "detector: {name: background}");
  const Received rx = run_daemon(config_text, 3.0, SIGTERM);
  ASSERT_GE(rx.profiles.size(), 50u / kSlowdown) << daemon_log();

  laserline::hal::SimScene scene = scene_of(config_text);
  laserline::hal::SimGroundTruth truth;
  std::int64_t valid = 0, correct = 0, truth_columns = 0;
  int subtracted = 0;
  for (std::size_t k = 0; k < rx.profiles.size(); ++k) {
    const auto& p = rx.profiles[k];
    EXPECT_EQ(p.detector, "background");
    EXPECT_EQ(p.search_axis, static_cast<int>(laserline::profile_t::SEARCH_COLUMNS));
    // The frame subtracted: an earlier laser-on one the scan moved away from (none at first),
    // among the 8 frames processed before (history_frames; a slow, sanitized daemon drops
    // frames, so sequence numbers can skip between them).
    if (p.background_sequence >= 0) {
      EXPECT_LT(p.background_sequence, p.sequence);
      const std::int64_t oldest =
          k >= 8 ? rx.profiles[k - 8].sequence : std::min(rx.profiles[0].sequence, p.sequence - 8);
      EXPECT_GE(p.background_sequence, oldest);
      EXPECT_FALSE(p.background_laser_off);
      ++subtracted;
    }
    if (p.num_points == 0) continue;
    scene.ground_truth(static_cast<std::uint64_t>(p.sequence), true, truth);
    for (float row : truth.position)
      truth_columns += std::isfinite(row) ? 1 : 0;
    for (const auto& pt : p.points) {
      if (!pt.valid) continue;
      ++valid;
      const float expected = truth.position[static_cast<std::size_t>(pt.u)];
      if (std::isfinite(expected) && std::abs(pt.v - expected) <= 2.0f) ++correct;
    }
  }
  EXPECT_GE(static_cast<double>(correct), 0.95 * static_cast<double>(truth_columns));
  EXPECT_GE(static_cast<double>(correct), 0.98 * static_cast<double>(valid));
  EXPECT_GE(subtracted, static_cast<int>(rx.profiles.size()) - 3);
}

// A projector beside the camera (`side: left`): the line runs down the image, the epipolar lines
// are the rows, and every profile says so; its points, mapped to pixels as the message documents,
// lie on the simulator's exact line and triangulate to the lit surface.
TEST_F(DaemonOverLcm, ProjectorBesideTheCameraSearchesAlongTheRows) {
  std::string config_text = test_config();
  config_text.replace(config_text.find("angle_deg: 80,"), 14, "angle_deg: 80, side: left,");
  config_text.replace(config_text.find("detector: {name: maxvalue, maxvalue: {threshold: 60}}"), 53,
                      "detector: {name: background}");
  const Received rx = run_daemon(config_text, 2.5, SIGTERM);
  ASSERT_GE(rx.profiles.size(), 40u / kSlowdown) << daemon_log();

  laserline::hal::SimScene scene = scene_of(config_text);
  // The simulator draws the line along the same rows: its truth is the column on each row.
  ASSERT_EQ(scene.lines().line_step, (std::array<double, 2>{0.0, 1.0}));
  ASSERT_EQ(scene.lines().count, 480);
  laserline::hal::SimGroundTruth truth;
  std::int64_t valid = 0, correct = 0, truth_rows = 0, not_triangulated = 0;
  double worst_depth_m = 0;
  for (const auto& p : rx.profiles) {
    EXPECT_EQ(p.search_axis, static_cast<int>(laserline::profile_t::SEARCH_ROWS));
    EXPECT_EQ(p.search_line_step[0], 0.0);
    EXPECT_EQ(p.search_line_step[1], 1.0);
    EXPECT_EQ(p.search_along[0], 1.0);
    EXPECT_EQ(p.search_along[1], 0.0);
    scene.ground_truth(static_cast<std::uint64_t>(p.sequence), true, truth);
    ASSERT_EQ(truth.position.size(), 480u);
    for (float column : truth.position)
      truth_rows += std::isfinite(column) ? 1 : 0;
    for (const auto& pt : p.points) {
      if (!pt.valid) continue;
      ++valid;
      // pixel = origin + u * line_step + v * along: row u, column v.
      const double x = p.search_origin[0] + pt.u * p.search_line_step[0] + pt.v * p.search_along[0];
      const double y = p.search_origin[1] + pt.u * p.search_line_step[1] + pt.v * p.search_along[1];
      ASSERT_GE(y, 0);
      ASSERT_LT(y, 480);
      const auto row = static_cast<std::size_t>(std::lround(y));
      const float expected = truth.position[row];
      if (!std::isfinite(expected) || std::abs(x - expected) > 2.0) continue;
      ++correct;
      if (std::isfinite(pt.xyz[2])) {
        worst_depth_m =
            std::max(worst_depth_m, std::abs(static_cast<double>(pt.xyz[2]) - truth.depth_m[row]));
      } else {
        ++not_triangulated;
      }
    }
  }
  EXPECT_GE(static_cast<double>(correct), 0.95 * static_cast<double>(truth_rows));
  EXPECT_GE(static_cast<double>(correct), 0.98 * static_cast<double>(valid));
  EXPECT_EQ(not_triangulated, 0);
  EXPECT_LT(worst_depth_m, 0.01);
  RecordProperty(
      "correct_of_valid_of_truth",
      std::to_string(correct) + " / " + std::to_string(valid) + " / " + std::to_string(truth_rows));
  RecordProperty("worst_depth_error_m", std::to_string(worst_depth_m));
}

TEST_F(DaemonOverLcm, AlternatingLaserSwitchesPerFrameAndSigintStops) {
  const Received rx = run_daemon(test_config("mode: alternate"), 2.0, SIGINT);
  ASSERT_GE(rx.profiles.size(), 40u / kSlowdown);
  int on = 0, off = 0;
  for (std::size_t i = 1; i < rx.profiles.size(); ++i) {
    const auto& a = rx.profiles[i - 1];
    const auto& b = rx.profiles[i];
    if (b.sequence == a.sequence + 1) {
      EXPECT_NE(a.laser_on, b.laser_on) << b.sequence;
    }
  }
  for (const auto& p : rx.profiles) {
    if (p.laser_on) {
      ++on;
      EXPECT_GT(p.num_points, 500) << "laser-on frame " << p.sequence;
    } else {
      ++off;
      EXPECT_LT(p.num_points, 20) << "laser-off frame " << p.sequence << " has no line";
    }
  }
  EXPECT_GT(on, 15 / kSlowdown);
  EXPECT_GT(off, 15 / kSlowdown);
  ASSERT_FALSE(rx.statuses.empty());
  EXPECT_FALSE(rx.statuses.back().laser_on);
}

// The memory camera through the real daemon: 100 frames/s held in memory (its own rate_hz, not
// camera.frame_rate_hz: the daemon's start line and budget follow it), four frames looped twenty
// times; the daemon stops by itself at their end. Counts and content, not speed: every frame is
// delivered or counted as lost, each profile carries the time its frame was due (10 ms apart),
// and lit and unlit frames follow the alternating laser.
TEST_F(DaemonOverLcm, MemoryCameraDeliversItsFramesAtTheSetRateAndEnds) {
  std::string config_text = test_config("mode: alternate");
  config_text.replace(config_text.find("backend: sim"), 12,
                      "backend: memory\n  memory: {frames: 4, loops: 20, rate_hz: 100}");
  ASSERT_NE(config_text.find("frame_rate_hz: 50"), std::string::npos);
  const std::string config_path = write_config(config_text);
  lcm::LCM lcm(kUrl);
  ASSERT_TRUE(lcm.good());
  Received rx;
  rx.subscribe(lcm);
  start_daemon(config_path);
  int status = 0;
  const std::int64_t give_up = laserline::hal::monotonic_ns() + 60'000'000'000;
  while (waitpid(pid_, &status, WNOHANG) == 0 && laserline::hal::monotonic_ns() < give_up)
    lcm.handleTimeout(50);
  receive_for(lcm, 0.3);
  pid_ = -1;
  ASSERT_TRUE(WIFEXITED(status)) << daemon_log();
  EXPECT_EQ(WEXITSTATUS(status), 0) << daemon_log();
  EXPECT_NE(daemon_log().find("stopped (end of recording)"), std::string::npos) << daemon_log();
  EXPECT_NE(daemon_log().find("memory camera 640x480 at 100.0 Hz"), std::string::npos)
      << daemon_log();
  ASSERT_FALSE(rx.statuses.empty());
  const laserline::status_t& last = rx.statuses.back();
  EXPECT_EQ(last.camera_backend, "memory");
  EXPECT_EQ(last.frames_captured + last.camera_skipped_frames, 80)
      << "each frame delivered or lost";
  EXPECT_EQ(last.frames_processed + last.frames_dropped, last.frames_captured);
  ASSERT_GE(rx.profiles.size(), 40u) << "most of the 80 frames arrive on any machine";
  int lit = 0, unlit = 0;
  for (const laserline::profile_t& p : rx.profiles) {
    EXPECT_LT(p.sequence, 80);
    EXPECT_EQ(p.camera_timestamp_ns, p.sequence * 10'000'000) << "frame " << p.sequence;
    (p.laser_on ? lit : unlit) += 1;
    if (p.laser_on) {
      EXPECT_GT(p.num_points, 500) << "lit frame " << p.sequence;
    } else {
      EXPECT_LT(p.num_points, 20) << "unlit frame " << p.sequence;
    }
  }
  EXPECT_GT(lit, 10);
  EXPECT_GT(unlit, 10);
}

}  // namespace

int main(int argc, char** argv) {
  // Before any thread exists: unshare(CLONE_NEWUSER) requires a single-threaded process.
  g_namespace_problem = laserline::test::enter_private_network();
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
