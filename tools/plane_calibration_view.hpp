#pragma once

// One view of the laser-plane calibration (laser_plane_calibration.cpp runs the stages): its
// images as the calibration uses them, the board's corners in it and the laser line's points on
// the board.

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "tools/laser_plane_calibration.hpp"

namespace laserline::tools {

// K, the intrinsics' camera matrix.
inline cv::Matx33d camera_matrix(const hal::CameraIntrinsics& c) {
  return {c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1};
}

// The images of one view as the calibration uses them (mono8): the laser's channel and the
// board's (luma), with the laser on and (when taken) off.
struct ViewImages {
  cv::Mat laser_on, laser_off, board_on, board_off;
};

// A view whose board was found: its corners and pose, and the laser line's points on it.
struct BoardView {
  std::size_t index = 0;  // into the views
  std::vector<cv::Point2f> corners;
  cv::Vec3d rvec, tvec;
  cv::Vec3d normal;  // board plane in the camera frame: normal . X = offset, offset > 0
  double offset = 0;
  std::vector<cv::Point2d> laser_px;  // undistorted pixel coordinates of the line's points
  std::vector<cv::Vec3d> laser_xyz;   // on the board plane, camera frame, metres
  // Per point: the sheet width its line's full width at half maximum gives at its depth
  // (metres; NaN where it could not be measured, e.g. a clipped core).
  std::vector<double> sheet_width_m;
  // Without a laser-off image: where the line was found and taken out before the corner search
  // (empty: no line found). The detector's points are kept there only.
  bool gated = false;
  cv::Mat line_band;
};

// The board's inner corners on its own plane (z = 0), metres, row by row.
std::vector<cv::Point3f> board_points(const PlaneCalibrationOptions& o);

// The board's corners in `grey`, refined to subpixel; false when no board was found.
bool find_corners(const cv::Mat& grey, const PlaneCalibrationOptions& o,
                  std::vector<cv::Point2f>& corners);

// Corners the removed line covered: the band lost the squares' edges that ran along the line, so
// what was found there is where the band put them, not where they are. Each is placed instead
// by the homography of its board's neighbours outside the band (within two squares, else three:
// near enough that the lens bends them little); returns how many were.
int place_hidden_corners(std::vector<cv::Point2f>& corners, const cv::Mat& band,
                         const PlaneCalibrationOptions& o);

// A laserline detector over whole images of one size, each on its own (no previous frame), in
// the image's pixel coordinates whichever way the line runs. Throws std::invalid_argument, from
// the detector, when it cannot work.
class LineFinder {
 public:
  LineFinder(const PlaneCalibrationOptions& o, const hal::CameraIntrinsics& cam,
             const std::string& detector);

  // The detector's chosen points (one per epipolar line), or with `candidates` every candidate,
  // in a mono8 image of the camera's size, in its pixel coordinates.
  std::vector<cv::Point2d> find(const cv::Mat& image, bool candidates = false);

 private:
  int width_, height_;
  std::unique_ptr<pipeline::Detector> detector_;
  pipeline::Profile profile_;
};

// The laser line's points on the board of `bv` (posed): the detector's points inside the board's
// outline (near the removed line's band when `bv.gated`) on one straight line, undistorted, and
// where their rays meet the board plane, with the sheet width each gives; counted in `report`.
void find_laser(BoardView& bv, const ViewImages& images, const PlaneCalibrationOptions& o,
                const hal::CameraIntrinsics& cam, LineFinder& finder, ViewReport& report);

// The view's images in the laser's channel and the board's (colours clipped from `clipped_from`,
// as to_laser_mono8 says); throws PlaneCalibrationError naming the view when one does not convert.
ViewImages images_of(const CalibrationView& v, const hal::LaserChannel& laser,
                     const hal::LaserChannel& board, int clipped_from);

}  // namespace laserline::tools
