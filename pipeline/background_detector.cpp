#include <cstring>

#include "pipeline/frontend_detectors.hpp"

namespace laserline::pipeline {

BackgroundDetector::BackgroundDetector(const DetectorOptions& options)
    : frontend_(options.geometry, options.frontend), motion_(options.motion) {}

std::size_t BackgroundDetector::max_points(int width, int /*height*/) const {
  return static_cast<std::size_t>(width) * frontend_.options().max_candidates_per_column;
}

void BackgroundDetector::reset(int width, int height) {
  frontend_.reset(width, height);
  motion_.reset(width, height);
  background_.assign(static_cast<std::size_t>(width) * height, 0);
  have_background_ = false;
  width_ = width;
  height_ = height;
}

void BackgroundDetector::detect(const ImageView& image, const FrameContext& frame, Profile& out) {
  out.clear();
  last_motion_ = motion_.update(image);
  if (frame.laser_on && have_background_ && last_motion_.valid) {
    const ImageView background{background_.data(), width_, height_, width_};
    frontend_.normalise_subtracting(image, background, last_motion_.previous_to_current.inverse());
    frontend_.band_pass();
    frontend_.find_candidates(out);
  }
  // This frame is the background of the next one.
  for (int v = 0; v < height_; ++v) {
    std::memcpy(background_.data() + static_cast<std::size_t>(v) * width_, image.row(v),
                static_cast<std::size_t>(width_));
  }
  have_background_ = true;
}

}  // namespace laserline::pipeline
