// A planar projective transformation of pixel coordinates, the motion stage's model of the image
// motion between consecutive frames (fitted in homography.cpp).
#pragma once

#include <Eigen/Core>
#include <array>

namespace laserline::pipeline {

// A planar projective transformation of pixel coordinates: p_current ~ H p_previous.
struct Homography {
  // Row-major: h.data() is the nine coefficients row by row, as the kernels take them. Not a
  // vectorisable size: no alignment requirement where it is held.
  using Matrix = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  Matrix h = Matrix::Identity();

  std::array<double, 2> map(double u, double v) const {
    const double w = h(2, 0) * u + h(2, 1) * v + h(2, 2);
    return {(h(0, 0) * u + h(0, 1) * v + h(0, 2)) / w, (h(1, 0) * u + h(1, 1) * v + h(1, 2)) / w};
  }
  // p_previous ~ inverse() p_current, scaled so that h(2, 2) = 1 where possible; all zero if
  // singular.
  Homography inverse() const;
  // The map p -> this(first(p)), scaled likewise.
  Homography after(const Homography& first) const;
};

}  // namespace laserline::pipeline
