// A planar projective transformation of pixel coordinates, the motion stage's model of the image
// motion between consecutive frames (fitted in homography.cpp).
#pragma once

#include <array>

namespace laserline::pipeline {

// A planar projective transformation of pixel coordinates: p_current ~ H p_previous.
struct Homography {
  std::array<double, 9> h{1, 0, 0, 0, 1, 0, 0, 0, 1};  // row-major

  std::array<double, 2> map(double u, double v) const {
    const double w = h[6] * u + h[7] * v + h[8];
    return {(h[0] * u + h[1] * v + h[2]) / w, (h[3] * u + h[4] * v + h[5]) / w};
  }
  // p_previous ~ inverse() p_current, scaled so that h[8] = 1 where possible; all zero if singular.
  Homography inverse() const;
  // The map p -> this(first(p)), scaled likewise.
  Homography after(const Homography& first) const;
};

}  // namespace laserline::pipeline
