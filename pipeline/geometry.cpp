#include "pipeline/geometry.hpp"

namespace laserline::pipeline {

namespace {

// Newton on the distortion model converges quadratically; a handful of steps reach the
// tolerance anywhere the model is invertible, the cap bounds the work where it is not.
constexpr int kMaxNewtonSteps = 20;
constexpr double kConverged = 1e-13;   // residual in normalised coordinates (~1e-10 px)
constexpr double kAcceptable = 1e-10;  // worse than this after the cap: not invertible here

}  // namespace

bool ScannerGeometry::normalised(double u, double v, double& x, double& y) const {
  const double xd = (u - cx) / fx;
  const double yd = (v - cy) / fy;
  x = xd;
  y = yd;
  if (!has_distortion()) return true;
  const auto& [k1, k2, p1, p2, k3] = distortion;
  // Solve distort(x, y) = (xd, yd) by Newton's method, starting at the distorted point. OpenCV's
  // undistortPoints uses a fixed-point iteration instead, which converges slowly (or not) where
  // the distortion is strong.
  for (int step = 0; step <= kMaxNewtonSteps; ++step) {
    const double x2 = x * x, y2 = y * y, xy = x * y;
    const double r2 = x2 + y2;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double ex = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2) - xd;
    const double ey = y * radial + p1 * (r2 + 2.0 * y2) + 2.0 * p2 * xy - yd;
    // d(radial)/d(r2), then the Jacobian of the distortion.
    const double slope = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
    const double jxx = radial + 2.0 * slope * x2 + 2.0 * p1 * y + 6.0 * p2 * x;
    const double jxy = 2.0 * slope * xy + 2.0 * p1 * x + 2.0 * p2 * y;
    const double jyy = radial + 2.0 * slope * y2 + 6.0 * p1 * y + 2.0 * p2 * x;
    const double det = jxx * jyy - jxy * jxy;
    // A root where the model folds over (det <= 0) is not the pixel's ray: the lens maps the
    // field one-to-one only up to the fold.
    if (!(det > 0.0) || !std::isfinite(det)) return false;
    const double residual2 = ex * ex + ey * ey;
    if (residual2 < kConverged * kConverged) return true;
    if (step == kMaxNewtonSteps) return residual2 < kAcceptable * kAcceptable;
    const double inverse_det = 1.0 / det;
    x -= (jyy * ex - jxy * ey) * inverse_det;
    y -= (jxx * ey - jxy * ex) * inverse_det;
  }
  return false;
}

std::array<double, 2> ScannerGeometry::pixel(double x, double y) const {
  const auto& [k1, k2, p1, p2, k3] = distortion;
  const double x2 = x * x, y2 = y * y, xy = x * y;
  const double r2 = x2 + y2;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const double xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2);
  const double yd = y * radial + p1 * (r2 + 2.0 * y2) + 2.0 * p2 * xy;
  return {fx * xd + cx, fy * yd + cy};
}

}  // namespace laserline::pipeline
