#pragma once

// Laser-plane calibration from views of a checkerboard with the laser line across it: the
// library behind laserline-calibrate (tools/laserline_calibrate.cpp), separate so the tests can
// run it on simulated views without files.

#include <array>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hal/calibration.hpp"
#include "hal/laser_channel.hpp"
#include "pipeline/detector.hpp"

namespace laserline::tools {

// A calibration problem the user has to fix (bad view, too few views, degenerate poses). what()
// is one line.
class PlaneCalibrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One board pose: the image with the laser on and, if taken, the same pose with the laser off
// (same size and type), as read from the files: mono or colour (OpenCV's BGR order), 8 or 16
// bit. With the laser off the corners are found without the line crossing them and the line is
// found in the difference, free of the board's own edges.
struct CalibrationView {
  std::string name;  // for messages (the file name)
  cv::Mat laser_on;
  cv::Mat laser_off;  // empty when not taken
};

struct PlaneCalibrationOptions {
  int board_columns = 9;  // inner corners per row of the checkerboard (OpenCV's pattern size)
  int board_rows = 6;     // inner corners per column
  double square_m = 0.03;
  // Given intrinsics (from a calibration file); when absent they are estimated from the views
  // with cv::calibrateCamera.
  std::optional<hal::CameraIntrinsics> intrinsics;
  // Distortion terms estimated with the intrinsics: 0 (none), 2 (k1 k2), 4 (k1 k2 p1 p2) or
  // 5 (k1 k2 p1 p2 k3).
  int distortion_terms = 5;
  // The nominal mount (design values): tells the detector where on the image the line can be.
  // The calibrated plane replaces its plane; its sheet_width_m is kept only when
  // measure_sheet_width is false (or too few points give a width).
  hal::LaserMount laser_prior;
  // The sheet width written is measured on the views: the line's full width at half maximum
  // across it, times its depth over the focal length, the median over the plane's inliers.
  bool measure_sheet_width = true;
  std::string detector = "fir";
  pipeline::FrontendOptions frontend = wide_search();
  // Which light of colour images is the laser's: the line is searched there, the board in luma.
  // Mono images are taken as they are.
  hal::LaserChannel channel;
  // Called once for each view that does not contribute to the plane, with one line
  // "<view>: <why>", as soon as that is known (a fatal error may follow).
  std::function<void(const std::string&)> on_skip;

  // The front-end's defaults, but searching nearly every row: the plane is not known yet.
  static pipeline::FrontendOptions wide_search() {
    pipeline::FrontendOptions f;
    f.min_depth_m = 0.2;
    f.max_depth_m = 20.0;
    return f;
  }
};

struct ViewReport {
  std::string name;
  bool board = false;  // its checkerboard was found
  // "laser-off image", "line removed" or "laser-on image", with how many corners under the line
  // were placed from their neighbours
  std::string corners_from;
  std::string skipped;       // why the view does not contribute to the plane; empty when it does
  double corner_rms_px = 0;  // reprojection of the board's corners with the final intrinsics
  double distance_m = 0;     // camera centre to the board plane
  double tilt_deg = 0;       // angle between the board normal and the optical axis
  int laser_candidates = 0;  // detector points inside the board
  int laser_points = 0;      // those on the view's line (straight after undistortion)
  int plane_inliers = 0;     // those kept by the plane fit
  double plane_rms_mm = 0;   // of this view's plane inliers
};

struct PlaneCalibrationResult {
  hal::Calibration calibration;  // camera (given or estimated) + laser with the fitted plane
  bool intrinsics_estimated = false;
  double camera_rms_px = 0;  // cv::calibrateCamera's RMS reprojection error (when estimated)
  double corner_rms_px = 0;  // all views' corners reprojected with their poses
  // How far out the boards' corners reach: the farthest corner's distance from the principal
  // point as a fraction of the farthest image corner's. Estimated distortion is extrapolated
  // beyond it.
  double corner_coverage = 0;
  std::vector<ViewReport> views;
  int points = 0;                             // laser points on the views' lines
  int inliers = 0;                            // kept by the plane fit
  double plane_rms_mm = 0, plane_max_mm = 0;  // inliers' distances to the fitted plane
  // Inliers' distances in the (undistorted) image to the line where the fitted plane meets
  // their view's board.
  double plane_rms_px = 0, plane_max_px = 0;
  // The plane's unit normal and distance: plane = [n, -distance] or sign-flipped so that e > 0.
  double normal_angle_to_y_deg = 0;  // angle between the normal and the camera's y axis
  // baseline_m / angle_deg / side of the paper's model closest to the plane (in
  // calibration.laser); false when the plane cannot be written that way within the calibration
  // file's limits (then clamped).
  bool fits_baseline_model = true;
  // The sheet width in calibration.laser is the median of width_points measurements (see
  // PlaneCalibrationOptions::measure_sheet_width); false: the prior's.
  bool sheet_width_measured = false;
  int width_points = 0;
  double depth_min_m = 0, depth_max_m = 0;  // where the inliers lie (their Z)
};

// Runs the whole calibration. Views that cannot contribute (no board, no line on it, ...) are
// left out, each reported once through options.on_skip and in its ViewReport. Throws
// PlaneCalibrationError with a one-line message naming the view (or the reason, with how many
// views were left out for each) when the rest do not give a calibration.
PlaneCalibrationResult calibrate_laser_plane(const std::vector<CalibrationView>& views,
                                             const PlaneCalibrationOptions& options);

// The calibration file of the front-end issue (camera + laser with `plane`), with the
// residuals as comments; readable by hal::load_calibration_file. Throws PlaneCalibrationError
// when it cannot be written.
void write_calibration_file(const std::string& path, const PlaneCalibrationResult& result,
                            const std::string& provenance);

// An image file as read (mono or colour, 8 or 16 bit), checked to give the laser's channel.
// Throws PlaneCalibrationError naming the file.
cv::Mat load_image(const std::string& path, const hal::LaserChannel& channel);

// Image files given directly or found in folders (sorted by name), in order. Throws
// PlaneCalibrationError for a path that is neither.
std::vector<std::string> expand_image_inputs(const std::vector<std::string>& inputs);

}  // namespace laserline::tools
