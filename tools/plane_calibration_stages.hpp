#pragma once

// The stages calibrate_laser_plane (laser_plane_calibration.cpp) runs in turn, and their state.

#include <cstddef>
#include <numbers>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "tools/laser_plane_calibration.hpp"
#include "tools/plane_calibration_view.hpp"

namespace laserline::tools {

constexpr double kDeg = std::numbers::pi / 180.0;

// Throws PlaneCalibrationError(message).
[[noreturn]] void fail(const std::string& message);
// snprintf of up to three numbers into one line.
std::string format(const char* fmt, double a, double b = 0, double c = 0);
double median(std::vector<double> v);

// One calibration as it runs.
struct CalibrationRun {
  CalibrationRun(const std::vector<CalibrationView>& calibration_views,
                 const PlaneCalibrationOptions& calibration_options);

  // View i does not contribute to the plane: `why` in its report and to options.on_skip, `kind`
  // counted in tally().
  void skip(std::size_t i, const std::string& why, const std::string& kind);
  // "3 without a 9x6 checkerboard, 1 without the laser line on the board": how many views were
  // left out for each reason.
  std::string tally() const;

  const std::vector<CalibrationView>& views;
  const PlaneCalibrationOptions& options;
  PlaneCalibrationResult result;
  std::vector<std::string> left_out;  // per view: why it was left out (kind), empty when it was not
};

// The boards (plane_calibration_boards.cpp). The corners in every view, with each view's images
// (of `size`) filled in `images`; the intrinsics given or estimated from the boards; each board's
// pose, leaving out those without one. Each fails when fewer than 2 boards are left.
std::vector<BoardView> find_boards(CalibrationRun& run, cv::Size size,
                                   std::vector<ViewImages>& images);
hal::CameraIntrinsics board_intrinsics(CalibrationRun& run, const std::vector<BoardView>& boards,
                                       cv::Size size);
void pose_boards(CalibrationRun& run, std::vector<BoardView>& boards,
                 const hal::CameraIntrinsics& cam);

// The laser line's points on the boards, in 3-D, in the order of the boards.
struct LinePoints {
  std::vector<cv::Vec3d> xyz;
  std::vector<int> view_of;  // index into the boards
};

struct Plane {
  cv::Vec3d normal;  // unit
  double e = 0;      // normal . X + e = 0
};

// The plane through the lines' points (laser_plane_fit.cpp): of the views whose lines agree on
// one plane, fitted robustly; `use` marks the points it keeps.
Plane fit_laser_plane(CalibrationRun& run, const std::vector<BoardView>& boards,
                      const LinePoints& points, const hal::CameraIntrinsics& cam,
                      std::vector<char>& use);

// The result from the fitted plane (laser_plane_report.cpp): the residuals, the sheet width
// measured, and the calibration with the plane and the paper's model closest to it.
void report_plane(CalibrationRun& run, const std::vector<BoardView>& boards, const Plane& plane,
                  const std::vector<char>& use, const hal::CameraIntrinsics& cam);

}  // namespace laserline::tools
