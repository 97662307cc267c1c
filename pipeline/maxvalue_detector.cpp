#include "pipeline/maxvalue_detector.hpp"

#include <algorithm>
#include <cmath>

#include "pipeline/options.hpp"
#include "pipeline/subpixel.hpp"

namespace laserline::pipeline {

MaxValueDetector::MaxValueDetector(int threshold) : threshold_(threshold) {
  validate_maxvalue_threshold(threshold);
  for (int i = 0; i < 256; ++i)
    log_lut_[i] = std::log(static_cast<float>(std::max(i, 1)));
}

void MaxValueDetector::reset(int width, int height) {
  (void)height;
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
  std::fill(max_value_.begin(), max_value_.end(), 0);
  std::fill(first_row_.begin(), first_row_.end(), 0);
  std::fill(last_row_.begin(), last_row_.end(), 0);
  std::fill(sum_.begin(), sum_.end(), 0);

  std::uint8_t* max_value = max_value_.data();
  std::uint16_t* first_row = first_row_.data();
  std::uint16_t* last_row = last_row_.data();
  std::uint32_t* sum = sum_.data();
  for (int v = 0; v < image.height; ++v) {
    const std::uint8_t* p = image.row(v);
    const auto row = static_cast<std::uint16_t>(v);
    // Branch-free so that the compiler vectorises across columns.
    for (int u = 0; u < width; ++u) {
      const std::uint8_t x = p[u];
      const bool greater = x > max_value[u];
      const bool not_less = x >= max_value[u];
      sum[u] += x;
      max_value[u] = greater ? x : max_value[u];
      first_row[u] = greater ? row : first_row[u];
      last_row[u] = not_less ? row : last_row[u];
    }
  }

  const float inv_height = 1.0f / static_cast<float>(image.height);
  for (int u = 0; u < width; ++u) {
    const int peak = max_value[u];
    if (peak < threshold_ || peak == 0) continue;
    const int first = first_row[u];
    const int last = last_row[u];
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
