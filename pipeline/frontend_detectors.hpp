#pragma once

#include <cstdint>
#include <vector>

#include "pipeline/detector.hpp"
#include "pipeline/frontend.hpp"
#include "pipeline/motion.hpp"

namespace laserline::pipeline {

// The paper's "FIR" detector: width normalisation, band-pass, SNR, thresholding and peaks on the
// frame itself (no background subtraction). Robust to backscatter; texture lit by ambient light
// gives false candidates.
class FirDetector final : public Detector {
 public:
  explicit FirDetector(const DetectorOptions& options);
  const char* name() const override { return "fir"; }
  std::size_t max_points(int width, int height) const override;
  void reset(int width, int height) override;
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override;

  const Frontend& frontend() const { return frontend_; }

 private:
  Frontend frontend_;
};

// The paper's "Background" detector: the previous frame, warped onto this one by the homography
// estimated from tracked features (III-A), is subtracted before the FIR stages. With the laser
// alternating, the previous frame is the laser-off one: the classic on/off subtraction, motion
// compensated. Laser-off frames and frames without a motion estimate (the first one) give no
// points. Keeps a copy of the previous frame (of the rows the warp can reach).
class BackgroundDetector final : public Detector {
 public:
  // estimate_camera_motion: the motion estimate also gives the camera's rotation and translation
  // (the essential matrix, from the geometry's intrinsics), for the validation of Section IV.
  explicit BackgroundDetector(const DetectorOptions& options, bool estimate_camera_motion = false);
  const char* name() const override { return "background"; }
  std::size_t max_points(int width, int height) const override;
  void reset(int width, int height) override;
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override;

  const Frontend& frontend() const { return frontend_; }
  const MotionEstimator& motion() const { return motion_; }
  const MotionEstimate& last_motion() const { return last_motion_; }

 private:
  Frontend frontend_;
  ScannerGeometry geometry_;
  bool estimate_camera_motion_ = false;
  MotionEstimator motion_;
  MotionEstimate last_motion_;
  std::vector<std::uint8_t> background_;  // the previous frame's rows the warp can reach, packed
  int band_first_ = 0, band_rows_ = 0;    // which rows those are
  bool have_background_ = false;
  int width_ = 0, height_ = 0;
};

}  // namespace laserline::pipeline
