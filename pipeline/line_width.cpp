#include "pipeline/line_width.hpp"

#include <algorithm>
#include <cmath>

namespace laserline::pipeline {

namespace {

// A line must rise this many grey levels above the median of its window to be measured: below,
// sensor noise moves the half-maximum crossings by a good part of the width.
constexpr float kMinimumHeight = 6.0f;

// Sampling by pixels and a lens's blur widen any line, by about 1.5 px in quadrature (a Gaussian
// blur of sigma 0.6 px and a pixel's box): not a width the sheet's thickness accounts for.
constexpr double kBlurPx = 1.5;

// Bilinear sample of `frame` at pixel (x, y) (centres at integers); false outside the frame.
bool sample(const ImageView& frame, double x, double y, float& value) {
  if (!(x >= 0.0 && y >= 0.0 && x <= frame.width - 1 && y <= frame.height - 1)) return false;
  const int x0 = std::min(static_cast<int>(x), frame.width - 1);
  const int y0 = std::min(static_cast<int>(y), frame.height - 1);
  const int x1 = std::min(x0 + 1, frame.width - 1), y1 = std::min(y0 + 1, frame.height - 1);
  const double fx = x - x0, fy = y - y0;
  const auto at = [&](int xi, int yi) {
    return static_cast<double>(frame.data[static_cast<std::size_t>(yi) * frame.stride + xi]);
  };
  value = static_cast<float>((1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x1, y0)) +
                             fy * ((1 - fx) * at(x0, y1) + fx * at(x1, y1)));
  return true;
}

}  // namespace

LineWidthMeter::LineWidthMeter(const ScannerGeometry& geometry) : geometry_(geometry) {}

void LineWidthMeter::add(const ImageView& frame, const Profile& profile) {
  const SearchAxes& axes = profile.axes();
  const ScannerGeometry search = search_geometry(geometry_, axes);
  std::vector<float> sorted;
  for (const ProfilePoint& p : profile.points()) {
    if (!p.valid) continue;
    const double predicted =
        search.fy * search.sheet_width_m * search.inverse_depth(p.u, static_cast<double>(p.v));
    if (!(predicted > 0.0) || !std::isfinite(predicted)) continue;
    // Wide enough for a line several times the predicted width and its surroundings.
    const int reach = std::clamp(static_cast<int>(std::ceil(6.0 * predicted)), 8, 64);
    const int centre = static_cast<int>(std::lround(p.v));
    samples_.resize(static_cast<std::size_t>(2 * reach + 1));
    bool inside = true;
    for (int t = -reach; t <= reach && inside; ++t) {
      const auto [x, y] = axes.to_image(p.u, centre + t);
      inside = sample(frame, x, y, samples_[static_cast<std::size_t>(t + reach)]);
    }
    if (!inside) continue;
    const auto at = [&](int t) { return samples_[static_cast<std::size_t>(t + reach)]; };
    // The peak near the point, the surroundings' level the window's median (the line covers
    // less than half of the window).
    const int near = std::max(2, static_cast<int>(std::ceil(predicted)));
    int top = 0;
    for (int t = -near; t <= near; ++t) {
      if (at(t) > at(top)) top = t;
    }
    sorted.assign(samples_.begin(), samples_.end());
    std::nth_element(sorted.begin(), sorted.begin() + reach, sorted.end());
    const float base = sorted[static_cast<std::size_t>(reach)];
    const float height = at(top) - base;
    if (height < kMinimumHeight) continue;
    const float half = base + 0.5f * height;
    // The half-maximum crossings on both sides, interpolated between the samples around them.
    int left = top;
    while (left > -reach && at(left) > half)
      --left;
    int right = top;
    while (right < reach && at(right) > half)
      ++right;
    if (at(left) > half || at(right) > half) continue;  // no fall within the window
    const double left_crossing = left + (half - at(left)) / (at(left + 1) - at(left));
    const double right_crossing = right - (half - at(right)) / (at(right - 1) - at(right));
    const double full_width = right_crossing - left_crossing;
    const double sheet_width = std::sqrt(
        std::max(full_width * full_width - kBlurPx * kBlurPx, 0.25 * full_width * full_width));
    ratios_.push_back(sheet_width / predicted);
  }
}

double LineWidthMeter::ratio() const {
  if (ratios_.empty()) return 0.0;
  const auto middle = ratios_.begin() + static_cast<std::ptrdiff_t>(ratios_.size() / 2);
  std::nth_element(ratios_.begin(), middle, ratios_.end());
  return *middle;
}

}  // namespace laserline::pipeline
