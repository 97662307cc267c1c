#pragma once

#include <array>
#include <memory>

#include "pipeline/detector.hpp"
#include "pipeline/geometry.hpp"
#include "pipeline/profile.hpp"

namespace laserline::pipeline {

// Turns laser points (raw pixels) into metres in the camera frame: removes the lens distortion
// (OpenCV's model k1 k2 p1 p2 k3) and intersects the pixel's ray with the laser sheet
// a*X + b*Y + c*Z + e = 0. Everything is precomputed at construction; nothing allocates.
class Triangulator {
 public:
  explicit Triangulator(const ScannerGeometry& geometry);

  // Undistorted normalised image coordinates (x, y) = (X/Z, Y/Z) of the raw pixel (u, v). False
  // where the distortion model cannot be inverted there (far outside the calibrated field).
  bool undistort(double u, double v, double& x, double& y) const;

  // The point of the laser sheet seen at raw pixel (u, v). False where the ray does not meet the
  // sheet in front of the camera (or cannot be undistorted).
  bool point(double u, double v, std::array<double, 3>& xyz) const;

  // Fills xyz of every valid point of the profile; NaN for rejected ones and for misses.
  void fill(Profile& profile) const;

 private:
  double fx_, fy_, cx_, cy_;
  double k1_, k2_, p1_, p2_, k3_;
  bool distorted_;
  std::array<double, 4> plane_;
};

// Wraps a detector so that its points leave with xyz (make_detector does this for every detector).
std::unique_ptr<Detector> with_triangulation(std::unique_ptr<Detector> detector,
                                             const ScannerGeometry& geometry);

}  // namespace laserline::pipeline
