// Calibration files: laserline's own layout and OpenCV's calibration layout, including a file
// written by cv::FileStorage itself.
#include "hal/calibration.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <opencv2/core.hpp>
#include <string>

namespace laserline::hal {
namespace {

class CalibrationFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("laserline_calibration_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  // The one-line error of loading `text` as a calibration file, or "" when it loads.
  std::string error_of(const std::string& text) {
    const std::string path = write("calib.yaml", text);
    try {
      load_calibration_file(path);
    } catch (const ConfigError& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
      // Reported relative to the file name so the expectations below stay readable.
      return what.rfind(path, 0) == 0 ? "calib.yaml" + what.substr(path.size()) : what;
    }
    return "";
  }

  std::filesystem::path dir_;
};

TEST_F(CalibrationFile, NativeLayout) {
  const Calibration c = load_calibration_file(
      write("native.yaml",
            "camera: {width: 1280, height: 1024, fx: 1400, fy: 1410, cx: 639.5, cy: 511.5,\n"
            "         distortion: [0.1, -0.2, 0.001, 0.002, 0.05]}\n"
            "laser: {baseline_m: 0.25, angle_deg: 80, sheet_width_m: 0.003}\n"));
  EXPECT_EQ(c.camera.width, 1280);
  EXPECT_EQ(c.camera.height, 1024);
  EXPECT_DOUBLE_EQ(c.camera.fy, 1410);
  EXPECT_DOUBLE_EQ(c.camera.distortion[4], 0.05);
  EXPECT_DOUBLE_EQ(c.laser.angle_deg, 80);
  EXPECT_FALSE(c.laser.plane.has_value());
}

// The projector on each side of the camera: the same sheet turned about the optical axis. Each
// plane passes through the projector (baseline d on that side, Z = 0) and meets the optical axis
// at the same depth d / tan(90 - beta).
TEST_F(CalibrationFile, LaserSides) {
  const double d = 0.2, t = std::tan((90.0 - 75.0) * M_PI / 180.0);
  const std::map<std::string, std::array<double, 3>> projector = {
      {"above", {0, -d, 0}}, {"below", {0, d, 0}}, {"left", {-d, 0, 0}}, {"right", {d, 0, 0}}};
  for (const auto& [side, at] : projector) {
    const Calibration c =
        load_calibration_file(write(side + ".yaml",
                                    "camera: {width: 640, height: 480, fx: 700, fy: 700}\nlaser: "
                                    "{baseline_m: 0.2, angle_deg: 75, side: " +
                                        side + "}\n"));
    EXPECT_STREQ(to_string(c.laser.side), side.c_str());
    const Eigen::Vector4d sheet = c.laser.plane_coefficients();
    const double a = sheet[0], b = sheet[1], cc = sheet[2], e = sheet[3];
    EXPECT_NEAR(a * at[0] + b * at[1] + cc * at[2] + e, 0.0, 1e-12) << side;
    const double axis_depth = -e / cc;  // X = Y = 0
    EXPECT_NEAR(axis_depth, d / t, 1e-12) << side;
  }
  EXPECT_EQ(error_of("laser: {side: up}\n"),
            "calib.yaml:1: laser.side: must be one of above, below, left, right, got 'up'");
}

// The layout of OpenCV's calibration sample, written by cv::FileStorage (with its `%YAML:1.0`
// header), plus the laser section laserline needs, also written by cv::FileStorage.
TEST_F(CalibrationFile, WrittenByOpenCvFileStorage) {
  const std::string path = (dir_ / "opencv.yml").string();
  {
    cv::FileStorage fs(path, cv::FileStorage::WRITE);
    ASSERT_TRUE(fs.isOpened());
    const cv::Mat k = (cv::Mat_<double>(3, 3) << 1402.5, 0, 641.25, 0, 1398.75, 509.5, 0, 0, 1);
    const cv::Mat d = (cv::Mat_<double>(5, 1) << -0.12, 0.034, 0.0011, -0.0007, 0.0021);
    const cv::Mat extrinsics = cv::Mat::zeros(2, 6, CV_64F);
    fs << "calibration_time"
       << "Sun Nov 22 22:00:00 2026";
    fs << "nframes" << 2 << "image_width" << 1280 << "image_height" << 1024;
    fs << "board_width" << 9 << "board_height" << 6 << "square_size" << 0.025f;
    fs << "flags" << 0 << "camera_matrix" << k << "distortion_coefficients" << d;
    fs << "avg_reprojection_error" << 0.21;
    fs << "per_view_reprojection_errors" << cv::Mat((cv::Mat_<float>(2, 1) << 0.2f, 0.22f));
    fs << "extrinsic_parameters" << extrinsics;
    fs << "laser"
       << "{"
       << "baseline_m" << 0.3 << "angle_deg" << 75.0 << "sheet_width_m" << 0.002 << "}";
  }
  std::ifstream in(path);
  std::string first_line;
  std::getline(in, first_line);
  ASSERT_EQ(first_line, "%YAML:1.0") << "not the header this test is about";

  const Calibration c = load_calibration_file(path);
  EXPECT_EQ(c.camera.width, 1280);
  EXPECT_EQ(c.camera.height, 1024);
  EXPECT_DOUBLE_EQ(c.camera.fx, 1402.5);
  EXPECT_DOUBLE_EQ(c.camera.fy, 1398.75);
  EXPECT_DOUBLE_EQ(c.camera.cx, 641.25);
  EXPECT_DOUBLE_EQ(c.camera.cy, 509.5);
  const std::array<double, 5> expected{-0.12, 0.034, 0.0011, -0.0007, 0.0021};
  for (std::size_t i = 0; i < expected.size(); ++i)
    EXPECT_DOUBLE_EQ(c.camera.distortion[i], expected[i]) << i;
  EXPECT_DOUBLE_EQ(c.laser.baseline_m, 0.3);
  EXPECT_DOUBLE_EQ(c.laser.angle_deg, 75.0);
  EXPECT_DOUBLE_EQ(c.laser.sheet_width_m, 0.002);
}

// Float matrices and the 8-coefficient vector OpenCV writes with CALIB_RATIONAL_MODEL off.
TEST_F(CalibrationFile, OpenCvFloatMatrixAndEightZeroTailedCoefficients) {
  const std::string path = (dir_ / "float.yml").string();
  {
    cv::FileStorage fs(path, cv::FileStorage::WRITE);
    fs << "image_width" << 640 << "image_height" << 480;
    fs << "camera_matrix" << cv::Mat((cv::Mat_<float>(3, 3) << 700, 0, 320, 0, 700, 240, 0, 0, 1));
    fs << "distortion_coefficients"
       << cv::Mat((cv::Mat_<float>(1, 8) << 0.5f, -0.25f, 0, 0, 0.125f, 0, 0, 0));
  }
  // Without a laser section: where the sheet is what is being calibrated (laserline-calibrate
  // --calib).
  const Calibration c = load_calibration_file(path, CalibrationParts::kCamera);
  EXPECT_EQ(c.camera.width, 640);
  EXPECT_DOUBLE_EQ(c.camera.fx, 700);
  EXPECT_DOUBLE_EQ(c.camera.cy, 240);
  EXPECT_DOUBLE_EQ(c.camera.distortion[0], 0.5);
  EXPECT_DOUBLE_EQ(c.camera.distortion[4], 0.125);
  EXPECT_DOUBLE_EQ(c.laser.baseline_m, LaserMount{}.baseline_m) << "laser takes its defaults";
}

TEST_F(CalibrationFile, OpenCvLayoutInsideTheCameraSection) {
  const Calibration c = load_calibration_file(
      write("nested.yaml",
            "camera:\n"
            "  image_width: 800\n"
            "  image_height: 600\n"
            "  camera_matrix: !!opencv-matrix\n"
            "    rows: 3\n"
            "    cols: 3\n"
            "    dt: d\n"
            "    data: [ 900., 0., 399.5, 0., 905., 299.5, 0., 0., 1. ]\n"
            "  distortion_coefficients: {rows: 1, cols: 4, dt: d, data: [0.01, 0.02, 0.003, "
            "0.004]}\n"
            "laser: {baseline_m: 0.2, plane: [0, 1, -0.2, 0.2]}\n"));
  EXPECT_EQ(c.camera.width, 800);
  EXPECT_DOUBLE_EQ(c.camera.fy, 905);
  EXPECT_DOUBLE_EQ(c.camera.cx, 399.5);
  EXPECT_DOUBLE_EQ(c.camera.distortion[3], 0.004);
  EXPECT_DOUBLE_EQ(c.camera.distortion[4], 0.0);
  ASSERT_TRUE(c.laser.plane.has_value());
  EXPECT_DOUBLE_EQ((*c.laser.plane)[2], -0.2);
}

// ROS's camera_info file (camera_calibration writes ost.yaml so), with a laser section added.
TEST_F(CalibrationFile, RosCameraInfo) {
  const std::string ros =
      "image_width: 1280\n"
      "image_height: 1024\n"
      "camera_name: ptu_camera\n"
      "camera_matrix:\n"
      "  rows: 3\n"
      "  cols: 3\n"
      "  data: [1402.5, 0.0, 641.25, 0.0, 1398.75, 509.5, 0.0, 0.0, 1.0]\n"
      "distortion_model: plumb_bob\n"
      "distortion_coefficients:\n"
      "  rows: 1\n"
      "  cols: 5\n"
      "  data: [-0.125, 0.0625, 0.001, -0.002, 0.0]\n"
      "rectification_matrix:\n"
      "  rows: 3\n"
      "  cols: 3\n"
      "  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n"
      "projection_matrix:\n"
      "  rows: 3\n"
      "  cols: 4\n"
      "  data: [1380.0, 0.0, 640.0, 0.0, 0.0, 1380.0, 510.0, 0.0, 0.0, 0.0, 1.0, 0.0]\n";
  const Calibration c = load_calibration_file(
      write("ost.yaml", ros + "laser: {baseline_m: 0.25, plane: [0, 0.98, -0.17, 0.25]}\n"));
  EXPECT_EQ(c.camera.width, 1280);
  EXPECT_DOUBLE_EQ(c.camera.fx, 1402.5);  // camera_matrix, not projection_matrix
  EXPECT_DOUBLE_EQ(c.camera.fy, 1398.75);
  EXPECT_DOUBLE_EQ(c.camera.cx, 641.25);
  EXPECT_DOUBLE_EQ(c.camera.distortion[0], -0.125);
  EXPECT_DOUBLE_EQ(c.camera.distortion[3], -0.002);
  ASSERT_TRUE(c.laser.plane.has_value());

  std::string rational = ros;
  rational.replace(rational.find("plumb_bob"), 9, "rational_polynomial");
  rational.replace(rational.find("cols: 5"), 7, "cols: 8");
  rational.replace(rational.find("0.0]\nrect"), 4, "0.0, 0.0, 0.0, 0.0]");
  EXPECT_EQ(error_of(rational + "laser: {angle_deg: 80}\n"), "");
  std::string fisheye = ros;
  fisheye.replace(fisheye.find("plumb_bob"), 9, "equidistant");
  EXPECT_EQ(error_of(fisheye),
            "calib.yaml:8: distortion_model: the equidistant (fisheye) model is not supported");
  std::string unknown = ros;
  unknown.replace(unknown.find("plumb_bob"), 9, "brown");
  EXPECT_EQ(error_of(unknown),
            "calib.yaml:8: distortion_model: must be one of plumb_bob, rational_polynomial, "
            "equidistant, got 'brown'");
}

// Kalibr's camchain file (its cam0), with a laser section added.
TEST_F(CalibrationFile, KalibrCamchain) {
  const std::string cam0 =
      "cam0:\n"
      "  T_cam_imu:\n"
      "  - [0.0, -1.0, 0.0, 0.05]\n"
      "  - [1.0, 0.0, 0.0, 0.0]\n"
      "  - [0.0, 0.0, 1.0, -0.02]\n"
      "  - [0.0, 0.0, 0.0, 1.0]\n"
      "  cam_overlaps: []\n"
      "  camera_model: pinhole\n"
      "  distortion_coeffs: [-0.25, 0.125, 0.0005, -0.001]\n"
      "  distortion_model: radtan\n"
      "  intrinsics: [1401.5, 1399.25, 640.75, 509.5]\n"
      "  resolution: [1280, 1024]\n"
      "  rostopic: /ptu/camera/image_raw\n"
      "  timeshift_cam_imu: 0.0021\n";
  const std::string laser = "laser: {baseline_m: 0.25, angle_deg: 80}\n";
  const Calibration c = load_calibration_file(write("camchain.yaml", cam0 + laser));
  EXPECT_EQ(c.camera.width, 1280);
  EXPECT_EQ(c.camera.height, 1024);
  EXPECT_DOUBLE_EQ(c.camera.fx, 1401.5);
  EXPECT_DOUBLE_EQ(c.camera.fy, 1399.25);
  EXPECT_DOUBLE_EQ(c.camera.cx, 640.75);
  EXPECT_DOUBLE_EQ(c.camera.cy, 509.5);
  EXPECT_DOUBLE_EQ(c.camera.distortion[0], -0.25);
  EXPECT_DOUBLE_EQ(c.camera.distortion[3], -0.001);
  EXPECT_DOUBLE_EQ(c.camera.distortion[4], 0.0);

  auto with = [&](const std::string& from, const std::string& to) {
    std::string text = cam0;
    text.replace(text.find(from), from.size(), to);
    return error_of(text + laser);
  };
  EXPECT_EQ(with("camera_model: pinhole", "camera_model: omni"),
            "calib.yaml:8: cam0.camera_model: the omni model is not supported (pinhole only)");
  EXPECT_EQ(with("distortion_model: radtan", "distortion_model: equidistant"),
            "calib.yaml:10: cam0.distortion_model: the equidistant model is not supported "
            "(radtan only)");
  EXPECT_EQ(with("[-0.25, 0.125, 0.0005, -0.001]", "[-0.25, 0.125]"),
            "calib.yaml:9: cam0.distortion_coeffs: must have 0 or 4 numbers, got 2");
  EXPECT_EQ(with("resolution: [1280, 1024]", "resolution: [1280.5, 1024]"),
            "calib.yaml:12: cam0.resolution: must be two whole numbers from 16 to 16384");
  EXPECT_EQ(with("intrinsics: [1401.5, ", "intrinsics: [0, "),
            "calib.yaml:11: cam0.intrinsics: fu and fv must be between 1 and 1e+06");
  EXPECT_EQ(with("distortion_model: radtan", "distortion_model: none"),
            "calib.yaml:9: cam0.distortion_coeffs: must be empty or zero with distortion_model "
            "none");
  EXPECT_EQ(error_of(cam0 + "cam1:\n  camera_model: pinhole\n" + laser),
            "calib.yaml:16: cam1: a second camera: laserline uses one; keep the scanner's camera "
            "as cam0 and remove the others");
  EXPECT_EQ(error_of(cam0 + "camera: {fx: 1}\n" + laser),
            "calib.yaml:15: camera: give the camera once: Kalibr's cam0 or this, not both");
  const std::string unknown = error_of("cam0:\n  focal: 3\n" + laser);
  EXPECT_EQ(unknown.rfind("calib.yaml:", 0), 0u) << unknown;
}

TEST_F(CalibrationFile, OpenCvLayoutErrorsNameFileLineAndKey) {
  const std::string k =
      "  camera_matrix: {rows: 3, cols: 3, dt: d, data: [1400, 0, 639.5, 0, "
      "1400, 511.5, 0, 0, 1]}\n";
  const std::string size = "  image_width: 1280\n  image_height: 1024\n";
  EXPECT_EQ(error_of("camera:\n" + size + k + "laser: {angle_deg: 80}\n"), "");
  EXPECT_EQ(error_of("camera:\n  image_width: 1280\n" + k),
            "calib.yaml:2: camera.image_height: is required");
  EXPECT_EQ(error_of("camera:\n" + size +
                     "  camera_matrix: {rows: 3, cols: 3, dt: d, data: [1, 2, 3]}\n"),
            "calib.yaml:4: camera.camera_matrix.data: must have 9 numbers, got 3");
  EXPECT_EQ(error_of("camera:\n" + size +
                     "  camera_matrix: {rows: 2, cols: 3, dt: d, data: [1, 0, 3, 0, 1, 3]}\n"),
            "calib.yaml:4: camera.camera_matrix: must be 3x3, got 2x3");
  EXPECT_EQ(error_of("camera:\n" + size +
                     "  camera_matrix: {rows: 3, cols: 3, dt: d, data: [1400, 2, 639.5, 0, 1400, "
                     "511.5, 0, 0, 1]}\n"),
            "calib.yaml:4: camera.camera_matrix: has a skew (element 0,1): not supported, must "
            "be 0");
  EXPECT_EQ(error_of("camera:\n" + size +
                     "  camera_matrix: {rows: 3, cols: 3, dt: d, data: [1400, 0, 639.5, 0, 1400, "
                     "511.5, 0, 0, 2]}\n"),
            "calib.yaml:4: camera.camera_matrix: is not a camera matrix [fx 0 cx; 0 fy cy; 0 0 "
            "1]");
  EXPECT_EQ(error_of("camera:\n" + size +
                     "  camera_matrix: {rows: 3, cols: 3, dt: d, data: [0, 0, 639.5, 0, 1400, "
                     "511.5, 0, 0, 1]}\n"),
            "calib.yaml:4: camera.camera_matrix: fx must be between 1 and 1e+06, got 0");
  EXPECT_EQ(error_of("camera:\n" + size + k +
                     "  distortion_coefficients: {rows: 1, cols: 8, dt: d, data: [0, 0, 0, 0, 0, "
                     "0.1, 0, 0]}\n"),
            "calib.yaml:5: camera.distortion_coefficients: coefficient 5 (k4 and later: "
            "rational, thin-prism or tilt model) is not supported, must be 0");
  EXPECT_EQ(error_of("camera:\n" + size + k +
                     "  distortion_coefficients: {rows: 2, cols: 3, dt: d, data: [0, 0, 0, 0, 0, "
                     "0]}\n"),
            "calib.yaml:5: camera.distortion_coefficients: must be a 1xN or Nx1 vector with N = "
            "4, 5, 8, 12 or 14, got 2x3");
  EXPECT_EQ(error_of("camera:\n" + size + k +
                     "  distortion_coefficients: {rows: 1, cols: 5, dt: 3f, data: [0, 0, 0, 0, "
                     "0]}\n"),
            "calib.yaml:5: camera.distortion_coefficients.dt: must be one of d, f, i, u, s, w, "
            "got '3f'");
  EXPECT_EQ(error_of("camera:\n" + size + k + "  fisheye_model: 1\n"),
            "calib.yaml:5: camera.fisheye_model: the fisheye model is not supported");
  // Native and OpenCV keys do not mix: the OpenCV layout lists its own keys.
  const std::string mixed = error_of("camera:\n" + size + k + "  fx: 1400\n");
  EXPECT_EQ(mixed.rfind("calib.yaml:5: camera.fx: unknown key (expected one of: ", 0), 0u) << mixed;
  EXPECT_NE(mixed.find("camera_matrix"), std::string::npos) << mixed;
  // At the top level, together with a camera section.
  EXPECT_EQ(error_of(size.substr(2, 18) + "image_height: 1024\ncamera_matrix: {rows: 3, cols: 3, "
                                          "dt: d, data: [1400, 0, 639.5, 0, 1400, 511.5, 0, 0, "
                                          "1]}\ncamera: {fx: 1}\n"),
            "calib.yaml:4: camera: give the camera either as a camera section or in OpenCV's "
            "layout (camera_matrix, ...), not both");
}

// A calibration file gives its camera (and, where the sheet is used, its laser): defaults belong
// to another camera. Files that are not calibrations are named as such.
TEST_F(CalibrationFile, RequiredPartsAreNamed) {
  const std::string camera = "camera: {width: 640, height: 480, fx: 700, fy: 700}\n";
  const std::string laser = "laser: {baseline_m: 0.2, angle_deg: 75}\n";
  EXPECT_EQ(error_of(camera + laser), "");
  EXPECT_EQ(error_of(laser),
            "calib.yaml:1: camera: is required: the camera's width, height, fx and fy (cx, cy, "
            "distortion optional), or OpenCV's image_width, image_height and camera_matrix, or "
            "Kalibr's cam0");
  EXPECT_EQ(error_of("camera: {width: 640, height: 480, fx: 700}\n" + laser),
            "calib.yaml:1: camera.fy: is required in a calibration file (the defaults are another "
            "camera's)");
  EXPECT_EQ(error_of("camera:\n" + laser),
            "calib.yaml:1: camera: is empty (give its keys, or leave the section out for the "
            "defaults)");
  EXPECT_EQ(error_of(camera),
            "calib.yaml:1: laser: is required: the laser sheet's plane [a, b, c, e] "
            "(laserline-calibrate writes it), or the mount's baseline_m and angle_deg");
  EXPECT_EQ(
      load_calibration_file(write("camera_only.yaml", camera), CalibrationParts::kCamera).camera.fx,
      700.0);
  EXPECT_EQ(error_of(""), "calib.yaml: has no keys (empty, or only comments)");
  for (const std::string& not_a_file : {dir_.string(), std::string("/dev/null")}) {
    try {
      load_calibration_file(not_a_file);
      ADD_FAILURE() << not_a_file;
    } catch (const ConfigError& e) {
      EXPECT_EQ(std::string(e.what()),
                not_a_file + ": is " +
                    (not_a_file == "/dev/null" ? "a character device" : "a directory") +
                    ", not a file: give a configuration or calibration file");
    }
  }
}

TEST_F(CalibrationFile, NativeErrorsUnchanged) {
  EXPECT_EQ(error_of("camera: {fx: 0}\n"),
            "calib.yaml:1: camera.fx: must be between 1 and 1e+06, got 0");
  EXPECT_EQ(error_of("camera:\n  distortion: [1, 2]\n"),
            "calib.yaml:2: camera.distortion: must have 4 or 5 numbers, got 2");
  EXPECT_EQ(error_of("laser:\n  angel_deg: 80\n"),
            "calib.yaml:2: laser.angel_deg: unknown key (expected one of: angle_deg, baseline_m, "
            "plane, sheet_width_m, side)");
}

// calibration_id: what a log's profiles and calibration_t name; it must stay the same across
// versions (logs outlive the software) and tell any two calibrations apart.
TEST(CalibrationId, StableAndTheSameHoweverTheSheetIsWritten) {
  const Calibration defaults;
  EXPECT_EQ(calibration_id(defaults), calibration_id(Calibration{}));
  // Pinned (computed independently in Python, docs/messages.md): a change of the serialisation
  // would make every recorded log name another id.
  EXPECT_EQ(calibration_id_text(calibration_id(defaults)), "252c9bdbd4951ce8");
  // The sheet given as its plane triangulates as baseline and angle do: the same id.
  Calibration as_plane = defaults;
  as_plane.laser.plane = defaults.laser.plane_coefficients();
  as_plane.laser.baseline_m = 1.0;  // not used once the plane is given
  EXPECT_EQ(calibration_id(as_plane), calibration_id(defaults));
  Calibration negative_zero = defaults;
  negative_zero.camera.distortion[2] = -0.0;
  EXPECT_EQ(calibration_id(negative_zero), calibration_id(defaults));
  EXPECT_EQ(calibration_id_text(0x00ab), "00000000000000ab");
  EXPECT_EQ(calibration_id_text(0xfedcba9876543210), "fedcba9876543210");
}

TEST(CalibrationId, ChangesWithEveryValue) {
  const Calibration base;
  const std::uint64_t id = calibration_id(base);
  std::map<std::uint64_t, std::string> seen{{id, "base"}};
  auto differs = [&](const std::string& what, const std::function<void(Calibration&)>& change) {
    Calibration c = base;
    change(c);
    const std::uint64_t other = calibration_id(c);
    EXPECT_NE(other, id) << what;
    const auto [at, inserted] = seen.emplace(other, what);
    EXPECT_TRUE(inserted) << what << " gives the id of " << at->second;
  };
  differs("width", [](Calibration& c) { c.camera.width += 1; });
  differs("height", [](Calibration& c) { c.camera.height += 1; });
  differs("width and height swapped", [](Calibration& c) {
    c.camera.width = 1024;
    c.camera.height = 1280;
  });
  differs("fx", [](Calibration& c) { c.camera.fx = std::nextafter(c.camera.fx, 2e3); });
  differs("fy", [](Calibration& c) { c.camera.fy += 0.001; });
  differs("cx", [](Calibration& c) { c.camera.cx += 0.001; });
  differs("cy", [](Calibration& c) { c.camera.cy += 0.001; });
  for (std::size_t k = 0; k < 5; ++k) {
    differs("distortion " + std::to_string(k),
            [k](Calibration& c) { c.camera.distortion[k] = 1e-6; });
  }
  differs("baseline", [](Calibration& c) { c.laser.baseline_m += 0.001; });
  differs("angle", [](Calibration& c) { c.laser.angle_deg += 0.01; });
  differs("side", [](Calibration& c) { c.laser.side = LaserSide::kBelow; });
  for (std::size_t k = 0; k < 4; ++k) {
    differs("plane " + std::to_string(k), [k](Calibration& c) {
      Eigen::Vector4d plane = c.laser.plane_coefficients();
      plane[k] += 1e-4;
      c.laser.plane = plane;
    });
  }
  differs("sheet width", [](Calibration& c) { c.laser.sheet_width_m *= 2; });
}

}  // namespace
}  // namespace laserline::hal
