#include "pipeline/frontend_detectors.hpp"

namespace laserline::pipeline {

FirDetector::FirDetector(const DetectorOptions& options)
    : frontend_(options.geometry, options.frontend) {}

std::size_t FirDetector::max_points(int width, int /*height*/) const {
  return frontend_.max_points(width);
}

void FirDetector::reset(int width, int height) {
  frontend_.reset(width, height);
}

void FirDetector::detect(const ImageView& image, const FrameContext& frame, Profile& out) {
  if (!frame.laser_on) {
    out.clear();
    return;
  }
  frontend_.set_frame(image);
  frontend_.find_candidates(out);
}

}  // namespace laserline::pipeline
