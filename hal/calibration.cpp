#include "hal/calibration.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <sstream>

namespace laserline::hal {

bool CameraIntrinsics::has_distortion() const {
  for (double k : distortion) {
    if (k != 0.0) return true;
  }
  return false;
}

const char* to_string(LaserSide side) {
  switch (side) {
    case LaserSide::kAbove:
      return "above";
    case LaserSide::kBelow:
      return "below";
    case LaserSide::kLeft:
      return "left";
    case LaserSide::kRight:
      return "right";
  }
  return "above";
}

Eigen::Vector4d LaserMount::plane_coefficients() const {
  if (plane) return *plane;
  // Above: Y = -d + tan(90 - beta) Z  <=>  0*X + 1*Y - tan(90 - beta) Z + d = 0; the other sides
  // are the same sheet turned about the optical axis, the projector at +y, -x or +x.
  const double t = std::tan((90.0 - angle_deg) * std::numbers::pi / 180.0);
  switch (side) {
    case LaserSide::kBelow:
      return Eigen::Vector4d{0.0, -1.0, -t, baseline_m};
    case LaserSide::kLeft:
      return Eigen::Vector4d{1.0, 0.0, -t, baseline_m};
    case LaserSide::kRight:
      return Eigen::Vector4d{-1.0, 0.0, -t, baseline_m};
    case LaserSide::kAbove:
      break;
  }
  return Eigen::Vector4d{0.0, 1.0, -t, baseline_m};
}

namespace {

class Fnv1a64 {
 public:
  void bytes(std::uint64_t value, int count) {
    for (int i = 0; i < count; ++i) {
      hash_ ^= (value >> (8 * i)) & 0xffu;
      hash_ *= 0x100000001b3u;
    }
  }
  void integer(int value) { bytes(static_cast<std::uint32_t>(value), 4); }
  void number(double value) {
    if (value == 0.0) value = 0.0;  // -0 and 0 triangulate alike
    bytes(std::bit_cast<std::uint64_t>(value), 8);
  }
  std::uint64_t value() const { return hash_; }

 private:
  std::uint64_t hash_ = 0xcbf29ce484222325u;
};

}  // namespace

std::uint64_t calibration_id(const Calibration& calibration) {
  const CameraIntrinsics& c = calibration.camera;
  Fnv1a64 h;
  h.integer(c.width);
  h.integer(c.height);
  for (double v : {c.fx, c.fy, c.cx, c.cy})
    h.number(v);
  for (double k : c.distortion)
    h.number(k);
  for (double p : calibration.laser.plane_coefficients())
    h.number(p);
  h.number(calibration.laser.sheet_width_m);
  return h.value();
}

std::string calibration_id_text(std::uint64_t id) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(id));
  return text;
}

namespace {

// The keys of laserline's own layout: camera: {width, height, fx, fy, cx, cy, distortion}.
void read_native_camera(YamlMap& cam, CameraIntrinsics& c) {
  c.width = static_cast<int>(cam.integer("width", c.width, 16, 16384));
  c.height = static_cast<int>(cam.integer("height", c.height, 16, 16384));
  c.fx = cam.number("fx", c.fx, 1.0, 1e6);
  c.fy = cam.number("fy", c.fy, 1.0, 1e6);
  c.cx = cam.number("cx", (c.width - 1) / 2.0, -1e5, 1e5);
  c.cy = cam.number("cy", (c.height - 1) / 2.0, -1e5, 1e5);
  std::vector<double> dist = cam.numbers("distortion", {4, 5});
  for (std::size_t i = 0; i < dist.size(); ++i)
    c.distortion[i] = dist[i];
}

struct OpenCvMatrix {
  int rows = 0;
  int cols = 0;
  std::vector<double> data;
};

// A matrix as cv::FileStorage writes it: `!!opencv-matrix {rows, cols, dt, data: [...]}` (the tag
// is optional, so a hand-written mapping works too). Only single-channel numeric types.
OpenCvMatrix read_opencv_matrix(YamlMap& parent, const std::string& key) {
  if (!parent.has(key)) parent.fail(key, "is required");
  YamlMap m = parent.map(key);
  OpenCvMatrix result;
  result.rows = static_cast<int>(m.required_integer("rows", 1, 64));
  result.cols = static_cast<int>(m.required_integer("cols", 1, 64));
  m.choice("dt", "d", {"d", "f", "i", "u", "s", "w"});
  if (!m.has("data")) m.fail("data", "is required");
  result.data = m.numbers("data", {static_cast<std::size_t>(result.rows * result.cols)});
  m.finish();
  return result;
}

// What OpenCV's calibration samples write besides the camera model; read past, not used.
const std::vector<std::string> kOpenCvInformationalKeys = {"calibration_time",
                                                           "nframes",
                                                           "nr_of_frames",
                                                           "board_width",
                                                           "board_height",
                                                           "square_size",
                                                           "aspectRatio",
                                                           "fix_aspect_ratio",
                                                           "flags",
                                                           "avg_reprojection_error",
                                                           "per_view_reprojection_errors",
                                                           "extrinsic_parameters",
                                                           "image_points",
                                                           "grid_points"};

// ROS's camera_info layout (camera_calibration's ost.yaml) is OpenCV's with these besides: the
// model's name, and the rectification and projection of a rectified stream, which laserline does
// not use (it reads the camera's raw frames: camera_matrix and the distortion apply).
const std::vector<std::string> kRosInformationalKeys = {"camera_name", "rectification_matrix",
                                                        "projection_matrix"};

// OpenCV's calibration layout (samples/cpp/calibration.cpp, cv::FileStorage): image_width,
// image_height, camera_matrix (3x3) and distortion_coefficients (k1 k2 p1 p2 [k3 [k4 k5 k6 ...]]);
// also as ROS writes it (kRosInformationalKeys, distortion_model).
void read_opencv_camera(YamlMap& cam, CameraIntrinsics& c) {
  // The size is required here: a camera matrix is only valid for the image size it was
  // calibrated at, and the native defaults belong to another camera.
  c.width = static_cast<int>(cam.required_integer("image_width", 16, 16384));
  c.height = static_cast<int>(cam.required_integer("image_height", 16, 16384));

  const OpenCvMatrix k = read_opencv_matrix(cam, "camera_matrix");
  const std::string k_data = "camera_matrix";
  if (k.rows != 3 || k.cols != 3) {
    cam.fail(k_data, "must be 3x3, got " + std::to_string(k.rows) + "x" + std::to_string(k.cols));
  }
  // [fx s cx; 0 fy cy; 0 0 1]: anything else is not a pinhole camera matrix.
  if (k.data[3] != 0.0 || k.data[6] != 0.0 || k.data[7] != 0.0 || k.data[8] != 1.0) {
    cam.fail(k_data, "is not a camera matrix [fx 0 cx; 0 fy cy; 0 0 1]");
  }
  if (k.data[1] != 0.0) cam.fail(k_data, "has a skew (element 0,1): not supported, must be 0");
  auto in_range = [&](double value, const char* name, double min, double max) {
    if (!(value >= min && value <= max)) {
      std::ostringstream problem;
      problem << name << " must be between " << min << " and " << max << ", got " << value;
      cam.fail(k_data, problem.str());
    }
    return value;
  };
  c.fx = in_range(k.data[0], "fx", 1.0, 1e6);
  c.cx = in_range(k.data[2], "cx", -1e5, 1e5);
  c.fy = in_range(k.data[4], "fy", 1.0, 1e6);
  c.cy = in_range(k.data[5], "cy", -1e5, 1e5);

  c.distortion = {};
  if (cam.has("distortion_coefficients")) {
    const OpenCvMatrix d = read_opencv_matrix(cam, "distortion_coefficients");
    const std::size_t n = d.data.size();
    if ((d.rows != 1 && d.cols != 1) || (n != 4 && n != 5 && n != 8 && n != 12 && n != 14)) {
      cam.fail("distortion_coefficients",
               "must be a 1xN or Nx1 vector with N = 4, 5, 8, 12 or 14, got " +
                   std::to_string(d.rows) + "x" + std::to_string(d.cols));
    }
    // The rational, thin-prism and tilt terms (k4 and later) are not part of laserline's model:
    // accepted only when zero, as OpenCV writes them when they were not estimated.
    for (std::size_t i = 5; i < n; ++i) {
      if (d.data[i] != 0.0) {
        cam.fail("distortion_coefficients",
                 "coefficient " + std::to_string(i) +
                     " (k4 and later: rational, thin-prism or tilt model) is not supported, must "
                     "be 0");
      }
    }
    for (std::size_t i = 0; i < std::min<std::size_t>(n, 5); ++i)
      c.distortion[i] = d.data[i];
  } else {
    cam.node("distortion_coefficients");  // absent or null: no distortion
  }
  if (cam.integer("fisheye_model", 0, 0, 1) != 0) {
    cam.fail("fisheye_model", "the fisheye model is not supported");
  }
  // ROS: plumb_bob is k1 k2 p1 p2 k3, rational_polynomial adds k4 k5 k6 (accepted as zero above).
  if (cam.choice("distortion_model", "plumb_bob",
                 {"plumb_bob", "rational_polynomial", "equidistant"}) == "equidistant") {
    cam.fail("distortion_model", "the equidistant (fisheye) model is not supported");
  }
  for (const auto& key : kOpenCvInformationalKeys)
    cam.node(key);
  for (const auto& key : kRosInformationalKeys)
    cam.node(key);
}

// Kalibr's camchain layout (camera-IMU and multi-camera calibration in ROS): cam0's pinhole model,
// intrinsics [fu, fv, pu, pv], resolution [width, height] and radtan distortion [k1, k2, p1, p2].
// Its other keys (the IMU and the other cameras' poses, the topic) are read past.
const std::vector<std::string> kKalibrInformationalKeys = {
    "rostopic", "T_cam_imu", "timeshift_cam_imu", "cam_overlaps", "T_cn_cnm1", "line_delay"};

void read_kalibr_camera(YamlMap& cam, CameraIntrinsics& c) {
  const std::string model =
      cam.choice("camera_model", "pinhole", {"pinhole", "omni", "eucm", "ds"});
  if (model != "pinhole") {
    cam.fail("camera_model", "the " + model + " model is not supported (pinhole only)");
  }
  if (!cam.has("resolution")) cam.fail("resolution", "is required: [width, height]");
  const std::vector<double> size = cam.numbers("resolution", {2});
  for (const double side : size) {
    if (side != std::floor(side) || side < 16 || side > 16384) {
      cam.fail("resolution", "must be two whole numbers from 16 to 16384");
    }
  }
  c.width = static_cast<int>(size[0]);
  c.height = static_cast<int>(size[1]);
  if (!cam.has("intrinsics")) cam.fail("intrinsics", "is required: [fu, fv, pu, pv]");
  const std::vector<double> k = cam.numbers("intrinsics", {4});
  if (!(k[0] >= 1.0 && k[0] <= 1e6 && k[1] >= 1.0 && k[1] <= 1e6)) {
    cam.fail("intrinsics", "fu and fv must be between 1 and 1e+06");
  }
  if (!(std::abs(k[2]) <= 1e5 && std::abs(k[3]) <= 1e5)) {
    cam.fail("intrinsics", "pu and pv must be between -1e+05 and 1e+05");
  }
  c.fx = k[0];
  c.fy = k[1];
  c.cx = k[2];
  c.cy = k[3];
  const std::string distortion =
      cam.choice("distortion_model", "radtan", {"radtan", "none", "equidistant", "fov"});
  if (distortion == "equidistant" || distortion == "fov") {
    cam.fail("distortion_model", "the " + distortion + " model is not supported (radtan only)");
  }
  const std::vector<double> d = cam.numbers("distortion_coeffs", {0, 4});
  if (distortion == "radtan" && d.size() != 4) {
    cam.fail("distortion_coeffs", "radtan needs 4 numbers: [k1, k2, p1, p2]");
  }
  if (distortion == "none" && std::any_of(d.begin(), d.end(), [](double x) { return x != 0; })) {
    cam.fail("distortion_coeffs", "must be empty or zero with distortion_model none");
  }
  c.distortion = {};
  for (std::size_t i = 0; i < d.size(); ++i)
    c.distortion[i] = d[i];
  for (const auto& key : kKalibrInformationalKeys)
    cam.node(key);
}

}  // namespace

Calibration read_calibration(YamlMap& map) {
  Calibration cal;
  if (map.has("cam0")) {
    for (const char* other : {"camera", "camera_matrix"}) {
      if (map.has(other)) {
        map.fail(other, "give the camera once: Kalibr's cam0 or this, not both");
      }
    }
    if (map.has("cam1")) {
      map.fail("cam1",
               "a second camera: laserline uses one; keep the scanner's camera as cam0 and "
               "remove the others");
    }
    YamlMap cam = map.map("cam0");
    read_kalibr_camera(cam, cal.camera);
    cam.finish();
  } else if (map.has("camera_matrix")) {
    // The mapping itself is OpenCV's calibration output (possibly with a laser section added).
    if (map.has("camera")) {
      map.fail("camera",
               "give the camera either as a camera section or in OpenCV's layout (camera_matrix, "
               "...), not both");
    }
    read_opencv_camera(map, cal.camera);
  } else {
    YamlMap cam = map.map("camera");
    if (cam.has("camera_matrix")) {
      read_opencv_camera(cam, cal.camera);
    } else {
      read_native_camera(cam, cal.camera);
    }
    cam.finish();
  }

  YamlMap laser = map.map("laser");
  cal.laser.baseline_m = laser.number("baseline_m", cal.laser.baseline_m, 1e-3, 10.0);
  cal.laser.angle_deg = laser.number("angle_deg", cal.laser.angle_deg, 1.0, 179.0);
  cal.laser.sheet_width_m = laser.number("sheet_width_m", cal.laser.sheet_width_m, 1e-5, 0.1);
  const std::string side =
      laser.choice("side", to_string(cal.laser.side), {"above", "below", "left", "right"});
  for (LaserSide s : {LaserSide::kAbove, LaserSide::kBelow, LaserSide::kLeft, LaserSide::kRight}) {
    if (side == to_string(s)) cal.laser.side = s;
  }
  std::vector<double> plane = laser.numbers("plane", {4});
  if (!plane.empty()) {
    const double norm = std::sqrt(plane[0] * plane[0] + plane[1] * plane[1] + plane[2] * plane[2]);
    if (norm < 1e-9) laser.fail("plane", "the normal (a, b, c) must not be zero");
    cal.laser.plane = Eigen::Vector4d{plane[0], plane[1], plane[2], plane[3]};
  }
  laser.finish();
  return cal;
}

Calibration load_calibration_file(const std::string& path, CalibrationParts required) {
  YamlMap root(load_yaml_file(path), path, "");
  Calibration cal = read_calibration(root);
  root.finish();
  // Checked after every given value was: a wrong value is named before a missing one.
  if (!root.has("camera_matrix") && !root.has("cam0")) {
    if (!root.has("camera")) {
      root.fail("camera",
                "is required: the camera's width, height, fx and fy (cx, cy, distortion "
                "optional), or OpenCV's image_width, image_height and camera_matrix, or Kalibr's "
                "cam0");
    }
    YamlMap camera = root.map("camera");
    if (!camera.has("camera_matrix")) {
      for (const char* key : {"width", "height", "fx", "fy"}) {
        if (!camera.has(key)) {
          camera.fail(key, "is required in a calibration file (the defaults are another camera's)");
        }
      }
    }
  }
  if (required == CalibrationParts::kCameraAndLaser && !root.has("laser")) {
    root.fail("laser",
              "is required: the laser sheet's plane [a, b, c, e] (laserline-calibrate writes it), "
              "or the mount's baseline_m and angle_deg");
  }
  return cal;
}

}  // namespace laserline::hal
