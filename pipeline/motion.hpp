// The motion stage's interface (paper III-A): frame-to-frame homography from tracked features and,
// with the camera's intrinsics, the camera's own motion. Implemented along its steps in
// motion.cpp, features.cpp, tracking.cpp, homography.cpp, camera_motion.cpp and five_point.cpp.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "pipeline/five_point.hpp"
#include "pipeline/geometry.hpp"
#include "pipeline/homography.hpp"
#include "pipeline/image_view.hpp"
#include "pipeline/parts.hpp"

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

  // What the tracker's fixed-size buffers hold.
  static constexpr int kMaxPyramidLevels = 8;
  static constexpr int kMaxWindowRadius = 15;

  // Throws OptionError (pipeline/options.hpp) naming the first field outside what the pipeline
  // supports.
  void validate() const;
};

// The camera's motion between consecutive frames: X_current = R * X_previous + t, camera
// coordinates (x right, y down, z forward), t of unit length (a single camera knows no scale).
struct CameraMotion {
  bool valid = false;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // R
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();   // t, |t| = 1 when valid
  int inliers = 0;
  // |t of this frame pair| / |t of the previous pair|, from features tracked over the three
  // frames (triangulated with both pairs); NaN when unknown.
  double relative_scale = std::numeric_limits<double>::quiet_NaN();
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

// Camera motion between consecutive frames from point correspondences in pixels (as seen, with
// the lens distortion of the geometry): undistorted and normalised, five-point RANSAC with
// a capped number of samples, Sampson error in pixels for the inliers, cheirality to pick R and t
// among the four decompositions, a linear (eight-point) refit on the inliers kept when it fits
// better. For relative_scale it asks for a subset of this pair's inliers to be followed into the
// next frame (to_follow()), keeping their depth; with where they were found there, their depth
// from the next pair gives the ratio of the two translations (median).
// reset() allocates; estimate() does not. Thread context: one thread at a time per instance.
class CameraMotionEstimator {
 public:
  explicit CameraMotionEstimator(const MotionOptions& options = {});

  // Capacity: at most max_tracks correspondences per estimate().
  void reset(const ScannerGeometry& geometry, int max_tracks);
  // Forgets the previous pair (no relative scale for the next estimate()).
  void forget();
  // `tracks`: previous -> current pixel positions (FeatureTrack::inlier is ignored).
  // `followed`: where the points to_follow() gave after the previous estimate() were found in
  // the current frame, in the same order; NaN where lost, empty when not followed.
  CameraMotion estimate(std::span<const FeatureTrack> tracks,
                        std::span<const std::array<float, 2>> followed);
  // Per track of the last estimate(): 1 if an inlier of the camera motion.
  std::span<const std::uint8_t> inliers() const { return {inlier_.data(), track_count_}; }
  // Points of the current frame (pixels) to find in the next one, for its relative_scale.
  std::span<const std::array<float, 2>> to_follow() const {
    return {follow_.data(), follow_count_};
  }

 private:
  // Undistorted normalised coordinates of pixel (u, v).
  std::array<double, 2> normalise(double u, double v) const;

  MotionOptions options_;
  ScannerGeometry geometry_;
  double focal_ = 1;
  std::size_t track_count_ = 0;
  // Per correspondence: normalised coordinates, RANSAC order and inlier flags, residuals.
  std::vector<double> x1_, y1_, x2_, y2_;
  std::vector<int> order_;
  std::vector<std::uint8_t> inlier_, candidate_;
  std::vector<double> residual_;
  // Points to follow into the next frame and their depth in this frame (units of |t|).
  std::vector<std::array<float, 2>> follow_;
  std::vector<double> follow_depth_;
  std::size_t follow_count_ = 0;
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
  // Splits the pyramid, the tracking and the feature detection of each frame into runner.parts()
  // parts; before reset(), which sizes each part's buffers. Default: one part.
  void use_parts(PartRunner& runner) { runner_ = &runner; }
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
  // work(part) for each part: by the runner, or one after another when it does not run the parts
  // reset() sized for.
  template <class Work>
  void run_parts(Work& work);
  // Part `part` of the corners of pyramid `index` (the strongest per grid cell of its grid rows)
  // and the laser filter's verdict on them.
  void find_corners(int index, const ImageView& frame, int part);
  // Part `part` of the tracks of the previous frame's features (and of the points followed) into
  // pyramid `current`.
  void track_part(int current, const ImageView& frame, int part);
  // The features of `frame`, whose pyramid is `index`, from find_corners() (and the ones the
  // laser filter rejects), and the full-size patches around them.
  void detect_features(int index, const ImageView& frame);
  // The homography (and camera motion) from the tracks track_part() found.
  MotionEstimate estimate_from_previous();
  // RANSAC and least-squares refit over the first n tracked pairs; false when nothing fits.
  bool fit_homography(int n, Homography& result, int& inlier_count);
  // Where the camera estimator's points (to_follow()) of the previous frame were found in the
  // current one (track_part() tracked them), into State::followed; returns how many there are.
  int follow_points();
  // Keeps the full-size patches around the camera estimator's new points to follow.
  void keep_follow_patches(const ImageView& frame);

  MotionOptions options_;
  PartRunner* runner_ = &one_part();
  State* state_ = nullptr;
  CameraMotionEstimator camera_;
};

}  // namespace laserline::pipeline
