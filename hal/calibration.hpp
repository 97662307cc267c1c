#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "hal/yaml_reader.hpp"

namespace laserline::hal {

// Pinhole intrinsics, OpenCV convention (x right, y down, pixel centres at integers).
struct CameraIntrinsics {
  int width = 1280;
  int height = 1024;
  double fx = 1400, fy = 1400, cx = 639.5, cy = 511.5;
  std::array<double, 5> distortion{};  // k1 k2 p1 p2 k3

  bool has_distortion() const;
};

// Which side of the camera the laser projector is on, as seen in the image: above (the paper's
// mounting, the line runs across the image), below, left or right (the line runs down the image).
enum class LaserSide : std::uint8_t { kAbove, kBelow, kLeft, kRight };
const char* to_string(LaserSide side);

// Where the laser sheet is relative to the camera (the paper's d, beta, l_w). With the projector
// above the camera it sits at baseline d along -y and the sheet contains the x direction:
// Y = -d + tan(90deg - beta) * Z; on another side the same model turned about the optical axis
// (left: X = -d + tan(90deg - beta) * Z). A calibrated plane a*X + b*Y + c*Z + e = 0 (camera
// frame, metres) replaces that model when set.
struct LaserMount {
  double baseline_m = 0.25;
  double angle_deg = 80.0;
  double sheet_width_m = 0.003;
  LaserSide side = LaserSide::kAbove;
  std::optional<Eigen::Vector4d> plane;

  // The sheet as a*X + b*Y + c*Z + e = 0, from `plane` or from baseline, angle and side.
  Eigen::Vector4d plane_coefficients() const;
};

struct Calibration {
  CameraIntrinsics camera;
  LaserMount laser;
};

// What tells two calibrations apart: 64-bit FNV-1a over the image size, fx, fy, cx, cy, the five
// distortion coefficients, the laser sheet's plane_coefficients() and its width, in that order
// (sizes as 32-bit and numbers as IEEE 754 bits, little-endian; -0 taken as 0). Two calibrations
// that triangulate alike have the same id however they were written (a plane or baseline and
// angle); any change of a value gives another.
std::uint64_t calibration_id(const Calibration& calibration);
// The id as people see it: 16 lower-case hex digits.
std::string calibration_id_text(std::uint64_t id);

// Reads `camera:` and `laser:` sections from a mapping (a calibration file, or the calibration
// section of the daemon's configuration). Throws ConfigError naming the key. The camera may also
// be given in OpenCV's calibration layout (image_width, image_height, camera_matrix,
// distortion_coefficients as cv::FileStorage writes them), either inside `camera:` or at the top
// of the mapping, so that the output of OpenCV's calibration sample is a calibration file as is
// (its `%YAML:1.0` header included) once a `laser:` section is added.
// Keys left out take laserline's defaults (the simulated camera), as in a configuration's inline
// calibration section.
Calibration read_calibration(YamlMap& map);

// What a calibration file must give besides being a valid YAML file (hal/yaml_reader.hpp): the
// camera always, with its width, height, fx and fy (or OpenCV's layout), as defaults would belong
// to another camera; the laser section (its plane, or baseline_m and angle_deg) where the sheet is
// used, not where it is what is being calibrated (laserline-calibrate --calib).
enum class CalibrationParts : std::uint8_t { kCameraAndLaser, kCamera };
Calibration load_calibration_file(const std::string& path,
                                  CalibrationParts required = CalibrationParts::kCameraAndLaser);

}  // namespace laserline::hal
