#include "pipeline/triangulation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace laserline::pipeline {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

}  // namespace

Triangulator::Triangulator(const ScannerGeometry& geometry) : geometry_(geometry) {}

bool Triangulator::point(double u, double v, Eigen::Vector3d& xyz) const {
  double x = 0, y = 0;
  if (!geometry_.normalised(u, v, x, y)) return false;
  // The ray is Z * (x, y, 1): a*x*Z + b*y*Z + c*Z + e = 0.
  const Eigen::Vector4d& plane = geometry_.laser_plane;
  const double a = plane[0], b = plane[1], c = plane[2], e = plane[3];
  const double z = -e / (a * x + b * y + c);
  if (!(z > 0.0) || !std::isfinite(z)) return false;
  xyz = Eigen::Vector3d(x * z, y * z, z);
  return true;
}

void Triangulator::fill(Profile& profile) const {
  fill(profile, 0, profile.size());
}

void Triangulator::fill(Profile& profile, std::size_t first, std::size_t end) const {
  for (ProfilePoint& p : profile.mutable_points().subspan(first, end - first)) {
    Eigen::Vector3d xyz;
    const auto [x, y] = profile.image_point(p);
    if (p.valid && point(x, y, xyz)) {
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
  void reset(int width, int height) override {
    detector_->reset(width, height);
    parts_ = std::clamp(runner_->parts(), 1, kMaxParts);
  }
  void use_parts(PartRunner& runner) override {
    runner_ = &runner;
    detector_->use_parts(runner);
  }
  void set_region(const DetectionRegion& region) override { detector_->set_region(region); }
  DetectionRegion region() const override { return detector_->region(); }
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override {
    detector_->detect(image, frame, out);
    // The points in parts (each its own range).
    auto part = [&](int p) {
      const auto [first, end] = part_range(static_cast<int>(out.size()), p, parts_);
      triangulator_.fill(out, static_cast<std::size_t>(first), static_cast<std::size_t>(end));
    };
    if (parts_ > 1 && runner_->parts() == parts_) {
      runner_->run(PartWork(part));
    } else {
      triangulator_.fill(out);
    }
  }

 private:
  std::unique_ptr<Detector> detector_;
  Triangulator triangulator_;
  PartRunner* runner_ = &one_part();
  int parts_ = 1;
};

}  // namespace

std::unique_ptr<Detector> with_triangulation(std::unique_ptr<Detector> detector,
                                             const ScannerGeometry& geometry) {
  if (!detector) return nullptr;
  return std::make_unique<TriangulatingDetector>(std::move(detector), geometry);
}

}  // namespace laserline::pipeline
