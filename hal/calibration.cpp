#include "hal/calibration.hpp"

#include <cmath>
#include <numbers>

namespace laserline::hal {

bool CameraIntrinsics::has_distortion() const {
  for (double k : distortion) {
    if (k != 0.0) return true;
  }
  return false;
}

std::array<double, 4> LaserMount::plane_coefficients() const {
  if (plane) return *plane;
  // Y = -d + tan(90 - beta) Z  <=>  0*X + 1*Y - tan(90 - beta) Z + d = 0
  const double t = std::tan((90.0 - angle_deg) * std::numbers::pi / 180.0);
  return {0.0, 1.0, -t, baseline_m};
}

Calibration read_calibration(YamlMap& map) {
  Calibration cal;
  YamlMap cam = map.map("camera");
  cal.camera.width = static_cast<int>(cam.integer("width", cal.camera.width, 16, 16384));
  cal.camera.height = static_cast<int>(cam.integer("height", cal.camera.height, 16, 16384));
  cal.camera.fx = cam.number("fx", cal.camera.fx, 1.0, 1e6);
  cal.camera.fy = cam.number("fy", cal.camera.fy, 1.0, 1e6);
  cal.camera.cx = cam.number("cx", (cal.camera.width - 1) / 2.0, -1e5, 1e5);
  cal.camera.cy = cam.number("cy", (cal.camera.height - 1) / 2.0, -1e5, 1e5);
  std::vector<double> dist = cam.numbers("distortion", {4, 5});
  for (std::size_t i = 0; i < dist.size(); ++i)
    cal.camera.distortion[i] = dist[i];
  cam.finish();

  YamlMap laser = map.map("laser");
  cal.laser.baseline_m = laser.number("baseline_m", cal.laser.baseline_m, 1e-3, 10.0);
  cal.laser.angle_deg = laser.number("angle_deg", cal.laser.angle_deg, 1.0, 179.0);
  cal.laser.sheet_width_m = laser.number("sheet_width_m", cal.laser.sheet_width_m, 1e-5, 0.1);
  std::vector<double> plane = laser.numbers("plane", {4});
  if (!plane.empty()) {
    const double norm = std::sqrt(plane[0] * plane[0] + plane[1] * plane[1] + plane[2] * plane[2]);
    if (norm < 1e-9) laser.fail("plane", "the normal (a, b, c) must not be zero");
    cal.laser.plane = std::array<double, 4>{plane[0], plane[1], plane[2], plane[3]};
  }
  laser.finish();
  return cal;
}

Calibration load_calibration_file(const std::string& path) {
  YamlMap root(load_yaml_file(path), path, "");
  Calibration cal = read_calibration(root);
  root.finish();
  return cal;
}

}  // namespace laserline::hal
