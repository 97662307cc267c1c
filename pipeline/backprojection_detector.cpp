#include "pipeline/backprojection_detector.hpp"

namespace laserline::pipeline {

BackprojectionDetector::BackprojectionDetector(const DetectorOptions& options)
    : background_(options, /*estimate_camera_motion=*/true),
      validator_(options.geometry, options.validation) {}

std::size_t BackprojectionDetector::max_points(int width, int height) const {
  return background_.max_points(width, height);
}

void BackprojectionDetector::reset(int width, int height) {
  background_.reset(width, height);
  validator_.reset(width, height, background_.max_points(width, height));
}

void BackprojectionDetector::detect(const ImageView& image, const FrameContext& frame,
                                    Profile& out) {
  // The candidates; the validation takes away those of the static scene (and noise); the line
  // is chosen among the rest.
  background_.collect_candidates(image, frame, out);
  const MotionEstimate& estimate = background_.last_motion();
  PairMotion motion;
  motion.valid = estimate.valid && estimate.camera.valid;
  motion.rotation = estimate.camera.rotation;
  motion.translation = estimate.camera.translation;
  motion.relative_scale = estimate.camera.relative_scale;
  validator_.validate(out, motion, image, estimate.valid ? &estimate.previous_to_current : nullptr);
  if (frame.laser_on) background_.select_line(image, out);
}

}  // namespace laserline::pipeline
