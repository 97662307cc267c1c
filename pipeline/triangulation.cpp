#include "pipeline/triangulation.hpp"

#include <cmath>
#include <limits>
#include <utility>

namespace laserline::pipeline {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
// Newton on the distortion model converges quadratically; a handful of steps reach the
// tolerance anywhere the model is invertible, the cap bounds the work where it is not.
constexpr int kMaxNewtonSteps = 20;
constexpr double kConverged = 1e-13;   // residual in normalised coordinates (~1e-10 px)
constexpr double kAcceptable = 1e-10;  // worse than this after the cap: not invertible here

}  // namespace

Triangulator::Triangulator(const ScannerGeometry& geometry)
    : fx_(geometry.fx),
      fy_(geometry.fy),
      cx_(geometry.cx),
      cy_(geometry.cy),
      k1_(geometry.distortion[0]),
      k2_(geometry.distortion[1]),
      p1_(geometry.distortion[2]),
      p2_(geometry.distortion[3]),
      k3_(geometry.distortion[4]),
      distorted_(k1_ != 0.0 || k2_ != 0.0 || p1_ != 0.0 || p2_ != 0.0 || k3_ != 0.0),
      plane_(geometry.laser_plane) {}

bool Triangulator::undistort(double u, double v, double& x, double& y) const {
  const double xd = (u - cx_) / fx_;
  const double yd = (v - cy_) / fy_;
  x = xd;
  y = yd;
  if (!distorted_) return true;
  // Solve distort(x, y) = (xd, yd) by Newton's method, starting at the distorted point. OpenCV's
  // undistortPoints uses a fixed-point iteration instead, which converges slowly (or not) where
  // the distortion is strong.
  for (int step = 0; step <= kMaxNewtonSteps; ++step) {
    const double x2 = x * x, y2 = y * y, xy = x * y;
    const double r2 = x2 + y2;
    const double radial = 1.0 + r2 * (k1_ + r2 * (k2_ + r2 * k3_));
    const double fx = x * radial + 2.0 * p1_ * xy + p2_ * (r2 + 2.0 * x2) - xd;
    const double fy = y * radial + p1_ * (r2 + 2.0 * y2) + 2.0 * p2_ * xy - yd;
    // d(radial)/d(r2), then the Jacobian of the distortion.
    const double slope = k1_ + r2 * (2.0 * k2_ + 3.0 * k3_ * r2);
    const double jxx = radial + 2.0 * slope * x2 + 2.0 * p1_ * y + 6.0 * p2_ * x;
    const double jxy = 2.0 * slope * xy + 2.0 * p1_ * x + 2.0 * p2_ * y;
    const double jyy = radial + 2.0 * slope * y2 + 6.0 * p1_ * y + 2.0 * p2_ * x;
    const double det = jxx * jyy - jxy * jxy;
    // A root where the model folds over (det <= 0) is not the pixel's ray: the lens maps the
    // field one-to-one only up to the fold.
    if (!(det > 0.0) || !std::isfinite(det)) return false;
    const double residual2 = fx * fx + fy * fy;
    if (residual2 < kConverged * kConverged) return true;
    if (step == kMaxNewtonSteps) return residual2 < kAcceptable * kAcceptable;
    const double inverse_det = 1.0 / det;
    x -= (jyy * fx - jxy * fy) * inverse_det;
    y -= (jxx * fy - jxy * fx) * inverse_det;
  }
  return false;
}

bool Triangulator::point(double u, double v, std::array<double, 3>& xyz) const {
  double x = 0, y = 0;
  if (!undistort(u, v, x, y)) return false;
  // The ray is Z * (x, y, 1): a*x*Z + b*y*Z + c*Z + e = 0.
  const auto& [a, b, c, e] = plane_;
  const double z = -e / (a * x + b * y + c);
  if (!(z > 0.0) || !std::isfinite(z)) return false;
  xyz = {x * z, y * z, z};
  return true;
}

void Triangulator::fill(Profile& profile) const {
  for (ProfilePoint& p : profile.mutable_points()) {
    std::array<double, 3> xyz{};
    if (p.valid && point(p.u, p.v, xyz)) {
      p.xyz = {static_cast<float>(xyz[0]), static_cast<float>(xyz[1]), static_cast<float>(xyz[2])};
    } else {
      p.xyz = {kNaN, kNaN, kNaN};
    }
  }
}

namespace {

// Any detector, its points triangulated after it has found them.
class TriangulatingDetector final : public Detector {
 public:
  TriangulatingDetector(std::unique_ptr<Detector> detector, const ScannerGeometry& geometry)
      : detector_(std::move(detector)), triangulator_(geometry) {}

  const char* name() const override { return detector_->name(); }
  std::size_t max_points(int width, int height) const override {
    return detector_->max_points(width, height);
  }
  void reset(int width, int height) override { detector_->reset(width, height); }
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override {
    detector_->detect(image, frame, out);
    triangulator_.fill(out);
  }

 private:
  std::unique_ptr<Detector> detector_;
  Triangulator triangulator_;
};

}  // namespace

std::unique_ptr<Detector> with_triangulation(std::unique_ptr<Detector> detector,
                                             const ScannerGeometry& geometry) {
  if (!detector) return nullptr;
  return std::make_unique<TriangulatingDetector>(std::move(detector), geometry);
}

}  // namespace laserline::pipeline
