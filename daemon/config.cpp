#include "daemon/config.hpp"

#include <malloc.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include "hal/camera.hpp"
#include "pipeline/options.hpp"
#include "pipeline/profile.hpp"

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
// The sanitizer runtime's count (declared in <sanitizer/allocator_interface.h>, which GCC 12 on
// Debian does not install).
extern "C" std::size_t __sanitizer_get_current_allocated_bytes();
#endif

namespace laserline::daemon {

namespace {

int power_of_two(hal::YamlMap& map, const std::string& key, int fallback) {
  const auto value = static_cast<int>(map.integer(key, fallback, 2, 1024));
  if ((value & (value - 1)) != 0)
    map.fail(key, "must be a power of two, got " + std::to_string(value));
  return value;
}

// The detector's options are read here as numbers and checked by the pipeline (their one check):
// its error names the field, which is the key in `map`.
void read(hal::YamlMap& map, const char* key, double& value) {
  value = map.number(key, value, -HUGE_VAL, HUGE_VAL);
}
void read(hal::YamlMap& map, const char* key, int& value) {
  value = static_cast<int>(map.integer(key, value, INT_MIN, INT_MAX));
}
template <typename Check>
void checked(const hal::YamlMap& map, Check check) {
  try {
    check();
  } catch (const pipeline::OptionError& e) {
    map.fail(e.field(), e.problem());
  }
}

hal::Calibration read_calibration_section(hal::YamlMap& root, const std::string& source,
                                          CalibrationSource& where) {
  if (root.has("calibration")) {
    YAML::Node node = root.node("calibration");
    if (node.IsScalar()) {
      // A path, relative to the configuration file.
      std::filesystem::path path = node.Scalar();
      if (path.is_relative() && source.find('/') != std::string::npos) {
        path = std::filesystem::path(source).parent_path() / path;
      }
      where = {path.string(), "laser"};
      return hal::load_calibration_file(path.string());
    }
  }
  where = {source, "calibration.laser"};
  hal::YamlMap section = root.map("calibration");
  hal::Calibration calibration = hal::read_calibration(section);
  section.finish();
  return calibration;
}

std::string format_number(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", value);
  return text;
}

std::string format_whole(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.15g", value);
  return text;
}

// Saturating arithmetic for sizes: a hostile configuration must give "too large", not a wrap.
std::uint64_t times(std::uint64_t a, std::uint64_t b) {
  std::uint64_t product = 0;
  return __builtin_mul_overflow(a, b, &product) ? UINT64_MAX : product;
}
std::uint64_t plus(std::uint64_t a, std::uint64_t b) {
  std::uint64_t sum = 0;
  return __builtin_add_overflow(a, b, &sum) ? UINT64_MAX : sum;
}

std::string megabytes(std::uint64_t bytes) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f MB", static_cast<double>(bytes) / 1e6);
  return text;
}

// Bytes the heap holds now (mmap'ed blocks included). A sanitizer's allocator replaces glibc's,
// whose counts then stay still: ask the sanitizer.
std::uint64_t heap_in_use() {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  return __sanitizer_get_current_allocated_bytes();
#else
  const struct mallinfo2 info = mallinfo2();
  return info.uordblks + info.hblkhd;
#endif
}

// The sheet as the calibration gives it: the plane, or the mount it is computed from.
std::string describe_sheet(const hal::LaserMount& laser) {
  if (laser.plane) {
    const Eigen::Vector4d& p = *laser.plane;
    return "the sheet [" + format_number(p[0]) + ", " + format_number(p[1]) + ", " +
           format_number(p[2]) + ", " + format_number(p[3]) + "]";
  }
  const bool beside = laser.side == hal::LaserSide::kLeft || laser.side == hal::LaserSide::kRight;
  return std::string("the sheet of a laser ") + hal::to_string(laser.side) + (beside ? " of" : "") +
         " the camera at baseline_m " + format_number(laser.baseline_m) + ", angle_deg " +
         format_number(laser.angle_deg);
}

}  // namespace

void read_detector_options(hal::YamlMap& detector, pipeline::DetectorOptions& options) {
  // Checked against the frame by the pipeline once the calibration is known (parse_config()).
  const std::vector<double> roi = detector.numbers("roi", {4});
  if (!roi.empty()) {
    for (double v : roi) {
      if (v != std::floor(v) || std::fabs(v) > 1e9) {
        detector.fail("roi", "expected [x, y, width, height] in whole pixels");
      }
    }
    options.roi = {static_cast<int>(roi[0]), static_cast<int>(roi[1]), static_cast<int>(roi[2]),
                   static_cast<int>(roi[3])};
  }

  hal::YamlMap maxvalue = detector.map("maxvalue");
  read(maxvalue, "threshold", options.maxvalue_threshold);
  checked(maxvalue, [&] { pipeline::validate_maxvalue_threshold(options.maxvalue_threshold); });
  maxvalue.finish();

  pipeline::FrontendOptions& f = options.frontend;
  hal::YamlMap frontend = detector.map("frontend");
  read(frontend, "min_depth_m", f.min_depth_m);
  read(frontend, "max_depth_m", f.max_depth_m);
  read(frontend, "normalised_width_px", f.normalised_width_px);
  read(frontend, "line_blur_px", f.line_blur_px);
  read(frontend, "passband_ratio", f.passband_ratio);
  read(frontend, "noise_rows", f.noise_rows);
  read(frontend, "noise_columns", f.noise_columns);
  read(frontend, "noise_side_ratio", f.noise_side_ratio);
  read(frontend, "snr_threshold_db", f.snr_threshold_db);
  read(frontend, "snr_hysteresis_db", f.snr_hysteresis_db);
  read(frontend, "max_candidates_per_column", f.max_candidates_per_column);
  read(frontend, "saturation_level", f.saturation_level);
  pipeline::LineSelectionOptions& l = f.selection;
  hal::YamlMap selection = frontend.map("selection");
  l.enabled = selection.boolean("enabled", l.enabled);
  read(selection, "restart_cost_db", l.restart_cost_db);
  read(selection, "amplitude_cap_db", l.amplitude_cap_db);
  read(selection, "jump_free_px", l.jump_free_px);
  read(selection, "jump_cost_db_per_px", l.jump_cost_db_per_px);
  read(selection, "jump_cost_cap_db", l.jump_cost_cap_db);
  read(selection, "gap_cost_db", l.gap_cost_db);
  read(selection, "max_gap", l.max_gap);
  read(selection, "previous_bonus_db", l.previous_bonus_db);
  read(selection, "previous_other_bonus_db", l.previous_other_bonus_db);
  read(selection, "faint_piece_db", l.faint_piece_db);
  read(selection, "previous_tolerance_px", l.previous_tolerance_px);
  checked(selection, [&] { l.validate(); });
  selection.finish();
  checked(frontend, [&] { f.validate(); });
  frontend.finish();

  pipeline::BackgroundOptions& b = options.background;
  hal::YamlMap background = detector.map("background");
  read(background, "history_frames", b.history_frames);
  read(background, "min_motion_widths", b.min_motion_widths);
  b.remove_own_line = background.boolean("remove_own_line", b.remove_own_line);
  checked(background, [&] { b.validate(); });
  background.finish();

  pipeline::MotionOptions& m = options.motion;
  hal::YamlMap motion = detector.map("motion");
  read(motion, "grid_columns", m.grid_columns);
  read(motion, "grid_rows", m.grid_rows);
  read(motion, "detect_level", m.detect_level);
  read(motion, "pyramid_levels", m.pyramid_levels);
  read(motion, "window_radius", m.window_radius);
  read(motion, "max_iterations", m.max_iterations);
  read(motion, "ransac_iterations", m.ransac_iterations);
  read(motion, "inlier_px", m.inlier_px);
  read(motion, "min_inliers", m.min_inliers);
  read(motion, "laser_filter_ratio", m.laser_filter_ratio);
  read(motion, "essential_ransac_iterations", m.essential_ransac_iterations);
  read(motion, "essential_inlier_px", m.essential_inlier_px);
  read(motion, "essential_min_parallax_px", m.essential_min_parallax_px);
  read(motion, "scale_tracks", m.scale_tracks);
  checked(motion, [&] { m.validate(); });
  motion.finish();

  pipeline::ValidationOptions& v = options.validation;
  hal::YamlMap validation = detector.map("validation");
  const std::string association = validation.choice(
      "association",
      v.association == pipeline::SegmentAssociation::chain_code ? "chain_code" : "image_features",
      {"chain_code", "image_features"});
  v.association = association == "chain_code" ? pipeline::SegmentAssociation::chain_code
                                              : pipeline::SegmentAssociation::image_features;
  read(validation, "max_neighbour_gap_px", v.max_neighbour_gap_px);
  read(validation, "min_segment_points", v.min_segment_points);
  read(validation, "max_box_distance_px", v.max_box_distance_px);
  read(validation, "max_column_offset", v.max_column_offset);
  read(validation, "min_correlation", v.min_correlation);
  read(validation, "feature_search_px", v.feature_search_px);
  read(validation, "patch_columns", v.patch_columns);
  read(validation, "patch_rows", v.patch_rows);
  read(validation, "background_px", v.background_px);
  read(validation, "max_depth_baselines", v.max_depth_baselines);
  v.require_track = validation.boolean("require_track", v.require_track);
  read(validation, "max_laser_motion_px", v.max_laser_motion_px);
  checked(validation, [&] { v.validate(); });
  validation.finish();
}

pipeline::ScannerGeometry scanner_geometry(const hal::Calibration& calibration) {
  pipeline::ScannerGeometry g;
  g.width = calibration.camera.width;
  g.height = calibration.camera.height;
  g.fx = calibration.camera.fx;
  g.fy = calibration.camera.fy;
  g.cx = calibration.camera.cx;
  g.cy = calibration.camera.cy;
  g.distortion = calibration.camera.distortion;
  g.laser_plane = calibration.laser.plane_coefficients();
  g.sheet_width_m = calibration.laser.sheet_width_m;
  return g;
}

DepthsSeen depths_seen(const hal::Calibration& calibration) {
  const pipeline::ScannerGeometry g = scanner_geometry(calibration);
  // 1/Z on the sheet is affine in the pixel (distortion left out, as the front-end does), so its
  // range over the image is its range over the four corners, whichever way the line runs.
  const double right = g.width - 1, bottom = g.height - 1;
  const double corners[] = {g.inverse_depth(0, 0), g.inverse_depth(right, 0),
                            g.inverse_depth(0, bottom), g.inverse_depth(right, bottom)};
  const double nearest = *std::max_element(std::begin(corners), std::end(corners));
  const double farthest = *std::min_element(std::begin(corners), std::end(corners));
  if (!(nearest > 0)) return {nearest, farthest};
  return {1.0 / nearest, farthest > 0 ? 1.0 / farthest : INFINITY};
}

void check_laser_sheet_in_view(const hal::Calibration& calibration,
                               const CalibrationSource& calibration_source,
                               const pipeline::FrontendOptions* depth_range,
                               const std::string& depth_range_source) {
  const pipeline::ScannerGeometry g = scanner_geometry(calibration);
  const std::string key =
      calibration_source.laser_key + (calibration.laser.plane ? std::string(".plane") : "");
  const std::string where = calibration_source.file + ": " + key + ": ";
  if (g.laser_plane[3] == 0.0) {
    throw hal::ConfigError(where + describe_sheet(calibration.laser) +
                           " passes through the camera centre: the camera sees it edge-on and "
                           "cannot triangulate (e must not be 0)");
  }
  const DepthsSeen seen = depths_seen(calibration);
  const std::string image = std::to_string(g.width) + "x" + std::to_string(g.height) + " image";
  if (!(seen.nearest > 0)) {
    throw hal::ConfigError(
        where + describe_sheet(calibration.laser) +
        " lies behind the camera at every pixel of the " + image +
        ", so no point can be triangulated" +
        (calibration.laser.plane
             ? " (with e of the other sign it would be in front: a sign flipped?)"
             : " (check side and angle_deg)"));
  }
  if (depth_range == nullptr) return;
  const double min_seen = seen.nearest, max_seen = seen.farthest;
  if (max_seen < depth_range->min_depth_m || min_seen > depth_range->max_depth_m) {
    throw hal::ConfigError(
        where + "the " + image + " sees the laser sheet at depths " + format_number(min_seen) +
        " m to " + (std::isfinite(max_seen) ? format_number(max_seen) + " m" : "infinity") +
        ", none of them within the depth range searched, " +
        format_number(depth_range->min_depth_m) + " to " + format_number(depth_range->max_depth_m) +
        " m (detector.frontend.min_depth_m and " + "max_depth_m of " + depth_range_source +
        "): check the calibration or the range");
  }
}

std::uint64_t frame_path_memory_bytes(const DaemonConfig& config, const hal::FrameFormat& format,
                                      std::size_t max_points) {
  const std::uint64_t frame = format.bytes();
  // The frame and raw-frame rings, each with the prototype its slots are copied from.
  std::uint64_t total = times(frame, static_cast<std::uint64_t>(config.frame_slots) + 1);
  total = plus(total, times(frame, static_cast<std::uint64_t>(config.image_slots) + 1));
  // The publisher's raw-frame message and its encoding buffer, each a frame and an eighth.
  total = plus(total, times(plus(plus(frame, frame / 8), 4096), 2));
  // Profiles: the ring, its prototype and the worker's unpublished one; the publisher's message.
  const std::uint64_t profile = times(max_points, sizeof(pipeline::ProfilePoint));
  total = plus(total, times(profile, static_cast<std::uint64_t>(config.profile_slots) + 3));
  total = plus(total, raw_frame_encoder_bytes(config.raw_frames, format));
  // Two latency windows of a status period at 4x the frame rate, and their histograms.
  const auto window = static_cast<std::uint64_t>(
      std::ceil(config.frame_rate_hz * config.status_period_s * 4.0) + 64);
  total = plus(total, times(plus(window, 200'001), 2 * sizeof(std::int64_t)));
  return total;
}

void check_frame_path(const DaemonConfig& config, const hal::FrameFormat& format,
                      pipeline::Detector& detector) {
  const std::string size = std::to_string(format.width) + "x" + std::to_string(format.height);
  if (format.width != config.calibration.camera.width ||
      format.height != config.calibration.camera.height) {
    throw hal::ConfigError(config.source + ": calibration.camera: size " +
                           std::to_string(config.calibration.camera.width) + "x" +
                           std::to_string(config.calibration.camera.height) +
                           " differs from the camera's " + size);
  }
  if (const std::string problem = raw_frame_region_problem(config.raw_frames, format);
      !problem.empty()) {
    throw hal::ConfigError(config.source + ": " + problem);
  }
  const std::uint64_t limit =
      times(static_cast<std::uint64_t>(config.frame_memory_limit_mb), 1'000'000);
  const std::string limit_text = config.source + ": pipeline.frame_memory_limit_mb: ";
  const std::uint64_t buffers =
      frame_path_memory_bytes(config, format, detector.max_points(format.width, format.height));
  if (buffers > limit) {
    throw hal::ConfigError(limit_text + "frames of " + size + " need " + megabytes(buffers) +
                           " (pipeline.frame_slots " + std::to_string(config.frame_slots) +
                           ", image_slots " + std::to_string(config.image_slots) +
                           ", profile_slots " + std::to_string(config.profile_slots) +
                           " and the raw-frame buffers), more than the limit of " +
                           std::to_string(config.frame_memory_limit_mb) +
                           " MB: fewer slots, a smaller camera or a higher limit");
  }
  // The detector's own refusal (e.g. a frame smaller than its filters), as the start meets it.
  // (Sized in as many parts as worker_threads, as the frame path will run it.)
  detector.use_parts(pipeline::sequential_parts(config.worker_threads));
  const std::uint64_t before = heap_in_use();
  try {
    detector.reset(format.width, format.height);
  } catch (const std::exception& e) {
    throw hal::ConfigError(config.source + ": detector " + detector.name() + ": frames of " + size +
                           " (calibration.camera): " + e.what());
  }
  const std::uint64_t after = heap_in_use();
  const std::uint64_t detector_bytes = after > before ? after - before : 0;
  if (plus(buffers, detector_bytes) > limit) {
    throw hal::ConfigError(limit_text + "frames of " + size + " need " + megabytes(buffers) +
                           " for the frame path and " + megabytes(detector_bytes) +
                           " for the detector " + detector.name() + ", more than the limit of " +
                           std::to_string(config.frame_memory_limit_mb) +
                           " MB: fewer slots, a smaller camera or a higher limit");
  }
}

RawFrameOptions with_raw_frame_region(RawFrameOptions options, const hal::FrameFormat& format) {
  if (options.roi_width == 0 || options.roi_height == 0) {
    options.roi_x = 0;
    options.roi_y = 0;
    options.roi_width = format.width;
    options.roi_height = format.height;
  }
  return options;
}

std::string raw_frame_region_problem(const RawFrameOptions& given, const hal::FrameFormat& format) {
  const RawFrameOptions o = with_raw_frame_region(given, format);
  const std::int64_t right = std::int64_t{o.roi_x} + o.roi_width;
  const std::int64_t bottom = std::int64_t{o.roi_y} + o.roi_height;
  if (o.roi_x < 0 || o.roi_y < 0 || o.roi_width <= 0 || o.roi_height <= 0 || right > format.width ||
      bottom > format.height) {
    return "lcm.image_roi: [" + std::to_string(o.roi_x) + ", " + std::to_string(o.roi_y) + ", " +
           std::to_string(o.roi_width) + ", " + std::to_string(o.roi_height) +
           "] is not inside the camera's " + std::to_string(format.width) + "x" +
           std::to_string(format.height) + " frame";
  }
  if (o.downscale < 1 || o.roi_width < o.downscale || o.roi_height < o.downscale) {
    return "lcm.image_downscale: " + std::to_string(o.downscale) + " leaves no pixel of a " +
           std::to_string(o.roi_width) + "x" + std::to_string(o.roi_height) + " region";
  }
  return "";
}

std::uint64_t raw_frame_encoder_bytes(const RawFrameOptions& given,
                                      const hal::FrameFormat& format) {
  const RawFrameOptions o = with_raw_frame_region(given, format);
  const int k = std::max(1, o.downscale);
  const auto out = static_cast<std::uint64_t>(std::max(0, o.roi_width / k)) *
                   static_cast<std::uint64_t>(std::max(0, o.roi_height / k));
  return out + out + out / 8 + 4096;  // the scaled region and the compressed output
}

bool searches_depth_range(const std::string& detector) {
  return detector != "maxvalue";
}

const char* to_string(LaserMode mode) {
  switch (mode) {
    case LaserMode::kOn:
      return "on";
    case LaserMode::kAlternate:
      return "alternate";
    case LaserMode::kOff:
      return "off";
    case LaserMode::kPattern:
      return "pattern";
  }
  return "unknown";
}

bool laser_mode_from_name(const std::string& name, LaserMode* mode) {
  for (LaserMode m :
       {LaserMode::kOn, LaserMode::kAlternate, LaserMode::kOff, LaserMode::kPattern}) {
    if (name == to_string(m)) {
      *mode = m;
      return true;
    }
  }
  return false;
}

DaemonConfig parse_config(const YAML::Node& root_node, const std::string& source) {
  DaemonConfig c;
  c.source = source;
  hal::YamlMap root(root_node, source, "");

  hal::YamlMap camera = root.map("camera");
  c.camera_backend = camera.string("backend", c.camera_backend);
  c.frame_rate_hz = camera.number("frame_rate_hz", c.frame_rate_hz, hal::kFrameRateRange.min,
                                  hal::kFrameRateRange.max);
  c.grab_timeout_ms = static_cast<int>(camera.integer("timeout_ms", c.grab_timeout_ms, 10, 60000));
  try {
    c.laser_channel = hal::parse_laser_channel(camera.string("channel", c.laser_channel.text));
  } catch (const std::invalid_argument& e) {
    camera.fail("channel", e.what());
  }
  // The backend reads the rest of the section (and rejects unknown keys) when it is created.
  c.camera_options = camera;

  c.calibration = read_calibration_section(root, source, c.calibration_source);

  hal::YamlMap laser = root.map("laser");
  c.laser_backend = laser.string("backend", c.laser_backend);
  laser_mode_from_name(laser.choice("mode", "on", {"on", "alternate", "off", "pattern"}),
                       &c.laser_mode);
  if (c.laser_mode == LaserMode::kPattern) {
    if (!laser.has("pattern")) {
      laser.fail("pattern", "required with mode: pattern, e.g. \"110\" (on, on, off, repeated)");
    }
    const std::string pattern = laser.string("pattern", "");
    if (pattern.empty() || pattern.size() > 1024 ||
        pattern.find_first_not_of("01") != std::string::npos) {
      laser.fail("pattern",
                 "must be 1 to 1024 characters 0 (off) or 1 (on), got '" + pattern + "'");
    }
    for (char bit : pattern)
      c.laser_pattern.push_back(bit == '1');
  } else if (laser.has("pattern")) {
    laser.fail("pattern", "only used with mode: pattern");
  }
  c.laser_frame_timeout_ms =
      static_cast<int>(laser.integer("frame_timeout_ms", c.laser_frame_timeout_ms, 10, 10000));
  c.laser_options = laser;

  hal::YamlMap detector = root.map("detector");
  c.detector = detector.choice("name", c.detector, pipeline::detector_names());
  read_detector_options(detector, c.detector_options);
  c.detector_options.geometry = scanner_geometry(c.calibration);
  checked(detector, [&] {
    c.detector_options.roi.validate(c.calibration.camera.width, c.calibration.camera.height);
  });
  detector.finish();

  hal::YamlMap realtime = root.map("realtime");
  c.realtime = realtime.boolean("enabled", c.realtime);
  for (double cpu : realtime.numbers("cpus", {1, 2, 3, 4, 5, 6, 7, 8})) {
    if (cpu != static_cast<int>(cpu) || cpu < 0 || cpu > 1023) {
      realtime.fail("cpus", "must list CPU numbers 0..1023");
    }
    c.cpus.push_back(static_cast<int>(cpu));
  }
  realtime.finish();

  hal::YamlMap pipe = root.map("pipeline");
  c.frame_slots = power_of_two(pipe, "frame_slots", c.frame_slots);
  c.profile_slots = power_of_two(pipe, "profile_slots", c.profile_slots);
  c.image_slots = power_of_two(pipe, "image_slots", c.image_slots);
  c.frame_memory_limit_mb =
      pipe.integer("frame_memory_limit_mb", c.frame_memory_limit_mb, 16, 1 << 20);
  c.worker_threads = pipe.integer("worker_threads", c.worker_threads, 1, pipeline::kMaxParts);
  pipe.finish();

  hal::YamlMap lcm = root.map("lcm");
  c.lcm_url = lcm.string("url", c.lcm_url);
  if (c.lcm_url.empty()) lcm.fail("url", "must not be empty");
  const std::string provider = c.lcm_url.substr(0, c.lcm_url.find("://"));
  if (c.lcm_url.find("://") == std::string::npos ||
      (provider != "udpm" && provider != "memq" && provider != "file" && provider != "tcpq")) {
    lcm.fail("url", "must be udpm://, memq://, file:// or tcpq://, got '" + c.lcm_url + "'");
  }
  for (auto [key, channel] : {std::pair{"profile_channel", &c.profile_channel},
                              std::pair{"image_channel", &c.image_channel},
                              std::pair{"status_channel", &c.status_channel},
                              std::pair{"calibration_channel", &c.calibration_channel}}) {
    *channel = lcm.string(key, *channel);
    // LCM carries channel names in the packet header, which caps them at 63 bytes.
    if (channel->empty() || channel->size() > 63) lcm.fail(key, "must be 1 to 63 characters");
  }
  c.command_channel = lcm.string("command_channel", c.command_channel);
  c.command_ack_channel = lcm.string("command_ack_channel", c.command_channel + "_ACK");
  for (auto [key, channel] : {std::pair{"command_channel", &c.command_channel},
                              std::pair{"command_ack_channel", &c.command_ack_channel}}) {
    if (channel->empty() || channel->size() > 63) lcm.fail(key, "must be 1 to 63 characters");
    for (const std::string* output :
         {&c.profile_channel, &c.image_channel, &c.status_channel, &c.calibration_channel}) {
      if (*channel == *output) lcm.fail(key, "'" + *channel + "' is already an output channel");
    }
  }
  if (c.command_channel == c.command_ack_channel) {
    lcm.fail("command_ack_channel", "must differ from lcm.command_channel");
  }
  c.command_token = lcm.string("command_token", c.command_token);
  if (c.command_token.size() > kMaxCommandTokenBytes) {
    lcm.fail("command_token",
             "must be at most " + std::to_string(kMaxCommandTokenBytes) + " characters");
  }
  c.profile_all_points = lcm.choice("profile_points", "accepted", {"accepted", "all"}) == "all";
  c.image_every_n = static_cast<int>(lcm.integer("image_every_n", c.image_every_n, 0, 1000000));
  RawFrameOptions& raw = c.raw_frames;
  raw.every_n = c.image_every_n;
  raw.max_rate_hz = lcm.number("image_max_rate_hz", 0.0, 0.0, 1000.0);
  const std::vector<double> roi = lcm.numbers("image_roi", {4});
  if (!roi.empty()) {
    // Compared as doubles before any conversion: x + width cannot overflow there.
    const hal::CameraIntrinsics& frame = c.calibration.camera;
    for (double v : roi) {
      if (v < 0 || v != std::floor(v)) {
        lcm.fail("image_roi", "expected [x, y, width, height] in whole pixels >= 0");
      }
    }
    if (roi[2] == 0 || roi[3] == 0) lcm.fail("image_roi", "width and height must be > 0");
    if (roi[0] + roi[2] > frame.width || roi[1] + roi[3] > frame.height) {
      lcm.fail("image_roi", "[" + format_whole(roi[0]) + ", " + format_whole(roi[1]) + ", " +
                                format_whole(roi[2]) + ", " + format_whole(roi[3]) +
                                "] is not inside the calibration's " + std::to_string(frame.width) +
                                "x" + std::to_string(frame.height) + " frame");
    }
    raw.roi_x = static_cast<int>(roi[0]);
    raw.roi_y = static_cast<int>(roi[1]);
    raw.roi_width = static_cast<int>(roi[2]);
    raw.roi_height = static_cast<int>(roi[3]);
  }
  raw.downscale = static_cast<int>(lcm.integer("image_downscale", raw.downscale, 1, 4));
  if (raw.downscale == 3) lcm.fail("image_downscale", "must be 1, 2 or 4, got 3");
  const std::string compression =
      lcm.choice("image_compression", "jpeg", {"none", "zlib", "png", "jpeg"});
  raw.compression = compression == "zlib"   ? ImageCompression::kZlib
                    : compression == "png"  ? ImageCompression::kPng
                    : compression == "jpeg" ? ImageCompression::kJpeg
                                            : ImageCompression::kNone;
  raw.jpeg_quality = static_cast<int>(lcm.integer("image_jpeg_quality", 90, 1, 100));
  raw.zlib_level = static_cast<int>(lcm.integer("image_zlib_level", 1, 1, 9));
  c.status_period_s = lcm.number("status_period_s", c.status_period_s, 0.05, 3600.0);
  c.calibration_period_s = lcm.number("calibration_period_s", c.calibration_period_s, 0.05, 3600.0);
  lcm.finish();

  root.finish();
  return c;
}

DaemonConfig load_config_file(const std::string& path) {
  return parse_config(hal::load_yaml_file(path), path);
}

DaemonConfig builtin_config() {
  return parse_config(hal::load_yaml_text(builtin_config_text(), "built-in default"),
                      "built-in default");
}

}  // namespace laserline::daemon
