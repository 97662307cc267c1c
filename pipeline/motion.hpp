#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "pipeline/geometry.hpp"
#include "pipeline/image_view.hpp"

namespace laserline::pipeline {

// Bounds and tolerances of the frame-to-frame motion estimate. Every bound caps the work per frame,
// so the worst case is known (DESIGN.md: bounded keypoints and RANSAC iterations).
struct MotionOptions {
  int grid_columns = 16;  // features are picked one per grid cell: at most columns * rows
  int grid_rows = 12;
  int detect_level = 2;     // pyramid level (0 = full size, 1 = half, ...) features are found at
  int pyramid_levels = 4;   // levels the tracker descends through (coarsest = levels - 1)
  int window_radius = 4;    // tracking window (2r+1)^2 at every level
  int max_iterations = 10;  // tracking iterations per level
  int ransac_iterations = 200;
  double inlier_px = 1.0;  // RANSAC inlier distance, full-size pixels
  int min_inliers = 12;    // fewer inliers: no estimate
  // Paper IV-A: a feature whose neighbourhood responds much more strongly across the laser line
  // (d/dv, the line runs along rows) than along it (d/du) may sit on the line; it is kept out.
  double laser_filter_ratio = 3.0;
  // Camera motion (essential matrix), only when reset() was given the intrinsics: five-point
  // RANSAC over the same tracks, at most this many samples (each gives up to 10 hypotheses).
  int essential_ransac_iterations = 100;
  double essential_inlier_px = 1.0;  // Sampson distance of an inlier, full-size pixels
  // Camera rotation alone (or too little translation) leaves the translation undetermined: the
  // median image motion the rotation does not explain must be at least this (full-size pixels).
  double essential_min_parallax_px = 1.0;
  // Inlier tracks of a pair followed on into the next frame, for CameraMotion::relative_scale
  // (0: no relative scale). Each costs one more tracked feature per frame.
  int scale_tracks = 64;
};

// The camera's motion between consecutive frames: X_current = R * X_previous + t, camera
// coordinates (x right, y down, z forward), t of unit length (a single camera knows no scale).
struct CameraMotion {
  bool valid = false;
  std::array<double, 9> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};  // row-major R
  std::array<double, 3> translation{};                        // t, |t| = 1 when valid
  int inliers = 0;
  // |t of this frame pair| / |t of the previous pair|, from features tracked over the three
  // frames (triangulated with both pairs); NaN when unknown.
  double relative_scale = std::numeric_limits<double>::quiet_NaN();
};

// A planar projective transformation of pixel coordinates: p_current ~ H p_previous.
struct Homography {
  std::array<double, 9> h{1, 0, 0, 0, 1, 0, 0, 0, 1};  // row-major

  std::array<double, 2> map(double u, double v) const {
    const double w = h[6] * u + h[7] * v + h[8];
    return {(h[0] * u + h[1] * v + h[2]) / w, (h[3] * u + h[4] * v + h[5]) / w};
  }
  // p_previous ~ inverse() p_current, scaled so that h[8] = 1 where possible; all zero if singular.
  Homography inverse() const;
};

// A feature of the previous frame and where it was found in the current one.
struct FeatureTrack {
  float previous_u = 0, previous_v = 0;
  float u = 0, v = 0;
  bool inlier = false;
};

struct MotionEstimate {
  bool valid = false;
  Homography previous_to_current;
  int detected = 0;           // features found in the previous frame
  int rejected_on_laser = 0;  // of those, kept out by the laser filter
  int tracked = 0;            // tracks that converged
  int inliers = 0;
  float rms_px = 0;     // RMS transfer error of the inliers, full-size pixels
  CameraMotion camera;  // invalid unless reset() was given the intrinsics
};

// Estimates the homography between consecutive frames from tracked image features (paper III-A):
// features picked on a grid at a reduced resolution, laser-like features filtered out (IV-A),
// tracked into the next frame coarse-to-fine, homography by bounded RANSAC and a least-squares
// refit on the inliers. With the camera's intrinsics and distortion (reset() with a geometry) it
// also estimates the camera motion from the same tracks: undistorted, normalised coordinates,
// five-point essential matrix by bounded RANSAC, cheirality to pick R and t, and the scale of t
// relative to the previous pair from tracks followed over three frames.
// reset() allocates; update() does not.
// Thread context: one thread at a time per instance.
class MotionEstimator {
 public:
  explicit MotionEstimator(const MotionOptions& options = {});
  ~MotionEstimator();
  MotionEstimator(const MotionEstimator&) = delete;
  MotionEstimator& operator=(const MotionEstimator&) = delete;

  const MotionOptions& options() const { return options_; }
  // `geometry` (copied; may be null: homography only) gives the intrinsics and distortion for the
  // camera motion; its size must be width x height.
  void reset(int width, int height, const ScannerGeometry* geometry = nullptr);
  // Takes frame n (it is not kept: what is needed is copied into the pyramid) and estimates the
  // motion from the frame given before. Invalid after reset() and when too few inliers remain.
  MotionEstimate update(const ImageView& frame);
  // The tracks of the last update(), for overlays and tests.
  std::span<const FeatureTrack> tracks() const;
  // Features of the previous frame the laser filter kept out in the last update().
  std::span<const std::array<float, 2>> rejected_features() const;

 private:
  struct State;
  // Finds the features of `frame`, whose pyramid is `index` (and the ones the laser filter
  // rejects), and keeps the full-size patches around them.
  void detect_features(int index, const ImageView& frame);
  // Tracks the previous frame's features into `frame` (pyramid `current`), fits the homography.
  MotionEstimate estimate_from_previous(int current, const ImageView& frame);
  // RANSAC and least-squares refit over the first n tracked pairs; false when nothing fits.
  bool fit_homography(int n, Homography& result, int& inlier_count);
  // Five-point RANSAC over the first n tracked pairs (undistorted, normalised), cheirality, refit,
  // and the scale relative to the previous pair.
  CameraMotion estimate_camera_motion(int n);

  MotionOptions options_;
  State* state_ = nullptr;
};

}  // namespace laserline::pipeline
