#include "pipeline/options.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>

#include "pipeline/detector.hpp"

// Every option of the pipeline is checked here, once: the stages' constructors call these, and a
// configuration reader calls them to refuse a file before anything starts. The bounds are what the
// stages support, or cap the work per frame so that its worst case is known.

namespace laserline::pipeline {

OptionError::OptionError(const std::string& field, const std::string& problem)
    : std::invalid_argument(field + " " + problem), field_(field), problem_(problem) {}

namespace {

std::string text(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}
std::string text(int value) {
  return std::to_string(value);
}

// Written so that NaN fails too.
template <typename T>
void within(const char* field, T value, T min, T max) {
  if (!(value >= min && value <= max)) {
    throw OptionError(
        field, "must be between " + text(min) + " and " + text(max) + ", got " + text(value));
  }
}

void at_least(const char* field, double value, double min) {
  if (!(value >= min && std::isfinite(value))) {
    throw OptionError(field, "must be at least " + text(min) + ", got " + text(value));
  }
}

}  // namespace

DetectionRegion DetectionRegion::in_frame(int frame_width, int frame_height) const {
  if (whole()) return {0, 0, frame_width, frame_height};
  const std::int64_t x0 = std::clamp<std::int64_t>(x, 0, frame_width);
  const std::int64_t y0 = std::clamp<std::int64_t>(y, 0, frame_height);
  const std::int64_t x1 = std::clamp<std::int64_t>(std::int64_t{x} + width, x0, frame_width);
  const std::int64_t y1 = std::clamp<std::int64_t>(std::int64_t{y} + height, y0, frame_height);
  return {static_cast<int>(x0), static_cast<int>(y0), static_cast<int>(x1 - x0),
          static_cast<int>(y1 - y0)};
}

bool DetectionRegion::contains(double px, double py) const {
  if (!(std::isfinite(px) && std::isfinite(py))) return false;
  const double column = std::round(px), row = std::round(py);
  return column >= x && column < static_cast<double>(x) + width && row >= y &&
         row < static_cast<double>(y) + height;
}

std::string DetectionRegion::text() const {
  std::ostringstream out;
  out << x << ',' << y << ',' << width << ',' << height;
  return out.str();
}

void DetectionRegion::validate(int frame_width, int frame_height) const {
  if (whole()) return;
  std::ostringstream bracketed;
  bracketed << '[' << x << ", " << y << ", " << width << ", " << height << ']';
  const std::string given = bracketed.str();
  if (x < 0 || y < 0) throw OptionError("roi", "x and y must be at least 0, got " + given);
  if (width < 1 || height < 1) {
    throw OptionError("roi", "width and height must be at least 1 pixel, got " + given);
  }
  if (std::int64_t{x} + width > frame_width || std::int64_t{y} + height > frame_height) {
    std::ostringstream problem;
    problem << given << " reaches beyond the " << frame_width << 'x' << frame_height << " frame";
    throw OptionError("roi", problem.str());
  }
}

void validate_maxvalue_threshold(int threshold) {
  within("threshold", threshold, 1, 255);
}

void LineSelectionOptions::validate() const {
  within("restart_cost_db", restart_cost_db, 0.0, 10000.0);
  within("amplitude_cap_db", amplitude_cap_db, 0.1, 1000.0);
  within("jump_free_px", jump_free_px, 0.0, 1000.0);
  within("jump_cost_db_per_px", jump_cost_db_per_px, 0.0, 1000.0);
  within("jump_cost_cap_db", jump_cost_cap_db, 0.0, 100000.0);
  within("gap_cost_db", gap_cost_db, 0.0, 1000.0);
  within("max_gap", max_gap, 0, 64);
  within("previous_bonus_db", previous_bonus_db, 0.0, 1000.0);
  within("previous_other_bonus_db", previous_other_bonus_db, 0.0, 1000.0);
  within("faint_piece_db", faint_piece_db, 0.0, 1000.0);
  within("previous_tolerance_px", previous_tolerance_px, 0.0, 1000.0);
}

void FrontendOptions::validate() const {
  within("min_depth_m", min_depth_m, 0.01, 1000.0);
  within("max_depth_m", max_depth_m, 0.01, 1000.0);
  if (!(max_depth_m > min_depth_m)) throw OptionError("max_depth_m", "must be above min_depth_m");
  within("normalised_width_px", normalised_width_px, 1.0, 32.0);
  within("line_blur_px", line_blur_px, 0.0, 32.0);
  within("passband_ratio", passband_ratio, 1.5, 16.0);
  within("noise_rows", noise_rows, 3, 1001);
  within("noise_columns", noise_columns, 1, 101);
  if (!(noise_side_ratio == 0.0 || (noise_side_ratio >= 1.0 && noise_side_ratio <= 1000.0))) {
    throw OptionError("noise_side_ratio",
                      "must be 0 (off) or between 1 and 1000, got " + text(noise_side_ratio));
  }
  within("snr_threshold_db", snr_threshold_db, 0.0, 60.0);
  within("snr_hysteresis_db", snr_hysteresis_db, 0.0, 60.0);
  // Candidates are counted per column in a byte.
  within("max_candidates_per_column", max_candidates_per_column, 1, 255);
  within("saturation_level", saturation_level, 1, 255);
  selection.validate();
}

void BackgroundOptions::validate() const {
  within("history_frames", history_frames, 1, 64);
  within("min_motion_widths", min_motion_widths, 0.0, 100.0);
}

void MotionOptions::validate() const {
  within("grid_columns", grid_columns, 1, 64);
  within("grid_rows", grid_rows, 1, 64);
  within("pyramid_levels", pyramid_levels, 1, kMaxPyramidLevels);
  if (detect_level < 0 || detect_level >= pyramid_levels) {
    throw OptionError("detect_level", "must be between 0 and " + text(pyramid_levels - 1) +
                                          " (below pyramid_levels), got " + text(detect_level));
  }
  within("window_radius", window_radius, 1, kMaxWindowRadius);
  within("max_iterations", max_iterations, 1, 50);
  within("ransac_iterations", ransac_iterations, 1, 10000);
  within("inlier_px", inlier_px, 0.05, 50.0);
  within("min_inliers", min_inliers, 4, 4096);
  // 1e9 and the like: no feature is taken for the laser line.
  at_least("laser_filter_ratio", laser_filter_ratio, 1.0);
  within("essential_ransac_iterations", essential_ransac_iterations, 1, 10000);
  within("essential_inlier_px", essential_inlier_px, 0.05, 50.0);
  within("essential_min_parallax_px", essential_min_parallax_px, 0.0, 100.0);
  within("scale_tracks", scale_tracks, 0, 4096);
}

void ValidationOptions::validate() const {
  within("max_neighbour_gap_px", max_neighbour_gap_px, 1.0, 64.0);
  within("min_segment_points", min_segment_points, 2, 1000);
  within("max_box_distance_px", max_box_distance_px, 0.0, 1000.0);
  within("max_column_offset", max_column_offset, 0, 256);
  within("min_correlation", min_correlation, 0.0, 1.0);
  within("feature_search_px", feature_search_px, 0, 32);
  within("patch_columns", patch_columns, 4, 256);
  within("patch_rows", patch_rows, 4, 256);
  within("background_px", background_px, 0.01, 100.0);
  within("max_depth_baselines", max_depth_baselines, 1.0, 1e6);
  within("max_laser_motion_px", max_laser_motion_px, 0.0, 1000.0);
}

void DetectorOptions::validate() const {
  validate_maxvalue_threshold(maxvalue_threshold);
  frontend.validate();
  background.validate();
  motion.validate();
  validation.validate();
}

}  // namespace laserline::pipeline
