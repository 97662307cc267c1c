// The motion stage's driver (paper III-A): MotionEstimator's options, reset() and the order of
// the steps per frame. The steps: features.cpp (pyramid, corners, laser filter), tracking.cpp
// (pyramidal Lucas-Kanade), homography.cpp (RANSAC and refit), camera_motion.cpp (essential
// matrix, R and t, relative scale) with five_point.cpp (the minimal solver).
#include "pipeline/motion.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "pipeline/motion_internal.hpp"

namespace laserline::pipeline {

using namespace motion_detail;

MotionEstimator::MotionEstimator(const MotionOptions& options)
    : options_(options), camera_(options) {
  options.validate();
  state_ = new State;
}

MotionEstimator::~MotionEstimator() {
  delete state_;
}

void MotionEstimator::reset(int width, int height, const ScannerGeometry* geometry) {
  const MotionOptions& o = options_;
  const std::string size = std::to_string(width) + "x" + std::to_string(height);
  if (width <= 0 || height <= 0 || width > 65535 || height > 65535) {
    throw std::invalid_argument("MotionEstimator::reset: image size " + size +
                                " must be within 1x1 .. 65535x65535");
  }
  if (geometry != nullptr) {
    if (geometry->width != width || geometry->height != height) {
      throw std::invalid_argument(
          "MotionEstimator::reset: image size " + size + " differs from the geometry's " +
          std::to_string(geometry->width) + "x" + std::to_string(geometry->height));
    }
    if (!(geometry->fx > 0 && geometry->fy > 0 && std::isfinite(geometry->fx) &&
          std::isfinite(geometry->fy) && std::isfinite(geometry->cx) &&
          std::isfinite(geometry->cy))) {
      throw std::invalid_argument(
          "MotionEstimator::reset: the geometry's fx, fy must be > 0 and "
          "cx, cy finite");
    }
    for (double k : geometry->distortion) {
      if (!std::isfinite(k)) {
        throw std::invalid_argument(
            "MotionEstimator::reset: the geometry's distortion must be finite");
      }
    }
  }
  State& s = *state_;
  // Until this reset() completes, update() refuses every frame (a refused size leaves no half
  // sized state behind).
  s.width = s.height = 0;
  s.has_previous = false;
  s.reported_rejected = -1;
  s.track_count = 0;

  // Every level must hold a whole tracking window with its gradient border.
  const int top = o.pyramid_levels - 1;
  const int min_side = 2 * (o.window_radius + 2) + 1;
  const int top_width = width >> top, top_height = height >> top;
  if (top_width < min_side || top_height < min_side) {
    throw std::invalid_argument(
        "MotionEstimator::reset: image " + size + " is too small for " +
        std::to_string(o.pyramid_levels) + " pyramid levels: level " + std::to_string(top) +
        " would be " + std::to_string(top_width) + "x" + std::to_string(top_height) +
        ", tracking with window_radius " + std::to_string(o.window_radius) + " needs at least " +
        std::to_string(min_side) + "x" + std::to_string(min_side));
  }
  // Features keep clear of the border by a tracking window at the coarsest level, so that they
  // can be tracked at every level.
  const int detect_width = width >> o.detect_level, detect_height = height >> o.detect_level;
  s.margin = (o.window_radius + 2) << std::max(0, top - o.detect_level);
  const int valid_width = detect_width - 2 * s.margin, valid_height = detect_height - 2 * s.margin;
  if (valid_width < o.grid_columns || valid_height < o.grid_rows) {
    throw std::invalid_argument("MotionEstimator::reset: image " + size + " is too small for a " +
                                std::to_string(o.grid_columns) + "x" + std::to_string(o.grid_rows) +
                                " feature grid at detect_level " + std::to_string(o.detect_level) +
                                " (" + std::to_string(detect_width) + "x" +
                                std::to_string(detect_height) + " with a border of " +
                                std::to_string(s.margin) + ")");
  }

  for (Pyramid& pyramid : s.pyramids) {
    for (int l = 0; l < kMaxLevels; ++l) {
      Level& level = pyramid.levels[l];
      // Full size is not kept (see State::patches).
      if (l >= 1 && l < o.pyramid_levels) {
        level.width = width >> l;
        level.height = height >> l;
        level.pixels.assign(static_cast<std::size_t>(level.width) * level.height, 0);
      } else {
        level = Level{};
      }
    }
  }
  const int cells = o.grid_columns * o.grid_rows;
  s.patch_bytes = (2 * o.window_radius + 3) * (2 * o.window_radius + 3);
  for (int i = 0; i < 2; ++i) {
    s.features[i].assign(cells, Point{});
    s.patches[i].assign(static_cast<std::size_t>(cells) * s.patch_bytes, 0);
    s.rejected[i].assign(cells, Point{});
    s.feature_count[i] = 0;
    s.rejected_count[i] = 0;
  }
  s.tracks.assign(cells, FeatureTrack{});

  s.cell_of_row.assign(detect_height, -1);
  s.grid_row_start.assign(o.grid_rows + 1, detect_height - s.margin);
  for (int v = detect_height - s.margin - 1; v >= s.margin; --v) {
    s.cell_of_row[v] = (v - s.margin) * o.grid_rows / valid_height;
    s.grid_row_start[s.cell_of_row[v]] = v;
  }
  s.parts = std::clamp(runner_->parts(), 1, kMaxParts);
  s.pyramid_alignment = 1 << std::max(0, o.pyramid_levels - 2);
  s.corner_scratch.resize(static_cast<std::size_t>(s.parts));
  for (CornerScratch& scratch : s.corner_scratch) {
    for (int i = 0; i < 3; ++i) {
      scratch.gxx[i].assign(detect_width, 0);
      scratch.gxy[i].assign(detect_width, 0);
      scratch.gyy[i].assign(detect_width, 0);
    }
    for (auto* v : {&scratch.column_xx, &scratch.column_xy, &scratch.column_yy})
      v->assign(detect_width, 0);
    scratch.score.assign(detect_width, 0.0f);
  }
  s.cell_on_laser.assign(cells, 0);
  s.feature_tracks.assign(cells, TrackResult{});
  s.cell_start.assign(o.grid_columns + 1, 0);
  for (int column = 0; column <= o.grid_columns; ++column)
    s.cell_start[column] = s.margin + (column * valid_width + o.grid_columns - 1) / o.grid_columns;
  s.cell_score.assign(cells, 0);
  s.cell_u.assign(cells, 0);
  s.cell_v.assign(cells, 0);

  for (auto* v : {&s.px, &s.py, &s.cx, &s.cy})
    v->assign(cells, 0);
  s.all_index.assign(cells, 0);
  s.inlier_index.assign(cells, 0);
  s.is_inlier.assign(cells, 0);
  s.best_inlier.assign(cells, 0);

  s.has_camera = geometry != nullptr;
  const int follow = s.has_camera ? std::min(cells, o.scale_tracks) : 0;
  s.follow_from.assign(follow, Point{});
  s.follow_pixel.assign(follow, Point{});
  s.follow_has_patch.assign(follow, 0);
  s.follow_patches.assign(static_cast<std::size_t>(follow) * s.patch_bytes, 0);
  s.followed.assign(follow, {});
  s.follow_tracks.assign(follow, TrackResult{});
  s.follow_count = 0;
  if (s.has_camera) camera_.reset(*geometry, cells);
  s.width = width;
  s.height = height;
}

template <class Work>
void MotionEstimator::run_parts(Work& work) {
  if (state_->parts > 1 && runner_->parts() == state_->parts) {
    runner_->run(PartWork(work));
  } else {
    for (int part = 0; part < state_->parts; ++part)
      work(part);
  }
}

std::span<const FeatureTrack> MotionEstimator::tracks() const {
  return {state_->tracks.data(), static_cast<std::size_t>(state_->track_count)};
}

std::span<const std::array<float, 2>> MotionEstimator::rejected_features() const {
  const State& s = *state_;
  if (s.reported_rejected < 0) return {};
  return {s.rejected[s.reported_rejected].data(),
          static_cast<std::size_t>(s.rejected_count[s.reported_rejected])};
}

MotionEstimate MotionEstimator::update(const ImageView& frame) {
  State& s = *state_;
  const MotionOptions& o = options_;
  MotionEstimate estimate;
  s.track_count = 0;
  s.reported_rejected = -1;
  if (s.width == 0 || frame.width != s.width || frame.height != s.height || frame.data == nullptr ||
      frame.stride < frame.width) {
    return estimate;
  }

  const int current = 1 - s.previous;
  // The pyramid in bands of rows; then the previous frame's features tracked into it and this
  // frame's corners found in it, each part a share of the features and a band of grid rows.
  const int level1 = s.height >> 1;
  const int units = (level1 + s.pyramid_alignment - 1) / s.pyramid_alignment;
  auto pyramid_part = [&](int part) {
    const auto [first, end] = part_range(units, part, s.parts);
    build_pyramid(frame, o.pyramid_levels, s.pyramids[current], first * s.pyramid_alignment,
                  std::min(end * s.pyramid_alignment, level1));
  };
  run_parts(pyramid_part);
  auto features_part = [&](int part) {
    if (s.has_previous) track_part(current, frame, part);
    find_corners(current, frame, part);
  };
  run_parts(features_part);

  if (s.has_previous) {
    estimate = estimate_from_previous();
    s.reported_rejected = s.previous;
  }
  if (s.has_camera) keep_follow_patches(frame);
  detect_features(current, frame);
  s.previous = current;
  s.has_previous = true;
  return estimate;
}

}  // namespace laserline::pipeline
