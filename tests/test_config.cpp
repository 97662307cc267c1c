// The configuration file: every key read, checked and refused in one line naming file, line and
// key. Over 600 lines: one unit (daemon/config), every section of the file.
#include "daemon/config.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "daemon/backends.hpp"
#include "daemon/lcm_publisher.hpp"

namespace laserline::daemon {
namespace {

// Parses `text` as if it were the file "test.yaml" and creates the backends (which validates
// backend options too); returns the error line, or "" when valid.
std::string error_of(const std::string& text) {
  try {
    DaemonConfig config = parse_config(hal::load_yaml_text(text, "test.yaml"), "test.yaml");
    create_backends(config);
  } catch (const hal::ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(Config, BuiltInDefaultIsValidAndRunsTheSimulator) {
  DaemonConfig config = builtin_config();
  EXPECT_EQ(config.camera_backend, "sim");
  EXPECT_EQ(config.laser_backend, "sim");
  EXPECT_EQ(config.detector, "background");
  EXPECT_EQ(parse_config(YAML::Load("{}"), "empty.yaml").detector, config.detector)
      << "a file without a detector section gets the built-in one";
  EXPECT_EQ(config.profile_channel, "LASERLINE_PROFILE");
  EXPECT_EQ(config.image_channel, "LASERLINE_IMAGE");
  EXPECT_EQ(config.status_channel, "LASERLINE_STATUS");
  EXPECT_EQ(config.calibration_channel, "LASERLINE_CALIBRATION");
  EXPECT_EQ(config.calibration_period_s, 5.0);
  Backends backends = create_backends(config);
  EXPECT_EQ(backends.camera->format().width, 1280);
  EXPECT_EQ(backends.camera->format().height, 1024);
  EXPECT_FALSE(backends.laser->is_on()) << "the laser is off until the frame path switches it";
}

TEST(Config, EmptyFileIsRefusedAnExplicitEmptyMappingTakesDefaults) {
  EXPECT_EQ(error_of(""), "test.yaml: has no keys (empty, or only comments)");
  EXPECT_EQ(error_of("# nothing but a comment\n\n"),
            "test.yaml: has no keys (empty, or only comments)");
  EXPECT_EQ(error_of("{}\n"), "") << "all defaults, said on purpose";
}

TEST(Config, ShippedConfigFileEqualsTheBuiltIn) {
  const DaemonConfig file = load_config_file(LASERLINE_SOURCE_DIR "/config/laserline.yaml");
  const DaemonConfig builtin = builtin_config();
  EXPECT_EQ(file.frame_rate_hz, builtin.frame_rate_hz);
  EXPECT_EQ(file.lcm_url, builtin.lcm_url);
  EXPECT_EQ(file.calibration.camera.fx, builtin.calibration.camera.fx);
}

TEST(Config, UnknownKeyNamesFileLineAndKey) {
  EXPECT_EQ(error_of("camera:\n  backend: sim\n  frame_rte_hz: 30\n"),
            "test.yaml:3: camera.frame_rte_hz: unknown key (expected one of: backend, channel, "
            "frame_rate_hz, sim, timeout_ms)");
  EXPECT_EQ(error_of("lcm: {}\nbogus: 1\n").rfind("test.yaml:2: bogus: unknown key", 0), 0u);
}

TEST(Config, KeyGivenTwiceNamesBothLines) {
  EXPECT_EQ(error_of("camera:\n  frame_rate_hz: 30\n  backend: sim\n  frame_rate_hz: 50\n"),
            "test.yaml:4: camera.frame_rate_hz: given twice (first on line 2)");
  EXPECT_EQ(error_of("lcm: {}\nlcm: {}\n"), "test.yaml:2: lcm: given twice (first on line 1)");
}

TEST(Config, WrongTypeNamesTheKey) {
  EXPECT_EQ(error_of("camera:\n  frame_rate_hz: fast\n"),
            "test.yaml:2: camera.frame_rate_hz: must be a number, got 'fast'");
  EXPECT_EQ(error_of("pipeline:\n  frame_slots: 2.5\n"),
            "test.yaml:2: pipeline.frame_slots: must be a whole number, got '2.5'");
  EXPECT_EQ(error_of("camera: 5\n"), "test.yaml:1: camera: must be a mapping of keys");
  EXPECT_EQ(error_of("lcm:\n  url: [a, b]\n"),
            "test.yaml:2: lcm.url: must be a single value, not a list or mapping");
}

TEST(Config, OutOfRangeNamesTheLimits) {
  EXPECT_EQ(error_of("camera:\n  frame_rate_hz: 0\n"),
            "test.yaml:2: camera.frame_rate_hz: must be between 0.1 and 1000, got 0");
  EXPECT_EQ(error_of("pipeline:\n  frame_slots: 6\n"),
            "test.yaml:2: pipeline.frame_slots: must be a power of two, got 6");
  EXPECT_EQ(error_of("detector:\n  maxvalue: {threshold: 300}\n"),
            "test.yaml:2: detector.maxvalue.threshold: must be between 1 and 255, got 300");
  // The detection region, against the calibration's 1280x1024 frame.
  EXPECT_EQ(error_of("detector:\n  name: fir\n  roi: [1200, 0, 100, 10]\n"),
            "test.yaml:3: detector.roi: [1200, 0, 100, 10] reaches beyond the 1280x1024 frame");
  EXPECT_EQ(error_of("detector:\n  roi: [0, 0, 0, 10]\n"),
            "test.yaml:2: detector.roi: width and height must be at least 1 pixel, got [0, 0, 0, "
            "10]");
  EXPECT_EQ(error_of("detector:\n  roi: [-5, 0, 10, 10]\n"),
            "test.yaml:2: detector.roi: x and y must be at least 0, got [-5, 0, 10, 10]");
  EXPECT_EQ(error_of("detector:\n  roi: [0, 0.5, 10, 10]\n"),
            "test.yaml:2: detector.roi: expected [x, y, width, height] in whole pixels");
  EXPECT_EQ(error_of("detector:\n  roi: [1e300, 0, 10, 10]\n"),
            "test.yaml:2: detector.roi: expected [x, y, width, height] in whole pixels");
  EXPECT_EQ(error_of("detector:\n  roi: [0, 0, 10]\n"),
            "test.yaml:2: detector.roi: must have 4 numbers, got 3");
  EXPECT_EQ(error_of("detector:\n  roi: [0, 100, 1280, 924]\n"), "");
  EXPECT_EQ(parse_config(hal::load_yaml_text("detector: {roi: [8, 100, 640, 480]}\n", "test.yaml"),
                         "test.yaml")
                .detector_options.roi,
            (pipeline::DetectionRegion{8, 100, 640, 480}));
  EXPECT_TRUE(builtin_config().detector_options.roi.whole());
  EXPECT_EQ(
      error_of("detector:\n  validation: {min_segment_points: 1}\n"),
      "test.yaml:2: detector.validation.min_segment_points: must be between 2 and 1000, got 1");
  EXPECT_EQ(error_of("camera:\n  sim:\n    noise_sigma: -1\n"),
            "test.yaml:3: camera.sim.noise_sigma: must be between 0 and 50, got -1");
  EXPECT_EQ(error_of("camera:\n  sim:\n    relief_height_m: 0.1\n    relief_min_height_m: 0.2\n"),
            "test.yaml:4: camera.sim.relief_min_height_m: must be between 0 and 0.1, got 0.2");
  EXPECT_EQ(error_of("camera:\n  sim:\n    relief_max_slope: 2\n"),
            "test.yaml:3: camera.sim.relief_max_slope: must be between 0.05 and 1, got 2");
  EXPECT_EQ(error_of("camera:\n  sim:\n    vehicle_speed_m_s: 20\n"),
            "test.yaml:3: camera.sim.vehicle_speed_m_s: must be between -10 and 10, got 20");
  EXPECT_EQ(error_of("camera:\n  sim:\n    laser_fan_deg: 180\n"),
            "test.yaml:3: camera.sim.laser_fan_deg: must be between 0 and 179, got 180");
  EXPECT_EQ(error_of("camera:\n  sim: {relief_height_m: 0.3, relief_max_slope: 0.3}\n"),
            "test.yaml:2: camera.sim.relief_max_slope: must be at least relief_height_m / 0.72 = "
            "0.417 (features must fit the 5.12 m relief tile)");
  EXPECT_EQ(error_of("camera:\n  sim: {relief_height_m: 0.3, relief_per_m2: 0.5, "
                     "relief_max_slope: 0.8, vehicle_speed_m_s: 0.4}\n"),
            "");
}

// The pipeline checks its options (one range each); the configuration names the key and the line.
TEST(Config, DetectorOptionsTakeThePipelinesRanges) {
  EXPECT_EQ(error_of("detector:\n  frontend:\n    max_candidates_per_column: 100\n"), "");
  EXPECT_EQ(error_of("detector:\n  frontend:\n    max_candidates_per_column: 300\n"),
            "test.yaml:3: detector.frontend.max_candidates_per_column: must be between 1 and 255, "
            "got 300");
  EXPECT_EQ(error_of("detector:\n  motion: {pyramid_levels: 7, detect_level: 2}\n"), "");
  EXPECT_EQ(error_of("detector:\n  motion:\n    pyramid_levels: 9\n"),
            "test.yaml:3: detector.motion.pyramid_levels: must be between 1 and 8, got 9");
  EXPECT_EQ(error_of("detector:\n  motion:\n    pyramid_levels: 4\n    detect_level: 4\n"),
            "test.yaml:4: detector.motion.detect_level: must be between 0 and 3 (below "
            "pyramid_levels), got 4");
  EXPECT_EQ(error_of("detector:\n  frontend:\n    selection: {max_gap: 65}\n"),
            "test.yaml:3: detector.frontend.selection.max_gap: must be between 0 and 64, got 65");
  EXPECT_EQ(error_of("detector:\n  frontend:\n    selection: {faint_piece_db: -1}\n"),
            "test.yaml:3: detector.frontend.selection.faint_piece_db: must be between 0 and 1000, "
            "got -1");
  EXPECT_EQ(
      parse_config(hal::load_yaml_text("detector: {frontend: {selection: {faint_piece_db: 0}}}\n",
                                       "test.yaml"),
                   "test.yaml")
          .detector_options.frontend.selection.faint_piece_db,
      0.0);
  EXPECT_EQ(error_of("detector:\n  frontend:\n    line_blur_px: 33\n"),
            "test.yaml:3: detector.frontend.line_blur_px: must be between 0 and 32, got 33");
  EXPECT_EQ(
      parse_config(hal::load_yaml_text("detector: {frontend: {line_blur_px: 0.5}}\n", "test.yaml"),
                   "test.yaml")
          .detector_options.frontend.line_blur_px,
      0.5);
  EXPECT_EQ(error_of("detector:\n  frontend:\n    noise_side_ratio: 0.5\n"),
            "test.yaml:3: detector.frontend.noise_side_ratio: must be 0 (off) or between 1 and "
            "1000, got 0.5");
  EXPECT_EQ(parse_config(
                hal::load_yaml_text("detector: {frontend: {noise_side_ratio: 0}}\n", "test.yaml"),
                "test.yaml")
                .detector_options.frontend.noise_side_ratio,
            0.0);
  EXPECT_EQ(error_of("detector:\n  frontend:\n    snr_hysteresis_db: -1\n"),
            "test.yaml:3: detector.frontend.snr_hysteresis_db: must be between 0 and 60, got -1");
  EXPECT_EQ(parse_config(
                hal::load_yaml_text("detector: {frontend: {snr_hysteresis_db: 0}}\n", "test.yaml"),
                "test.yaml")
                .detector_options.frontend.snr_hysteresis_db,
            0.0);
  EXPECT_EQ(error_of("detector:\n  frontend: {min_depth_m: 3}\n"),
            "test.yaml:2: detector.frontend.max_depth_m: must be above min_depth_m");
  EXPECT_EQ(error_of("detector:\n  background:\n    history_frames: 0\n"),
            "test.yaml:3: detector.background.history_frames: must be between 1 and 64, got 0");
  EXPECT_FALSE(parse_config(hal::load_yaml_text(
                                "detector: {background: {remove_own_line: false}}\n", "test.yaml"),
                            "test.yaml")
                   .detector_options.background.remove_own_line);
  EXPECT_EQ(error_of("detector:\n  background: {remove_own_line: 1}\n"),
            "test.yaml:2: detector.background.remove_own_line: must be true or false, got '1'");
}

TEST(Config, CameraMotionOptions) {
  const DaemonConfig config =
      parse_config(hal::load_yaml_text("detector:\n  motion: {essential_ransac_iterations: 50, "
                                       "essential_inlier_px: 0.7, essential_min_parallax_px: 2, "
                                       "scale_tracks: 0}\n",
                                       "test.yaml"),
                   "test.yaml");
  const pipeline::MotionOptions& m = config.detector_options.motion;
  EXPECT_EQ(m.essential_ransac_iterations, 50);
  EXPECT_EQ(m.essential_inlier_px, 0.7);
  EXPECT_EQ(m.essential_min_parallax_px, 2.0);
  EXPECT_EQ(m.scale_tracks, 0);
  const pipeline::MotionOptions shipped =
      load_config_file(LASERLINE_SOURCE_DIR "/config/laserline.yaml").detector_options.motion;
  const pipeline::MotionOptions builtin = builtin_config().detector_options.motion;
  EXPECT_EQ(shipped.essential_ransac_iterations, builtin.essential_ransac_iterations);
  EXPECT_EQ(shipped.essential_inlier_px, builtin.essential_inlier_px);
  EXPECT_EQ(shipped.essential_min_parallax_px, builtin.essential_min_parallax_px);
  EXPECT_EQ(shipped.scale_tracks, builtin.scale_tracks);
  EXPECT_EQ(error_of("detector:\n  motion:\n    essential_ransac_iterations: 0\n"),
            "test.yaml:3: detector.motion.essential_ransac_iterations: must be between 1 and "
            "10000, got 0");
  EXPECT_EQ(error_of("detector:\n  motion:\n    essential_inlier_px: 0\n"),
            "test.yaml:3: detector.motion.essential_inlier_px: must be between 0.05 and 50, got 0");
  EXPECT_EQ(error_of("detector:\n  motion:\n    essential_min_parallax_px: -1\n"),
            "test.yaml:3: detector.motion.essential_min_parallax_px: must be between 0 and 100, "
            "got -1");
  EXPECT_EQ(error_of("detector:\n  motion:\n    scale_tracks: many\n"),
            "test.yaml:3: detector.motion.scale_tracks: must be a whole number, got 'many'");
}

TEST(Config, ChoicesListTheAlternatives) {
  EXPECT_EQ(error_of("detector:\n  name: magic\n"),
            "test.yaml:2: detector.name: must be one of maxvalue, fir, background, backprojection, "
            "got 'magic'");
  EXPECT_EQ(error_of("detector:\n  validation:\n    association: shapes\n"),
            "test.yaml:3: detector.validation.association: must be one of chain_code, "
            "image_features, got 'shapes'");
  EXPECT_EQ(error_of("laser:\n  mode: blink\n"),
            "test.yaml:2: laser.mode: must be one of on, alternate, off, pattern, got 'blink'");
  EXPECT_EQ(error_of("camera:\n  backend: gige\n"),
            "test.yaml:2: camera.backend: unknown camera backend 'gige' (available: aravis, lcm, "
            "memory, sim, v4l2)");
  EXPECT_EQ(error_of("laser:\n  backend: gpio\n"),
            "test.yaml:2: laser.backend: unknown laser backend 'gpio' (available: gpiod, sim)");
}

TEST(Config, ReplayCameraNeedsAUrl) {
  EXPECT_EQ(error_of("camera:\n  backend: lcm\n"),
            "test.yaml: camera.lcm.url: required: file:///path/to/dive.lcmlog (offline) or an "
            "LCM URL (live)");
  EXPECT_EQ(error_of("camera:\n  backend: lcm\n  lcm: {url: 'file://'}\n"),
            "test.yaml:3: camera.lcm.url: file:// needs the path of a log file");
  EXPECT_EQ(
      error_of("camera:\n  backend: lcm\n  lcm: {url: 'file:///x.lcmlog', chanel: A}\n"),
      "test.yaml:3: camera.lcm.chanel: unknown key (expected one of: calibration_channel, channel, "
      "url)");
  EXPECT_EQ(error_of("camera:\n  backend: lcm\n  lcm: {url: 'file:///x.lcmlog'}\n"), "")
      << "the log is opened with the camera, not when the configuration is checked";
}

TEST(Config, ProfilePoints) {
  auto parse = [](const std::string& text) {
    return parse_config(hal::load_yaml_text(text, "test.yaml"), "test.yaml");
  };
  EXPECT_FALSE(parse("{}\n").profile_all_points) << "default: accepted points only";
  EXPECT_FALSE(parse("lcm: {profile_points: accepted}\n").profile_all_points);
  EXPECT_TRUE(parse("lcm: {profile_points: all}\n").profile_all_points);
  EXPECT_EQ(error_of("lcm:\n  profile_points: valid\n"),
            "test.yaml:2: lcm.profile_points: must be one of accepted, all, got 'valid'");
}

TEST(Config, RawFrameOptions) {
  EXPECT_EQ(error_of("lcm:\n  image_compression: gzip\n"),
            "test.yaml:2: lcm.image_compression: must be one of none, zlib, png, jpeg, got 'gzip'");
  EXPECT_EQ(error_of("lcm:\n  image_downscale: 3\n"),
            "test.yaml:2: lcm.image_downscale: must be 1, 2 or 4, got 3");
  EXPECT_EQ(error_of("lcm:\n  image_roi: [0, 0, 0, 10]\n"),
            "test.yaml:2: lcm.image_roi: width and height must be > 0");
  EXPECT_EQ(error_of("lcm:\n  image_roi: [1000, 0, 400, 10]\n"),
            "test.yaml:2: lcm.image_roi: [1000, 0, 400, 10] is not inside the calibration's "
            "1280x1024 frame");
  // x + width overflowed a 32-bit int and passed: the encoder then read far outside the frame
  // (a crash) or allocated 8 GB.
  EXPECT_EQ(error_of("lcm:\n  image_roi: [2147483647, 0, 16, 16]\n"),
            "test.yaml:2: lcm.image_roi: [2147483647, 0, 16, 16] is not inside the calibration's "
            "1280x1024 frame");
  EXPECT_EQ(error_of("lcm:\n  image_roi: [1, 0, 2147483647, 16]\n"),
            "test.yaml:2: lcm.image_roi: [1, 0, 2147483647, 16] is not inside the calibration's "
            "1280x1024 frame");
  EXPECT_EQ(error_of("lcm:\n  image_roi: [1e300, 0, 16, 16]\n"),
            "test.yaml:2: lcm.image_roi: [1e+300, 0, 16, 16] is not inside the calibration's "
            "1280x1024 frame");
  EXPECT_EQ(error_of("lcm:\n  image_roi: [1272, 1020, 8, 4]\n  image_downscale: 4\n"), "")
      << "the last pixels of the frame, one downscaled row";
  EXPECT_EQ(error_of("lcm:\n  image_roi: [1272, 1020, 8, 3]\n  image_downscale: 4\n"),
            "test.yaml: lcm.image_downscale: 4 leaves no pixel of a 8x3 region");
  DaemonConfig c = parse_config(
      hal::load_yaml_text("lcm: {image_every_n: 1, image_max_rate_hz: 10, image_compression: "
                          "zlib, image_roi: [8, 4, 640, 480], image_downscale: 2}\n",
                          "test.yaml"),
      "test.yaml");
  EXPECT_EQ(c.raw_frames.every_n, 1);
  EXPECT_EQ(c.raw_frames.max_rate_hz, 10.0);
  EXPECT_EQ(c.raw_frames.compression, ImageCompression::kZlib);
  EXPECT_EQ(c.raw_frames.roi_x, 8);
  EXPECT_EQ(c.raw_frames.roi_height, 480);
  EXPECT_EQ(c.raw_frames.downscale, 2);
}

// --check-config runs what the start runs: a configuration it passes must start.
TEST(Config, CalibrationTooSmallForTheDetectorIsRefusedAtTheCheck) {
  const std::string small = "calibration: {camera: {width: 16, height: 16, fx: 20, fy: 20}}\n";
  EXPECT_EQ(error_of(small),
            "test.yaml: detector background: frames of 16x16 (calibration.camera): frame smaller "
            "than 64x4 pixels");
  EXPECT_EQ(error_of("calibration: {camera: {width: 64, height: 48, fx: 80, fy: 80}}\n")
                .rfind("test.yaml: detector background: frames of 64x48 (calibration.camera): "
                       "MotionEstimator::reset: image 64x48 is too small for 4 pyramid levels",
                       0),
            0u);
  EXPECT_EQ(error_of(small + "detector: {name: maxvalue}\n"), "") << "maxvalue takes any size";
}

TEST(Config, FrameMemoryIsWithinTheStatedLimit) {
  const std::string huge =
      "calibration: {camera: {width: 16384, height: 16384, fx: 20000, fy: "
      "20000}}\npipeline: {frame_slots: 1024}\n";
  EXPECT_EQ(error_of(huge),
            "test.yaml: pipeline.frame_memory_limit_mb: frames of 16384x16384 need 276860.8 MB "
            "(pipeline.frame_slots 1024, image_slots 2, profile_slots 16 and the raw-frame "
            "buffers), more than the limit of 1024 MB: fewer slots, a smaller camera or a higher "
            "limit");
  EXPECT_EQ(error_of("pipeline: {frame_memory_limit_mb: 8}\n"),
            "test.yaml:1: pipeline.frame_memory_limit_mb: must be between 16 and 1048576, got 8");

  // The default configuration's frame path, then limits just below and above what it needs.
  DaemonConfig config = builtin_config();
  Backends backends = create_backends(config);
  const hal::FrameFormat format = backends.camera->format();
  const std::uint64_t buffers = frame_path_memory_bytes(
      config, format, backends.detector->max_points(format.width, format.height));
  const std::uint64_t frame = format.bytes();
  EXPECT_GT(buffers, (config.frame_slots + config.image_slots + 2) * frame);
  // (The profiles' slots hold up to max_candidates_per_column points per column: ~16 frames.)
  EXPECT_LT(buffers, (config.frame_slots + config.image_slots + 18) * frame);
  // A detector as create_backends() makes it, not yet sized.
  auto fresh_detector = [&] {
    return pipeline::make_detector(config.detector, config.detector_options);
  };
  config.frame_memory_limit_mb = static_cast<std::int64_t>(buffers / 1'000'000);
  try {
    check_frame_path(config, format, *fresh_detector());
    FAIL() << "frame buffers of " << buffers << " bytes above the limit";
  } catch (const hal::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("more than the limit of"), std::string::npos);
  }
  // The detector's buffers count too: the background detector's are several megabytes.
  config.frame_memory_limit_mb = static_cast<std::int64_t>(buffers / 1'000'000) + 1;
  try {
    check_frame_path(config, format, *fresh_detector());
    FAIL() << "the detector's buffers must count";
  } catch (const hal::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(" for the detector background, more than the limit of"),
              std::string::npos)
        << e.what();
  }
  config.frame_memory_limit_mb = static_cast<std::int64_t>(buffers / 1'000'000) + 64;
  EXPECT_NO_THROW(check_frame_path(config, format, *fresh_detector()));
}

TEST(Config, LcmChannelsAndUrl) {
  EXPECT_EQ(error_of("lcm:\n  status_channel: ''\n"),
            "test.yaml:2: lcm.status_channel: must be 1 to 63 characters");
  EXPECT_EQ(error_of("lcm:\n  image_channel: " + std::string(64, 'X') + "\n"),
            "test.yaml:2: lcm.image_channel: must be 1 to 63 characters");
  EXPECT_EQ(error_of("lcm:\n  url: 239.255.76.67\n"),
            "test.yaml:2: lcm.url: must be udpm://, memq://, file:// or tcpq://, got "
            "'239.255.76.67'");
  DaemonConfig config = parse_config(
      hal::load_yaml_text("lcm: {profile_channel: SCAN_A, url: 'memq://'}\n", "t"), "t");
  EXPECT_EQ(config.profile_channel, "SCAN_A");
  EXPECT_EQ(config.status_channel, "LASERLINE_STATUS");
  EXPECT_EQ(error_of("lcm:\n  calibration_channel: ''\n"),
            "test.yaml:2: lcm.calibration_channel: must be 1 to 63 characters");
  EXPECT_EQ(error_of("lcm:\n  calibration_period_s: 0\n"),
            "test.yaml:2: lcm.calibration_period_s: must be between 0.05 and 3600, got 0");
}

TEST(Config, CommandChannelsAndToken) {
  const DaemonConfig defaults = builtin_config();
  EXPECT_EQ(defaults.command_channel, "LASERLINE_COMMAND");
  EXPECT_EQ(defaults.command_ack_channel, "LASERLINE_COMMAND_ACK");
  EXPECT_EQ(defaults.command_token, "");
  const DaemonConfig renamed = parse_config(
      hal::load_yaml_text("lcm: {command_channel: ROV2_CMD, command_token: abc}\n", "t"), "t");
  EXPECT_EQ(renamed.command_channel, "ROV2_CMD");
  EXPECT_EQ(renamed.command_ack_channel, "ROV2_CMD_ACK");
  EXPECT_EQ(renamed.command_token, "abc");
  EXPECT_EQ(error_of("lcm:\n  command_channel: ''\n"),
            "test.yaml:2: lcm.command_channel: must be 1 to 63 characters");
  EXPECT_EQ(error_of("lcm:\n  command_ack_channel: LASERLINE_STATUS\n"),
            "test.yaml:2: lcm.command_ack_channel: 'LASERLINE_STATUS' is already an output "
            "channel");
  EXPECT_EQ(error_of("lcm:\n  command_ack_channel: LASERLINE_COMMAND\n"),
            "test.yaml:2: lcm.command_ack_channel: must differ from lcm.command_channel");
  EXPECT_EQ(error_of("lcm:\n  command_token: " + std::string(256, 't') + "\n"),
            "test.yaml:2: lcm.command_token: must be at most 255 characters");
}

TEST(Config, Realtime) {
  EXPECT_EQ(error_of("realtime: {enabled: sure}\n"),
            "test.yaml:1: realtime.enabled: must be true or false, got 'sure'");
  EXPECT_EQ(error_of("realtime:\n  cpus: [1.5]\n"),
            "test.yaml:2: realtime.cpus: must list CPU numbers 0..1023");
  const DaemonConfig c =
      parse_config(hal::load_yaml_text("realtime: {enabled: true, cpus: [0, 1]}\n", "t"), "t");
  EXPECT_TRUE(c.realtime);
  EXPECT_EQ(c.cpus, (std::vector<int>{0, 1}));
  EXPECT_FALSE(builtin_config().realtime) << "off by default: it needs privileges";
}

TEST(Config, CalibrationErrors) {
  EXPECT_EQ(error_of("calibration:\n  camera: {fx: 0}\n"),
            "test.yaml:2: calibration.camera.fx: must be between 1 and 1e+06, got 0");
  EXPECT_EQ(error_of("calibration:\n  camera:\n    distortion: [1, 2]\n"),
            "test.yaml:3: calibration.camera.distortion: must have 4 or 5 numbers, got 2");
  EXPECT_EQ(error_of("calibration:\n  laser:\n    plane: [0, 0, 0, 1]\n"),
            "test.yaml:3: calibration.laser.plane: the normal (a, b, c) must not be zero");
  EXPECT_NE(error_of("calibration:\n  camera:\n    distortion: [0.1, 0, 0, 0, 0]\n")
                .find("camera.sim: the simulator renders an ideal pinhole camera"),
            std::string::npos);
}

TEST(Config, CalibrationFromAFileRelativeToTheConfig) {
  const auto dir = std::filesystem::temp_directory_path() / "laserline_test_config";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "calib.yaml") << "camera: {width: 640, height: 480, fx: 700, fy: 700}\n"
                                       "laser: {baseline_m: 0.1, angle_deg: 75}\n";
  std::ofstream(dir / "daemon.yaml") << "calibration: calib.yaml\n";
  const DaemonConfig config = load_config_file((dir / "daemon.yaml").string());
  EXPECT_EQ(config.calibration.camera.width, 640);
  EXPECT_DOUBLE_EQ(config.calibration.camera.cx, 319.5);
  EXPECT_DOUBLE_EQ(config.calibration.laser.baseline_m, 0.1);

  std::ofstream(dir / "broken.yaml") << "calibration: missing.yaml\n";
  try {
    load_config_file((dir / "broken.yaml").string());
    FAIL() << "a missing calibration file must be an error";
  } catch (const hal::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.yaml: cannot be opened"), std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

// The calibration section may use OpenCV's calibration layout; it reaches the detector geometry.
TEST(Config, CalibrationInOpenCvLayout) {
  const DaemonConfig config = parse_config(
      hal::load_yaml_text(
          "calibration:\n"
          "  image_width: 640\n"
          "  image_height: 480\n"
          "  camera_matrix: !!opencv-matrix\n"
          "    {rows: 3, cols: 3, dt: d, data: [700, 0, 320.5, 0, 710, 240.5, 0, 0, 1]}\n"
          "  laser: {baseline_m: 0.1}\n",
          "test.yaml"),
      "test.yaml");
  EXPECT_EQ(config.detector_options.geometry.width, 640);
  EXPECT_DOUBLE_EQ(config.detector_options.geometry.fy, 710);
  EXPECT_DOUBLE_EQ(config.detector_options.geometry.cx, 320.5);
  EXPECT_DOUBLE_EQ(config.detector_options.geometry.laser_plane[3], 0.1);
  EXPECT_EQ(error_of("calibration:\n  image_width: 640\n  image_height: 480\n"
                     "  camera_matrix: {rows: 3, cols: 3, dt: d, data: [700, 0, 320]}\n"),
            "test.yaml:4: calibration.camera_matrix.data: must have 9 numbers, got 3");
}

TEST(Config, UnreadableAndInvalidYaml) {
  try {
    load_config_file("/nonexistent/laserline.yaml");
    FAIL();
  } catch (const hal::ConfigError& e) {
    EXPECT_STREQ(e.what(),
                 "/nonexistent/laserline.yaml: cannot be opened for reading: No such file or "
                 "directory");
  }
  const std::string bad = error_of("camera: {backend: sim\nlcm: 1\n");
  EXPECT_EQ(bad.rfind("test.yaml:", 0), 0u) << bad;
  EXPECT_NE(bad.find("not valid YAML"), std::string::npos) << bad;
  EXPECT_EQ(error_of("- a\n- b\n"), "test.yaml:1: the top level must be a mapping of keys");
}

// What an outside tester gave laserlined as a configuration: each is one line naming the file,
// the place and what is wrong, and none takes long or much memory.
class HostileConfigFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("laserline_hostile_config_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string write(const std::string& name, const std::string& bytes) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << bytes;
    return path;
  }
  // The error of loading `path` as laserlined does, with the directory left out; "" when valid.
  std::string error_of_file(const std::string& path) {
    try {
      DaemonConfig config = load_config_file(path);
      create_backends(config);
    } catch (const hal::ConfigError& e) {
      std::string what = e.what();
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
      const std::string prefix = dir_.string() + "/";
      return what.rfind(prefix, 0) == 0 ? what.substr(prefix.size()) : what;
    }
    return "";
  }

  std::filesystem::path dir_;
};

TEST_F(HostileConfigFile, OnlyRegularFilesAreRead) {
  EXPECT_EQ(
      error_of_file(dir_.string()),
      dir_.string() + ": is a directory, not a file: give a configuration or calibration file");
  EXPECT_EQ(error_of_file("/dev/null"),
            "/dev/null: is a character device, not a file: give a configuration or calibration "
            "file");
  EXPECT_EQ(error_of_file("/dev/zero"),
            "/dev/zero: is a character device, not a file: give a configuration or calibration "
            "file");
  // A named pipe without a writer: refused at once instead of waiting for one forever.
  const std::string fifo = (dir_ / "pipe.yaml").string();
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_EQ(error_of_file(fifo),
            "pipe.yaml: is a named pipe (FIFO), not a file: give a configuration or calibration "
            "file");
  EXPECT_EQ(error_of_file(write("empty.yaml", "")),
            "empty.yaml: has no keys (empty, or only comments)");
}

TEST_F(HostileConfigFile, SizeIsLimitedBeforeParsing) {
  // Three million keys took 3 GB and 22 s before the unknown-key error; now the size decides.
  std::string keys;
  for (int i = 0; keys.size() <= hal::kMaxYamlFileBytes; ++i)
    keys += "k" + std::to_string(i) + ": 1\n";
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(error_of_file(write("huge.yaml", keys)),
            "huge.yaml: is " + std::to_string(keys.size()) +
                " bytes, more than the 1048576 (1 MiB) a configuration or calibration may have");
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(1));
  std::string just_fits = "lcm: {url: 'memq://'}\n";
  just_fits += std::string(hal::kMaxYamlFileBytes - just_fits.size() - 1, '#') + "\n";
  EXPECT_EQ(error_of_file(write("fits.yaml", just_fits)), "");
}

TEST_F(HostileConfigFile, NestingIsLimitedWithAClearMessage) {
  // yaml-cpp's own guard said "not valid YAML: bad file".
  EXPECT_EQ(error_of_file(write("deep.yaml",
                                "a: " + std::string(10000, '[') + std::string(10000, ']') + "\n")),
            "deep.yaml:1: nested more than 32 levels deep");
  std::string block = "camera:\n";
  for (int level = 1; level <= 40; ++level)
    block +=
        std::string(static_cast<std::size_t>(2 * level), ' ') + "k" + std::to_string(level) + ":\n";
  block += std::string(82, ' ') + "x: 1\n";
  EXPECT_EQ(error_of_file(write("block.yaml", block)),
            "block.yaml:33: camera.k1.k2.k3.k4.k5.k6.k7.k8.k9.k10.k11.k12.k13.k14.k15.k16.k17.k18."
            "k19.k20.k21.k22.k23.k24.k25.k26.k27.k28.k29.k30.k31: nested more than 32 levels deep");
  // A few aliases used many times (a "billion laughs") are counted as what they expand to.
  std::string laughs = "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n";
  for (char name = 'b'; name <= 'i'; ++name) {
    const std::string prev(1, static_cast<char>(name - 1));
    laughs += std::string(1, name) + ": &" + name + " [*" + prev + ", *" + prev + ", *" + prev +
              ", *" + prev + ", *" + prev + ", *" + prev + ", *" + prev + ", *" + prev + ", *" +
              prev + ", *" + prev + "]\n";
  }
  const std::string error = error_of_file(write("laughs.yaml", laughs));
  EXPECT_NE(error.find(": more than 100000 keys and values (aliases counted each time they are "
                       "used)"),
            std::string::npos)
      << error;
}

TEST_F(HostileConfigFile, OneDocumentOnly) {
  EXPECT_EQ(
      error_of_file(write("two.yaml", "lcm: {url: 'memq://'}\n---\nlcm: {url: 'file://x'}\n")),
      "two.yaml:3: a second YAML document (after '---'): only one is read, give all keys in "
      "one");
}

// yaml-cpp 0.7's LoadAll never ends on a stream that starts with a ',' (it yields empty documents
// without consuming input and grows until memory runs out); found by tests/fuzz/fuzz_config.
TEST_F(HostileConfigFile, ALoneCommaEndsWithAnError) {
  EXPECT_EQ(error_of_file(write("comma.yaml", ",")),
            "comma.yaml: has no keys (empty, or only comments)");
  EXPECT_EQ(error_of_file(write("comment.yaml", "# a comment\n ,\n")),
            "comment.yaml: has no keys (empty, or only comments)");
  // An empty second document holds nothing that would be lost.
  EXPECT_EQ(error_of_file(write("empty_second.yaml", "lcm: {url: 'memq://'}\n---\n")), "");
}

TEST_F(HostileConfigFile, NulBytesAreRefusedAndShownEscaped) {
  EXPECT_EQ(
      error_of_file(write("raw.yaml", std::string("lcm:\n  profile_channel: LASER\0X\n", 31))),
      "raw.yaml:2: a NUL byte (\\0) at column 25 (byte offset 29): not a text file");
  // Escaped in a double-quoted string: the channel name was cut at the NUL.
  EXPECT_EQ(error_of_file(write("value.yaml", "lcm:\n  profile_channel: \"LASER\\0X\"\n")),
            "value.yaml:2: lcm.profile_channel: contains a NUL byte: \"LASER\\0X\"");
  EXPECT_EQ(error_of_file(write("key.yaml", "lcm:\n  \"url\\0x\": 'memq://'\n")),
            "key.yaml:2: lcm: the key \"url\\0x\" contains a NUL byte");
  // Other control characters in a value stay on the one line, escaped.
  EXPECT_EQ(error_of_file(write("newline.yaml", "laser: {mode: \"o\\nn\\x1b\"}\n")),
            "newline.yaml:1: laser.mode: must be one of on, alternate, off, pattern, got "
            "'o\\nn\\x1b'");
}

TEST_F(HostileConfigFile, KeysWithoutValueAndEmptySectionsAreNamed) {
  EXPECT_EQ(error_of_file(write("novalue.yaml", "camera:\n  frame_rate_hz:\n")),
            "novalue.yaml:2: camera.frame_rate_hz: has no value (give one or leave the key out)");
  EXPECT_EQ(error_of_file(write("nosection.yaml", "camera:\nlcm: {url: 'memq://'}\n")),
            "nosection.yaml:1: camera: is empty (give its keys, or leave the section out for the "
            "defaults)");
  EXPECT_EQ(error_of_file(write("listkey.yaml", "lcm:\n  ? [a, b]\n  : 1\n")),
            "listkey.yaml:2: lcm: a key must be a plain name, not a list, a mapping or empty");
}

TEST(Config, ErrorsAreOneLine) {
  for (const char* text : {"camera:\n  frame_rte_hz: 30\n", "camera: {backend: sim\n",
                           "calibration:\n  camera: {fx: 0}\n"}) {
    const std::string e = error_of(text);
    EXPECT_FALSE(e.empty());
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
}

}  // namespace
}  // namespace laserline::daemon

namespace laserline::daemon {
namespace {

// camera.channel: read once here, for every backend; colour backends convert with it.
TEST(Config, CameraChannelIsTheLasersColour) {
  const hal::LaserChannel standard = builtin_config().laser_channel;
  EXPECT_EQ(standard.text, "green") << "the default is the 535 nm laser's green";
  EXPECT_TRUE(standard.single());
  EXPECT_EQ(standard.green, 1.0f);
  const DaemonConfig red = parse_config(
      hal::load_yaml_text("camera:\n  channel: red - (green + blue) / 2\n", "test.yaml"),
      "test.yaml");
  EXPECT_EQ(red.laser_channel.red, 1.0f);
  EXPECT_EQ(red.laser_channel.green, -0.5f);
  EXPECT_EQ(red.laser_channel.blue, -0.5f);
  EXPECT_EQ(red.laser_channel.text, "red - (green + blue) / 2");
  // Errors: the parser's one line after the file, the line and the key.
  EXPECT_EQ(error_of("camera:\n  backend: sim\n  channel: purple\n"),
            "test.yaml:3: camera.channel: channel \"purple\": unknown name 'purple' (red, green, "
            "blue, grey) at character 1");
  EXPECT_EQ(error_of("camera:\n  channel: \"red * green\"\n"),
            "test.yaml:2: camera.channel: channel \"red * green\": a product of two channels is "
            "not a weighted sum at character 12");
  EXPECT_EQ(error_of("camera:\n  channel: [red]\n"),
            "test.yaml:2: camera.channel: must be a single value, not a list or mapping");
}

// The hardware backends validate their own keys when created, before any device is opened.
TEST(Config, HardwareBackendOptionsAreValidatedWithoutHardware) {
  const std::string size = "calibration: {camera: {width: 640, height: 480}}\n";
  EXPECT_EQ(error_of(size + "camera: {backend: aravis, device: GV01, trigger: software,"
                            " features: {Gamma: 1.0}, packet_size: -1}\n"),
            "");
  EXPECT_EQ(error_of(size + "camera:\n  backend: aravis\n  pixel_format: RGB16\n"),
            "test.yaml:4: camera.pixel_format: must be one of Mono8, Mono12, Mono16, BayerRG8, "
            "BayerGR8, BayerGB8, BayerBG8, BayerRG12, BayerGR12, BayerGB12, BayerBG12, BayerRG16, "
            "BayerGR16, BayerGB16, BayerBG16, RGB8, BGR8, got 'RGB16'");
  for (const char* format : {"BayerRG8", "BayerGR8", "BayerGB8", "BayerBG8", "BayerRG12",
                             "BayerBG16", "RGB8", "BGR8", "Mono12"}) {
    EXPECT_EQ(
        error_of(size + "camera: {backend: aravis, channel: red, pixel_format: " + format + "}\n"),
        "")
        << format;
  }
  EXPECT_EQ(error_of(size + "camera:\n  backend: aravis\n  features: [Gamma]\n"),
            "test.yaml:4: camera.features: must be a mapping of GenICam feature: value");
  EXPECT_EQ(error_of(size + "camera:\n  backend: aravis\n  trigger: sometimes\n"),
            "test.yaml:4: camera.trigger: must be one of free, software, line, got 'sometimes'");
  EXPECT_EQ(
      error_of(size + "camera:\n  backend: v4l2\n  device: /dev/video3\n  pixel_format: MJPG\n"),
      "test.yaml:5: camera.pixel_format: must be one of GREY, Y16, YUYV, SRGGB8, SGRBG8, SGBRG8, "
      "SBGGR8, SRGGB12, SGRBG12, SGBRG12, SBGGR12, SRGGB16, SGRBG16, SGBRG16, SBGGR16, RGB24, "
      "BGR24, got 'MJPG'");
  for (const char* format :
       {"SRGGB8", "SGRBG8", "SGBRG8", "SBGGR8", "SGBRG12", "SRGGB16", "RGB24", "BGR24", "YUYV"}) {
    EXPECT_EQ(error_of(size +
                       "camera: {backend: v4l2, channel: 'red - (green + blue) / 2', "
                       "pixel_format: " +
                       format + "}\n"),
              "")
        << format;
  }
  EXPECT_EQ(error_of(size + "camera: {backend: aravis, pixel_format: BayerGB8, width: 1}\n"),
            "test.yaml:2: camera.pixel_format: a Bayer mosaic needs at least 2x2 pixels, got "
            "1x480");
  EXPECT_EQ(error_of("calibration: {camera: {width: 641, height: 480}}\n"
                     "camera: {backend: v4l2, device: /dev/video2, pixel_format: YUYV}\n"),
            "test.yaml:2: camera.pixel_format: YUYV needs an even width (pixels come in pairs), "
            "got 641x480");
  EXPECT_EQ(error_of(size + "camera:\n  backend: v4l2\n  width: 320\n"),
            "test.yaml: calibration.camera: size 640x480 differs from the camera's 320x480");
  EXPECT_EQ(error_of("laser:\n  mode: pattern\n"),
            "test.yaml:2: laser.pattern: required with mode: pattern, e.g. \"110\" (on, on, off, "
            "repeated)");
  EXPECT_EQ(
      error_of("laser:\n  mode: pattern\n  pattern: 1x0\n"),
      "test.yaml:3: laser.pattern: must be 1 to 1024 characters 0 (off) or 1 (on), got '1x0'");
  EXPECT_EQ(error_of("laser:\n  mode: on\n  pattern: \"10\"\n"),
            "test.yaml:3: laser.pattern: only used with mode: pattern");
  EXPECT_EQ(error_of("laser:\n  mode: pattern\n  pattern: \"110\"\n"), "");
  EXPECT_EQ(error_of("laser:\n  backend: gpiod\n  chip: gpiochip0\n  line: -3\n"),
            "test.yaml:4: laser.line: offset must be 0..511, got -3");
  EXPECT_EQ(error_of("laser:\n  backend: gpiod\n  chip: gpiochip0\n  line: 3\n  pin: 4\n"),
            "test.yaml:5: laser.pin: unknown key (expected one of: active_low, backend, chip, "
            "consumer, frame_timeout_ms, line, mode)");
}

}  // namespace
}  // namespace laserline::daemon

namespace laserline::daemon {
namespace {

// A laser sheet the camera cannot see is one line naming the calibration, before any frame,
// whichever way the line runs in the image (laser above or beside the camera).
TEST(Config, LaserSheetOutOfViewIsOneLine) {
  EXPECT_EQ(error_of("calibration:\n  laser: {angle_deg: 150}\n"),
            "test.yaml: calibration.laser: the sheet of a laser above the camera at baseline_m "
            "0.25, angle_deg 150 lies behind the camera at every pixel of the 1280x1024 image, so "
            "no point can be triangulated (check side and angle_deg)");
  EXPECT_EQ(error_of("calibration:\n  laser: {side: left, angle_deg: 150}\n"),
            "test.yaml: calibration.laser: the sheet of a laser left of the camera at baseline_m "
            "0.25, angle_deg 150 lies behind the camera at every pixel of the 1280x1024 image, so "
            "no point can be triangulated (check side and angle_deg)");
  EXPECT_EQ(error_of("calibration:\n  laser: {plane: [0, 0.5, 0.866, 0.25]}\n"),
            "test.yaml: calibration.laser.plane: the sheet [0, 0.5, 0.866, 0.25] lies behind the "
            "camera at every pixel of the 1280x1024 image, so no point can be triangulated (with e "
            "of the other sign it would be in front: a sign flipped?)");
  EXPECT_EQ(error_of("calibration:\n  laser: {plane: [0, 1, -0.2, 0]}\n"),
            "test.yaml: calibration.laser.plane: the sheet [0, 1, -0.2, 0] passes through the "
            "camera centre: the camera sees it edge-on and cannot triangulate (e must not be 0)");
  // The sheet of e of the other sign is seen in part of the image: not refused here (the points
  // it drops are counted where they are triangulated).
  EXPECT_EQ(error_of("calibration:\n  laser: {plane: [0, 0.985, -0.174, -0.25]}\n"
                     "detector: {name: maxvalue}\n"),
            "");

  // Nearest seen: 1/Z = (tan 10deg + 0.365) / 0.25 at the top rows (above), at the left columns
  // (left of the camera, the line running down the image).
  const std::string near_range = "detector: {frontend: {min_depth_m: 0.1, max_depth_m: 0.3}}\n";
  EXPECT_EQ(error_of(near_range),
            "test.yaml: calibration.laser: the 1280x1024 image sees the laser sheet at depths "
            "0.462 m to infinity, none of them within the depth range searched, 0.1 to 0.3 m "
            "(detector.frontend.min_depth_m and max_depth_m of test.yaml): check the calibration "
            "or the range");
  EXPECT_EQ(error_of("calibration:\n  laser: {side: left}\n" + near_range),
            "test.yaml: calibration.laser: the 1280x1024 image sees the laser sheet at depths "
            "0.395 m to infinity, none of them within the depth range searched, 0.1 to 0.3 m "
            "(detector.frontend.min_depth_m and max_depth_m of test.yaml): check the calibration "
            "or the range");
  // A sheet steep enough to stay near: seen up to a finite depth.
  EXPECT_EQ(error_of("calibration:\n  laser: {angle_deg: 60}\n"
                     "detector: {frontend: {min_depth_m: 3, max_depth_m: 10}}\n"),
            "test.yaml: calibration.laser: the 1280x1024 image sees the laser sheet at depths "
            "0.265 m to 1.18 m, none of them within the depth range searched, 3 to 10 m "
            "(detector.frontend.min_depth_m and max_depth_m of test.yaml): check the calibration "
            "or the range");
  // maxvalue looks at every pixel: the front-end's range is not its business.
  EXPECT_EQ(error_of("detector:\n  name: maxvalue\n  frontend: {min_depth_m: 0.1, max_depth_m: "
                     "0.3}\n"),
            "");
}

TEST(Config, LaserSheetOutOfViewNamesTheCalibrationFile) {
  const auto dir = std::filesystem::temp_directory_path() / "laserline_test_config_sheet";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "calib.yaml") << "camera: {width: 1280, height: 1024, fx: 1400, fy: 1400}\n"
                                       "laser: {angle_deg: 150}\n";
  std::ofstream(dir / "daemon.yaml") << "calibration: calib.yaml\n";
  try {
    DaemonConfig config = load_config_file((dir / "daemon.yaml").string());
    create_backends(config);
    FAIL() << "a sheet behind the camera must be an error";
  } catch (const hal::ConfigError& e) {
    EXPECT_EQ(std::string(e.what()).rfind((dir / "calib.yaml").string() + ": laser: the sheet", 0),
              0u)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

// The calibration in a calibration_t message: what the daemon publishes is what a tool reads back
// (the same id); a message whose values are out of range or whose id is not its content's is
// refused in one line.
TEST(CalibrationMessage, RoundTripsWithItsIdAndRefusesWhatDoesNotHold) {
  hal::Calibration calibration;
  calibration.camera.width = 640;
  calibration.camera.height = 480;
  calibration.camera.fx = 701.5;
  calibration.camera.distortion = {-0.1, 0.02, 0.001, -0.002, 0.003};
  calibration.laser.side = hal::LaserSide::kLeft;
  const laserline::calibration_t message = calibration_message(calibration, 42);
  EXPECT_EQ(static_cast<std::uint64_t>(message.calibration_id), hal::calibration_id(calibration));
  EXPECT_EQ(message.instance_id, 42);
  EXPECT_EQ(message.width, 640);
  EXPECT_EQ(message.distortion[4], 0.003);
  EXPECT_EQ(message.laser_plane[0], 1.0) << "the sheet of a projector on the left";
  hal::Calibration back;
  std::string problem;
  ASSERT_TRUE(calibration_from_message(message, &back, &problem)) << problem;
  EXPECT_EQ(hal::calibration_id(back), hal::calibration_id(calibration));
  EXPECT_EQ(back.camera.fx, 701.5);
  EXPECT_TRUE(back.laser.plane.has_value());

  laserline::calibration_t changed = message;
  changed.cy += 1;  // the content changed, the id did not
  EXPECT_FALSE(calibration_from_message(changed, &back, &problem));
  EXPECT_EQ(problem,
            "calibration_id " +
                hal::calibration_id_text(static_cast<std::uint64_t>(message.calibration_id)) +
                " is not the id of its content (" +
                hal::calibration_id_text(hal::calibration_id([&] {
                  hal::Calibration c = calibration;
                  c.camera.cy += 1;
                  return c;
                }())) +
                ")");
  changed = message;
  changed.fx = NAN;
  EXPECT_FALSE(calibration_from_message(changed, &back, &problem));
  EXPECT_EQ(problem, "fx nan outside 1..1e+06");
  changed = message;
  changed.width = 0;
  EXPECT_FALSE(calibration_from_message(changed, &back, &problem));
  EXPECT_EQ(problem, "width 0 outside 16..16384");
  changed = message;
  changed.laser_plane[0] = changed.laser_plane[1] = changed.laser_plane[2] = 0;
  EXPECT_FALSE(calibration_from_message(changed, &back, &problem));
  EXPECT_EQ(problem, "laser_plane: the normal (a, b, c) is zero");
}

}  // namespace
}  // namespace laserline::daemon
