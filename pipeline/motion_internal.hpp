// Private to the motion stage (pipeline/motion.cpp, features.cpp, tracking.cpp, homography.cpp,
// camera_motion.cpp, five_point.cpp): the bounds, the image pyramid, the state of MotionEstimator
// and the small pieces more than one stage uses. Not part of the pipeline's interface.
#pragma once

#include <Eigen/Dense>
#include <array>
#include <cstdint>
#include <vector>

#include "pipeline/image_view.hpp"
#include "pipeline/motion.hpp"

namespace laserline::pipeline::motion_detail {

constexpr int kMaxLevels = MotionOptions::kMaxPyramidLevels;
constexpr int kMaxWindowRadius = MotionOptions::kMaxWindowRadius;
// Sampled patch around a tracked point: the window plus one pixel each side for the gradient.
constexpr int kMaxPatch = 2 * kMaxWindowRadius + 3;
// Shi-Tomasi floor: the weaker eigenvalue of the 3x3 structure tensor (half central differences,
// grey levels) must exceed this, i.e. about one grey level per pixel of gradient in the weaker
// direction. Sensor noise at the detect level (averaged over 2^level squared pixels) stays well
// below.
constexpr float kMinEigenvalue = 9.0f;
// Laser filter Haar wavelets at the detect level: boxes of kHaarSize x kHaarSize/2 (difference of
// the two halves), laid on a grid of step kHaarSize/2 across the neighbourhood. Boxes integrate
// along the line, where the laser is coherent and the texture is not.
constexpr int kHaarSize = 4;
// Blocks across the laser filter's neighbourhood (radius 2 * window_radius) and one more.
constexpr int kMaxHaarBlocks = (4 * kMaxWindowRadius) / (kHaarSize / 2) + 2;
// A track has converged when its last update at full size moved it less than this (pixels).
constexpr float kConvergedStep = 0.05f;
constexpr float kStopStep = 0.01f;
constexpr float kCoarseStopStep = 0.05f;
constexpr double kRansacConfidence = 0.999;
constexpr std::uint64_t kRansacSeed = 0x9e3779b97f4a7c15ull;

struct Level {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;  // stride = width
  const std::uint8_t* row(int v) const {
    return pixels.data() + static_cast<std::ptrdiff_t>(v) * width;
  }
  ImageView view() const { return ImageView{pixels.data(), width, height, width}; }
};

struct Pyramid {
  std::array<Level, kMaxLevels> levels;
};

using Point = std::array<float, 2>;

// Where a point was tracked to (tracking.cpp).
struct TrackResult {
  float u = 0, v = 0;
  bool converged = false;
};

// One part's scratch for the corners (features.cpp): gradient products of the last three rows,
// their sums over those rows (kept sliding), the corner score (smaller eigenvalue) per column.
struct CornerScratch {
  std::array<std::vector<std::int32_t>, 3> gxx, gxy, gyy;
  std::vector<std::int32_t> column_xx, column_xy, column_yy;
  std::vector<float> score;
};

// splitmix64: small, fast and the same everywhere, so RANSAC repeats bit for bit.
struct Random {
  std::uint64_t state;
  std::uint64_t next() {
    std::uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  int below(int n) { return static_cast<int>(next() % static_cast<std::uint64_t>(n)); }
};

using Matrix3 = Eigen::Matrix3d;

Matrix3 to_matrix(const Homography& h);

// Builds levels 1 .. levels-1 of `frame`'s pyramid (level 0, full size, is not kept): the rows
// [first, end) of level 1 and the rows of the coarser levels made from them only (first and end
// multiples of 2^(levels - 2), or end the height of level 1).
void build_pyramid(const ImageView& frame, int levels, Pyramid& pyramid, int first, int end);

// The eight-point normal matrix row of one correspondence: current^T E previous = row . e.
inline Eigen::Matrix<double, 9, 1> epipolar_row(double x1, double y1, double x2, double y2) {
  Eigen::Matrix<double, 9, 1> row;
  row << x2 * x1, x2 * y1, x2, y2 * x1, y2 * y1, y2, x1, y1, 1;
  return row;
}

}  // namespace laserline::pipeline::motion_detail

namespace laserline::pipeline {

struct MotionEstimator::State {
  using Point = motion_detail::Point;
  using Pyramid = motion_detail::Pyramid;

  int width = 0;
  int height = 0;
  bool has_previous = false;
  std::array<Pyramid, 2> pyramids;
  int previous = 0;  // index of the previous frame's pyramid and features

  // Features found in each pyramid's frame, full-size coordinates, and the ones the laser filter
  // kept out.
  std::array<std::vector<Point>, 2> features;
  std::array<int, 2> feature_count{};
  std::array<std::vector<Point>, 2> rejected;
  std::array<int, 2> rejected_count{};
  int reported_rejected = -1;  // index of the rejected list the last update() reports, -1: none
  // Full-size frames are not kept, only the (2r+3)^2 patch around each feature (what the
  // tracker's full-size template needs): patch_bytes per feature.
  std::array<std::vector<std::uint8_t>, 2> patches;
  int patch_bytes = 0;

  std::vector<FeatureTrack> tracks;
  int track_count = 0;

  // Feature detection at the detect level: border kept clear, grid cells of the area within.
  int margin = 0;
  std::vector<int> cell_of_row;
  std::vector<int> cell_start;      // first column of each grid column, and one past the last
  std::vector<int> grid_row_start;  // first row of each grid row, and one past the last
  std::vector<motion_detail::CornerScratch> corner_scratch;  // per part
  std::vector<float> cell_score;
  std::vector<int> cell_u, cell_v;
  std::vector<std::uint8_t> cell_on_laser;  // the laser filter's verdict on the cell's corner

  // The work split in parts (pipeline/parts.hpp): each part's rows of level 1 (a multiple of
  // pyramid_alignment), features tracked and grid rows searched.
  int parts = 1;
  int pyramid_alignment = 1;
  std::vector<motion_detail::TrackResult> feature_tracks, follow_tracks;

  // RANSAC, per tracked pair: full-size coordinates as double, indices of the converged tracks.
  std::vector<double> px, py, cx, cy;
  std::vector<int> all_index;  // 0..n-1 in some order (RANSAC shuffles it to draw samples)
  std::vector<int> inlier_index;
  std::vector<std::uint8_t> is_inlier;
  std::vector<std::uint8_t> best_inlier;

  // Camera motion (with a geometry only): the camera estimator's points to follow from the
  // previous frame, the whole pixels they are tracked from, their full-size patches (empty where
  // the patch does not fit), and where they were found in the current frame (NaN: lost).
  bool has_camera = false;
  std::vector<Point> follow_from;
  std::vector<Point> follow_pixel;
  std::vector<std::uint8_t> follow_has_patch;
  std::vector<std::uint8_t> follow_patches;
  int follow_count = 0;
  std::vector<std::array<float, 2>> followed;
};

}  // namespace laserline::pipeline
