#pragma once

#include <algorithm>
#include <cmath>

namespace laserline::pipeline {

// Sub-pixel offset of a peak from the three samples around it (a = before, b = peak, c = after),
// assuming a Gaussian profile: the vertex of the parabola through their logarithms. Exact for a
// sampled Gaussian. Returns an offset in [-0.5, 0.5]; 0 when the samples are not a peak.
inline float gaussian_offset_from_logs(float la, float lb, float lc) {
  const float curvature = la - 2.0f * lb + lc;
  if (!(curvature < 0.0f)) return 0.0f;
  return std::clamp(0.5f * (la - lc) / curvature, -0.5f, 0.5f);
}

inline float gaussian_offset(float a, float b, float c) {
  // Values below 1 carry no usable shape and would make the logarithm explode.
  a = std::max(a, 1.0f);
  b = std::max(b, 1.0f);
  c = std::max(c, 1.0f);
  // ln a - ln c and ln a - 2 ln b + ln c as the logarithms of two ratios: one call fewer (this
  // runs once per column and frame).
  const float curvature = std::log(a * c / (b * b));
  if (!(curvature < 0.0f)) return 0.0f;
  return std::clamp(0.5f * std::log(a / c) / curvature, -0.5f, 0.5f);
}

}  // namespace laserline::pipeline
