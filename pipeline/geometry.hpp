#pragma once

#include <Eigen/Core>
#include <array>
#include <cmath>

namespace laserline::pipeline {

// What the pipeline knows about the scanner: pinhole intrinsics (OpenCV convention: x right, y
// down, pixel centres at integers) and the laser sheet a*X + b*Y + c*Z + e = 0 in the camera frame
// (metres). Filled by the daemon and the tools from the calibration file; the pipeline does not
// read files.
struct ScannerGeometry {
  int width = 1280;
  int height = 1024;
  double fx = 1400, fy = 1400, cx = 639.5, cy = 511.5;
  std::array<double, 5> distortion{};  // k1 k2 p1 p2 k3 (the front-end works on raw pixels)
  Eigen::Vector4d laser_plane{0.0, 1.0, -0.17632698070846498, 0.25};
  double sheet_width_m = 0.003;  // the paper's l_w

  // Inverse depth 1/Z of the sheet seen at pixel (u, v) (distortion ignored); <= 0 where the ray
  // does not meet the sheet in front of the camera.
  double inverse_depth(double u, double v) const {
    const double a = laser_plane[0], b = laser_plane[1], c = laser_plane[2], e = laser_plane[3];
    if (e == 0.0) return 0.0;
    return -(a * (u - cx) / fx + b * (v - cy) / fy + c) / e;
  }
  // Width of the projected sheet in pixels at row v of the centre column (paper eq. 3): linear
  // in v, f * l_w / Z.
  double line_width_px(double v) const { return fy * sheet_width_m * inverse_depth(cx, v); }

  bool has_distortion() const {
    return distortion[0] != 0.0 || distortion[1] != 0.0 || distortion[2] != 0.0 ||
           distortion[3] != 0.0 || distortion[4] != 0.0;
  }
  // The lens (OpenCV's model k1 k2 p1 p2 k3): raw pixel (u, v) -> undistorted normalised image
  // coordinates (x, y) = (X/Z, Y/Z) of its ray. False where the model cannot be inverted there
  // (beyond the fold of a strongly distorting model, far outside the calibrated field).
  bool normalised(double u, double v, double& x, double& y) const;
  // And back: the raw pixel where the ray (x, y, 1) is seen.
  std::array<double, 2> pixel(double x, double y) const;
};

}  // namespace laserline::pipeline
