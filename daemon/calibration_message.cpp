#include "daemon/calibration_message.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <iterator>

namespace laserline::daemon {

laserline::calibration_t calibration_message(const hal::Calibration& calibration,
                                             std::int64_t instance_id) {
  laserline::calibration_t m{};
  const hal::CameraIntrinsics& c = calibration.camera;
  m.calibration_id = static_cast<std::int64_t>(hal::calibration_id(calibration));
  m.width = c.width;
  m.height = c.height;
  m.fx = c.fx;
  m.fy = c.fy;
  m.cx = c.cx;
  m.cy = c.cy;
  std::copy(c.distortion.begin(), c.distortion.end(), m.distortion);
  const Eigen::Vector4d plane = calibration.laser.plane_coefficients();
  std::copy(plane.begin(), plane.end(), m.laser_plane);
  m.sheet_width_m = calibration.laser.sheet_width_m;
  m.instance_id = instance_id;
  return m;
}

bool calibration_from_message(const laserline::calibration_t& m, hal::Calibration* calibration,
                              std::string* problem) {
  // The ranges of hal/calibration.cpp's reader.
  auto outside = [&](const char* field, double value, double min, double max) {
    if (value >= min && value <= max) return false;  // NaN is outside
    if (problem != nullptr) {
      char line[160];
      std::snprintf(line, sizeof line, "%s %g outside %g..%g", field, value, min, max);
      *problem = line;
    }
    return true;
  };
  if (outside("width", m.width, 16, 16384) || outside("height", m.height, 16, 16384) ||
      outside("fx", m.fx, 1, 1e6) || outside("fy", m.fy, 1, 1e6) ||
      outside("cx", m.cx, -1e5, 1e5) || outside("cy", m.cy, -1e5, 1e5) ||
      outside("sheet_width_m", m.sheet_width_m, 1e-5, 0.1)) {
    return false;
  }
  for (double k : m.distortion) {
    if (outside("distortion", k, -1e6, 1e6)) return false;
  }
  for (double p : m.laser_plane) {
    if (outside("laser_plane", p, -1e6, 1e6)) return false;
  }
  const double* n = m.laser_plane;
  if (std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) < 1e-9) {
    if (problem != nullptr) *problem = "laser_plane: the normal (a, b, c) is zero";
    return false;
  }
  hal::Calibration c;
  c.camera.width = m.width;
  c.camera.height = m.height;
  c.camera.fx = m.fx;
  c.camera.fy = m.fy;
  c.camera.cx = m.cx;
  c.camera.cy = m.cy;
  std::copy(std::begin(m.distortion), std::end(m.distortion), c.camera.distortion.begin());
  c.laser.plane = Eigen::Vector4d{n[0], n[1], n[2], n[3]};
  c.laser.sheet_width_m = m.sheet_width_m;
  const std::uint64_t id = hal::calibration_id(c);
  if (id != static_cast<std::uint64_t>(m.calibration_id)) {
    if (problem != nullptr) {
      *problem = "calibration_id " +
                 hal::calibration_id_text(static_cast<std::uint64_t>(m.calibration_id)) +
                 " is not the id of its content (" + hal::calibration_id_text(id) + ")";
    }
    return false;
  }
  *calibration = c;
  return true;
}

}  // namespace laserline::daemon
