#include "pipeline/maxvalue_detector.hpp"

#include <algorithm>
#include <cmath>

#include "pipeline/kernels/kernels.hpp"
#include "pipeline/options.hpp"
#include "pipeline/subpixel.hpp"

namespace laserline::pipeline {

MaxValueDetector::MaxValueDetector(int threshold) : threshold_(threshold) {
  validate_maxvalue_threshold(threshold);
  for (int i = 0; i < 256; ++i)
    log_lut_[i] = std::log(static_cast<float>(std::max(i, 1)));
}

void MaxValueDetector::reset(int width, int height) {
  width_ = width;
  height_ = height;
  max_value_.assign(width, 0);
  first_row_.assign(width, 0);
  last_row_.assign(width, 0);
  sum_.assign(width, 0);
}

void MaxValueDetector::detect(const ImageView& image, const FrameContext& frame, Profile& out) {
  out.clear();
  const int width = image.width;
  if (!frame.laser_on || static_cast<int>(max_value_.size()) != width || image.height > 65535)
    return;
  const DetectionRegion region = region_.in_frame(width, image.height);
  if (region.width == 0 || region.height == 0) return;
  // The region's rows from its top: first_row_ and last_row_ count from there.
  kernels::column_maxima(image.row(region.y), image.stride, region.x, region.x + region.width,
                         region.height, max_value_.data(), first_row_.data(), last_row_.data(),
                         sum_.data());
  const std::uint8_t* max_value = max_value_.data();
  const std::uint16_t* first_row = first_row_.data();
  const std::uint16_t* last_row = last_row_.data();
  const std::uint32_t* sum = sum_.data();

  const float inv_height = 1.0f / static_cast<float>(region.height);
  for (int u = region.x; u < region.x + region.width; ++u) {
    const int peak = max_value[u];
    if (peak < threshold_ || peak == 0) continue;
    const int first = region.y + first_row[u];
    const int last = region.y + last_row[u];
    float v = static_cast<float>(first);
    bool plateau = last > first;
    for (int r = first + 1; plateau && r < last; ++r)
      plateau = image.at(u, r) == peak;
    if (plateau) {
      // A clipped core: the centre of the saturated run.
      v = 0.5f * static_cast<float>(first + last);
    } else if (first > 0 && first + 1 < image.height) {
      v += gaussian_offset_from_logs(log_lut_[image.at(u, first - 1)], log_lut_[peak],
                                     log_lut_[image.at(u, first + 1)]);
    }
    const float mean = std::max(static_cast<float>(sum[u]) * inv_height, 1.0f);
    ProfilePoint point;
    point.u = u;
    point.v = v;
    point.snr_db = 20.0f * std::log10(static_cast<float>(peak) / mean);
    if (!out.add(point)) break;
  }
}

}  // namespace laserline::pipeline
