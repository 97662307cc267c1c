#pragma once

#include <Eigen/Core>
#include <memory>

#include "pipeline/detector.hpp"
#include "pipeline/geometry.hpp"
#include "pipeline/profile.hpp"

namespace laserline::pipeline {

// Turns laser points (raw pixels) into metres in the camera frame: removes the lens distortion
// (OpenCV's model k1 k2 p1 p2 k3, ScannerGeometry::normalised) and intersects the pixel's ray with
// the laser sheet a*X + b*Y + c*Z + e = 0. Nothing allocates.
class Triangulator {
 public:
  explicit Triangulator(const ScannerGeometry& geometry);

  // The point of the laser sheet seen at raw pixel (u, v). False where the ray does not meet the
  // sheet in front of the camera (or cannot be undistorted).
  bool point(double u, double v, Eigen::Vector3d& xyz) const;

  // Fills xyz of every valid point of the profile (its points mapped to the frame by its axes);
  // NaN for rejected ones and for misses.
  void fill(Profile& profile) const;
  // fill() of the points [first, end) only.
  void fill(Profile& profile, std::size_t first, std::size_t end) const;

 private:
  ScannerGeometry geometry_;
};

// Wraps a detector so that its points leave with xyz (make_detector does this for every detector).
std::unique_ptr<Detector> with_triangulation(std::unique_ptr<Detector> detector,
                                             const ScannerGeometry& geometry);

}  // namespace laserline::pipeline
