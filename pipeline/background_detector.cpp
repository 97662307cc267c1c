#include <algorithm>
#include <cmath>
#include <cstring>

#include "pipeline/frontend_detectors.hpp"

namespace laserline::pipeline {

BackgroundDetector::BackgroundDetector(const DetectorOptions& options, bool estimate_camera_motion)
    : frontend_(options.geometry, options.frontend),
      geometry_(options.geometry),
      estimate_camera_motion_(estimate_camera_motion),
      motion_(options.motion) {}

std::size_t BackgroundDetector::max_points(int width, int /*height*/) const {
  return frontend_.max_points(width);
}

void BackgroundDetector::reset(int width, int height) {
  frontend_.reset(width, height);
  motion_.reset(width, height, estimate_camera_motion_ ? &geometry_ : nullptr);
  // Only the rows the warp can reach are kept: those of the depth range, plus what the scene can
  // move between two frames (an eighth of the image: 3 degrees per frame at f = 2240 px).
  const RowNormalisation& rows = frontend_.rows();
  const float lo = std::min(rows.source_row(0), rows.source_row(rows.rows() - 1));
  const float hi = std::max(rows.source_row(0), rows.source_row(rows.rows() - 1));
  const int margin = std::max(64, height / 8);
  band_first_ = std::max(static_cast<int>(std::floor(lo)) - margin, 0);
  band_rows_ = std::min(static_cast<int>(std::ceil(hi)) + margin, height - 1) - band_first_ + 1;
  background_.assign(static_cast<std::size_t>(width) * band_rows_, 0);
  have_background_ = false;
  width_ = width;
  height_ = height;
}

void BackgroundDetector::detect(const ImageView& image, const FrameContext& frame, Profile& out) {
  out.clear();
  last_motion_ = motion_.update(image);
  if (frame.laser_on && have_background_ && last_motion_.valid) {
    const ImageView background{background_.data(), width_, band_rows_, width_};
    // Current pixel -> previous frame -> row within the kept band.
    Homography to_band = last_motion_.previous_to_current.inverse();
    for (int i = 0; i < 3; ++i)
      to_band.h[3 + i] -= band_first_ * to_band.h[6 + i];
    frontend_.set_frame_minus_background(image, background, to_band);
    frontend_.find_candidates(out);
  }
  // This frame is the background of the next one.
  for (int v = 0; v < band_rows_; ++v) {
    std::memcpy(background_.data() + static_cast<std::size_t>(v) * width_,
                image.row(band_first_ + v), static_cast<std::size_t>(width_));
  }
  have_background_ = true;
}

}  // namespace laserline::pipeline
