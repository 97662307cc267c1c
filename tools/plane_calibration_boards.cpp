// The calibration's boards: the corners in every view, the intrinsics and each board's pose.
#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>

#include "tools/laser_line_removal.hpp"
#include "tools/plane_calibration_stages.hpp"

namespace laserline::tools {

namespace {

// Boards whose normals differ by less than this are parallel for the purpose of calibration.
constexpr double kMinPoseSpreadDeg = 3.0;

// Where the radial distortion stops being one-to-one inside the image: the distorted radius
// (as a fraction of the farthest image corner's) at which r (1 + k1 r^2 + k2 r^4 + k3 r^6) stops
// growing; 0 when it grows all the way to the image's corners.
double distortion_fold(const hal::CameraIntrinsics& c) {
  double corner = 0;
  for (double u : {0.0, c.width - 1.0}) {
    for (double v : {0.0, c.height - 1.0})
      corner = std::max(corner, std::hypot((u - c.cx) / c.fx, (v - c.cy) / c.fy));
  }
  const auto& [k1, k2, p1, p2, k3] = c.distortion;
  (void)p1;
  (void)p2;
  constexpr int kSteps = 2000;
  const double step = 4.0 * corner / kSteps;  // undistorted radius may exceed the distorted one
  for (int i = 1; i <= kSteps; ++i) {
    const double r = i * step, r2 = r * r;
    const double rd = r * (1 + r2 * (k1 + r2 * (k2 + r2 * k3)));
    if (rd >= corner) return 0.0;
    const double slope = 1 + r2 * (3 * k1 + r2 * (5 * k2 + r2 * 7 * k3));
    if (!(slope > 0)) return rd / corner;
  }
  return 1.0;  // never reaches the corners: the model shrinks the whole image onto less
}

}  // namespace

std::vector<BoardView> find_boards(CalibrationRun& run, cv::Size size,
                                   std::vector<ViewImages>& images) {
  const std::vector<CalibrationView>& views = run.views;
  const PlaneCalibrationOptions& o = run.options;
  PlaneCalibrationResult& result = run.result;
  // The board is black and white, so it is in every channel of a colour image: luma (mostly
  // green, two of a Bayer sensor's four sites) gives it with the least noise. The laser's part of
  // luma is taken out with the line. (The channels without the laser found fewer real boards:
  // dim blue is noisy.)
  const hal::LaserChannel board_light = hal::parse_laser_channel("grey");
  const std::string pattern = std::to_string(o.board_columns) + "x" + std::to_string(o.board_rows);

  // Corners in every view. Without a laser-off image the line is taken out of the image first
  // (found by the detector with the intrinsics given, or a guess: a field of view of about 53
  // degrees), and the raw image is searched when that does not give the board.
  hal::CameraIntrinsics provisional;
  if (o.intrinsics) {
    provisional = *o.intrinsics;
  } else {
    provisional.width = size.width;
    provisional.height = size.height;
    provisional.fx = provisional.fy = size.width;
    provisional.cx = (size.width - 1) / 2.0;
    provisional.cy = (size.height - 1) / 2.0;
  }
  // The line's points for its removal: the user's detector's and `maxvalue`'s (each column's
  // brightest pixel: no width model, so it also finds lines much wider or brighter than the
  // nominal mount's, which the front-end's width normalisation may pass over).
  std::vector<LineFinder> removal_finders;
  for (const std::string& name : {o.detector, std::string("maxvalue")}) {
    try {
      removal_finders.emplace_back(o, provisional, name);
    } catch (const std::invalid_argument&) {
      // Nothing to search with the guessed intrinsics: that detector does not help the
      // removal; its error, if it persists with the final intrinsics, comes below.
    }
  }
  std::vector<BoardView> boards;
  for (std::size_t i = 0; i < views.size(); ++i) {
    images[i] = images_of(views[i], o.channel, board_light, o.frontend.saturation_level);
    const ViewImages& im = images[i];
    BoardView b;
    b.index = i;
    std::string from;
    if (!im.board_off.empty()) {
      if (find_corners(im.board_off, o, b.corners)) from = "laser-off image";
    } else {
      std::vector<cv::Point2d> points;
      for (LineFinder& finder : removal_finders) {
        const std::vector<cv::Point2d> found = finder.find(im.laser_on);
        points.insert(points.end(), found.begin(), found.end());
      }
      cv::Mat removed;
      const LineRemoval removal = remove_laser_line(im.board_on, im.laser_on, points, removed);
      if (removal.points > 0 && find_corners(removed, o, b.corners)) from = "line removed";
      if (from.empty() && find_corners(im.board_on, o, b.corners)) from = "laser-on image";
      // Found either way, the corners the line covered are not where they were found.
      const int placed = from.empty() ? 0 : place_hidden_corners(b.corners, removal.band, o);
      b.gated = true;
      b.line_band = removal.band;
      if (placed > 0) {
        from += " (" + std::to_string(placed) + " corner" + (placed > 1 ? "s" : "") +
                " under the line placed from their neighbours)";
      }
    }
    if (from.empty()) {
      run.skip(i,
               "no " + pattern + " checkerboard found" +
                   (im.board_off.empty() ? "" : " in its laser-off image"),
               "without a " + pattern + " checkerboard");
      continue;
    }
    result.views[i].board = true;
    result.views[i].corners_from = from;
    boards.push_back(std::move(b));
  }
  if (boards.size() < 2) {
    fail("the " + pattern + " checkerboard was found in " + std::to_string(boards.size()) + " of " +
         std::to_string(views.size()) +
         " views, need at least 2 (the whole board must be in view; --board counts inner "
         "corners)");
  }
  return boards;
}

hal::CameraIntrinsics board_intrinsics(CalibrationRun& run, const std::vector<BoardView>& boards,
                                       cv::Size size) {
  const PlaneCalibrationOptions& o = run.options;
  PlaneCalibrationResult& result = run.result;
  hal::CameraIntrinsics cam;
  const std::vector<cv::Point3f> object = board_points(o);
  if (o.intrinsics) {
    cam = *o.intrinsics;
  } else {
    std::vector<std::vector<cv::Point3f>> objects(boards.size(), object);
    std::vector<std::vector<cv::Point2f>> corners;
    for (const auto& b : boards)
      corners.push_back(b.corners);
    int flags = 0;
    switch (o.distortion_terms) {
      case 0:
        flags =
            cv::CALIB_FIX_K1 | cv::CALIB_FIX_K2 | cv::CALIB_FIX_K3 | cv::CALIB_ZERO_TANGENT_DIST;
        break;
      case 2:
        flags = cv::CALIB_FIX_K3 | cv::CALIB_ZERO_TANGENT_DIST;
        break;
      case 4:
        flags = cv::CALIB_FIX_K3;
        break;
      case 5:
        break;
      default:
        fail("distortion terms must be 0, 2, 4 or 5");
    }
    cv::Mat k, dist;
    std::vector<cv::Mat> rvecs, tvecs;
    result.camera_rms_px =
        cv::calibrateCamera(objects, corners, size, k, dist, rvecs, tvecs, flags);
    cam.width = size.width;
    cam.height = size.height;
    cam.fx = k.at<double>(0, 0);
    cam.fy = k.at<double>(1, 1);
    cam.cx = k.at<double>(0, 2);
    cam.cy = k.at<double>(1, 2);
    cam.distortion = {};
    for (int i = 0; i < std::min(5, static_cast<int>(dist.total())); ++i)
      cam.distortion[static_cast<std::size_t>(i)] = dist.at<double>(i);
    if (!std::isfinite(cam.fx) || !(cam.fx > 0) || !(cam.fy > 0)) {
      fail(
          "camera calibration failed: the board poses do not determine the intrinsics (tilt "
          "the board in different directions)");
    }
    result.intrinsics_estimated = true;
  }

  double reach = 0, image_corner = 0;
  for (const auto& b : boards) {
    for (const auto& p : b.corners)
      reach = std::max(reach, std::hypot(p.x - cam.cx, p.y - cam.cy));
  }
  for (double u : {0.0, cam.width - 1.0}) {
    for (double v : {0.0, cam.height - 1.0})
      image_corner = std::max(image_corner, std::hypot(u - cam.cx, v - cam.cy));
  }
  result.corner_coverage = reach / image_corner;
  if (result.intrinsics_estimated) {
    const double fold = distortion_fold(cam);
    if (fold > 0) {
      fail(
          format("the estimated distortion folds the image over at %.0f%% of the way to its "
                 "corners while the boards reach only %.0f%%: add views with the board near the "
                 "image's corners and edges, or estimate fewer --distortion-terms",
                 100.0 * fold, 100.0 * result.corner_coverage));
    }
  }
  return cam;
}

void pose_boards(CalibrationRun& run, std::vector<BoardView>& boards,
                 const hal::CameraIntrinsics& cam) {
  const std::vector<CalibrationView>& views = run.views;
  const PlaneCalibrationOptions& o = run.options;
  PlaneCalibrationResult& result = run.result;
  const std::vector<cv::Point3f> object = board_points(o);
  const cv::Matx33d k = camera_matrix(cam);
  const cv::Mat dist(cam.distortion, false);
  double corner_sq = 0;
  std::size_t corner_count = 0;
  std::vector<BoardView> posed;
  for (BoardView& b : boards) {
    ViewReport& r = result.views[b.index];
    if (!cv::solvePnP(object, b.corners, k, dist, b.rvec, b.tvec, false, cv::SOLVEPNP_ITERATIVE)) {
      run.skip(b.index, "the board's pose could not be estimated", "whose board's pose failed");
      continue;
    }
    std::vector<cv::Point2f> projected;
    cv::projectPoints(object, b.rvec, b.tvec, k, dist, projected);
    double sq = 0;
    for (std::size_t j = 0; j < projected.size(); ++j) {
      const cv::Point2f d = projected[j] - b.corners[j];
      sq += d.dot(d);
    }
    corner_sq += sq;
    corner_count += projected.size();
    r.corner_rms_px = std::sqrt(sq / static_cast<double>(projected.size()));
    cv::Matx33d rotation;
    cv::Rodrigues(b.rvec, rotation);
    b.normal = cv::Vec3d(rotation(0, 2), rotation(1, 2), rotation(2, 2));
    b.offset = b.normal.dot(b.tvec);
    if (b.offset < 0) {
      b.normal = -b.normal;
      b.offset = -b.offset;
    }
    r.distance_m = b.offset;
    r.tilt_deg = std::acos(std::clamp(std::abs(b.normal[2]), 0.0, 1.0)) / kDeg;
    posed.push_back(std::move(b));
  }
  boards = std::move(posed);
  if (boards.size() < 2) {
    fail("the board's pose was found in " + std::to_string(boards.size()) + " of " +
         std::to_string(views.size()) + " views, need at least 2: " + run.tally());
  }
  result.corner_rms_px = std::sqrt(corner_sq / static_cast<double>(corner_count));

  // Board poses must not all be parallel: parallel boards determine neither the intrinsics nor,
  // robustly, the plane (all lines on it would be parallel).
  double spread = 0;
  for (const auto& a : boards) {
    for (const auto& b : boards)
      spread = std::max(spread, std::acos(std::clamp(a.normal.dot(b.normal), -1.0, 1.0)) / kDeg);
  }
  if (spread < kMinPoseSpreadDeg) {
    fail(
        format("degenerate board poses: all %.0f boards are parallel (normals within %.2f deg); "
               "need at least 2 views with the board tilted differently (>= %.0f deg apart)",
               static_cast<double>(boards.size()), spread, kMinPoseSpreadDeg));
  }
}

}  // namespace laserline::tools
