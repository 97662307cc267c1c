#include "tools/line_width.hpp"

#include <algorithm>
#include <cmath>

#include "pipeline/search_axes.hpp"
#include "tools/laser_line_removal.hpp"

namespace laserline::tools {

LineWidthMeter::LineWidthMeter(const pipeline::ScannerGeometry& geometry, int saturation_level)
    : geometry_(geometry), saturation_level_(saturation_level) {}

void LineWidthMeter::add(const cv::Mat& frame, const pipeline::Profile& profile) {
  const pipeline::SearchAxes& axes = profile.axes();
  // The width model in search coordinates, as the detectors have it.
  const pipeline::ScannerGeometry search = pipeline::search_geometry(geometry_, axes);
  const cv::Point2d along(axes.along[0], axes.along[1]);
  for (const pipeline::ProfilePoint& p : profile.points()) {
    if (!p.valid) continue;
    const double predicted =
        search.fy * search.sheet_width_m * search.inverse_depth(p.u, static_cast<double>(p.v));
    if (!(predicted > 0.0) || !std::isfinite(predicted)) continue;
    const auto [x, y] = axes.to_image(p.u, p.v);
    // A detector sized for another width may place its point off the line's centre: the peak is
    // looked for within half the predicted width.
    const double width =
        full_width_at_half_maximum(frame, {x, y}, along, static_cast<double>(saturation_level_),
                                   std::max(1.0, 0.5 * predicted));
    if (std::isfinite(width)) ratios_.push_back(width / predicted);
  }
}

double LineWidthMeter::ratio() const {
  if (ratios_.empty()) return 0.0;
  const auto middle = ratios_.begin() + static_cast<std::ptrdiff_t>(ratios_.size() / 2);
  std::nth_element(ratios_.begin(), middle, ratios_.end());
  return *middle;
}

}  // namespace laserline::tools
