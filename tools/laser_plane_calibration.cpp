#include "tools/laser_plane_calibration.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <numbers>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "tools/frame_channel.hpp"

namespace laserline::tools {

namespace {

namespace fs = std::filesystem;

constexpr double kDeg = std::numbers::pi / 180.0;
// Boards whose normals differ by less than this are parallel for the purpose of calibration.
constexpr double kMinPoseSpreadDeg = 3.0;
// A view's laser line: points within this distance (undistorted pixels) of the RANSAC line.
constexpr double kLineInlierPx = 2.0;
constexpr int kLineRansacIterations = 300;
// A view needs this many points on its line to take part.
constexpr int kMinLinePoints = 20;
// Candidates closer to the board's outline than this (pixels) are left out: the line's end on
// the board's edge and the edge itself are not reliable.
constexpr double kBoardInsetPx = 6.0;
// Height of the opening that removes the laser line from a laser-on image before the corner
// search: longer than the line is thick, shorter than a square is high.
constexpr int kLineOpeningPx = 21;

[[noreturn]] void fail(const std::string& message) {
  throw PlaneCalibrationError(message);
}

std::string format(const char* fmt, double a, double b = 0, double c = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}

cv::Matx33d camera_matrix(const hal::CameraIntrinsics& c) {
  return {c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1};
}

struct BoardView {
  const CalibrationView* view = nullptr;
  std::vector<cv::Point2f> corners;
  cv::Vec3d rvec, tvec;
  cv::Vec3d normal;  // board plane in the camera frame: normal . X = offset, offset > 0
  double offset = 0;
  std::vector<cv::Point2d> laser_px;  // undistorted pixel coordinates of the line's points
  std::vector<cv::Vec3d> laser_xyz;   // on the board plane, camera frame, metres
};

std::vector<cv::Point3f> board_points(const PlaneCalibrationOptions& o) {
  std::vector<cv::Point3f> points;
  for (int r = 0; r < o.board_rows; ++r) {
    for (int c = 0; c < o.board_columns; ++c) {
      points.emplace_back(static_cast<float>(c * o.square_m), static_cast<float>(r * o.square_m),
                          0.0f);
    }
  }
  return points;
}

bool find_corners(const cv::Mat& grey, const PlaneCalibrationOptions& o,
                  std::vector<cv::Point2f>& corners) {
  const cv::Size pattern(o.board_columns, o.board_rows);
  const int flags = cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE;
  if (!cv::findChessboardCorners(grey, pattern, corners, flags)) return false;
  // Refinement window: about a third of the smallest square seen, so it never reaches the next
  // corner.
  double nearest = 1e9;
  for (int r = 0; r < o.board_rows; ++r) {
    for (int c = 0; c + 1 < o.board_columns; ++c) {
      const auto& p = corners[static_cast<std::size_t>(r * o.board_columns + c)];
      const auto& q = corners[static_cast<std::size_t>(r * o.board_columns + c + 1)];
      nearest = std::min(nearest, static_cast<double>(std::hypot(p.x - q.x, p.y - q.y)));
    }
  }
  const int half = std::clamp(static_cast<int>(nearest / 3.0), 2, 10);
  cv::cornerSubPix(grey, corners, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  return true;
}

// The straight line (undistorted pixels) through most points, by RANSAC then least squares;
// returns the inliers' indices.
std::vector<std::size_t> line_inliers(const std::vector<cv::Point2d>& points) {
  std::vector<std::size_t> best;
  if (points.size() < 2) return best;
  cv::RNG rng(0x6c617365);  // fixed: the same views give the same calibration
  auto inliers_of = [&](const cv::Point2d& p, const cv::Point2d& direction) {
    std::vector<std::size_t> in;
    const cv::Point2d n(-direction.y, direction.x);
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (std::abs((points[i] - p).dot(n)) <= kLineInlierPx) in.push_back(i);
    }
    return in;
  };
  const int count = static_cast<int>(points.size());
  for (int k = 0; k < kLineRansacIterations; ++k) {
    const int i = rng.uniform(0, count), j = rng.uniform(0, count);
    const cv::Point2d d = points[static_cast<std::size_t>(j)] - points[static_cast<std::size_t>(i)];
    const double length = std::hypot(d.x, d.y);
    if (length < 10.0) continue;
    auto in = inliers_of(points[static_cast<std::size_t>(i)], d / length);
    if (in.size() > best.size()) best = std::move(in);
  }
  // Least-squares refinement once, then the final inlier set.
  if (best.size() >= 2) {
    std::vector<cv::Point2f> fit;
    for (std::size_t i : best)
      fit.emplace_back(static_cast<float>(points[i].x), static_cast<float>(points[i].y));
    cv::Vec4f line;
    cv::fitLine(fit, line, cv::DIST_L2, 0, 0.01, 0.01);
    best = inliers_of(cv::Point2d(line[2], line[3]), cv::Point2d(line[0], line[1]));
  }
  return best;
}

void find_laser(BoardView& bv, const PlaneCalibrationOptions& o, const hal::CameraIntrinsics& cam,
                pipeline::Detector& detector, pipeline::Profile& profile, ViewReport& report) {
  const CalibrationView& view = *bv.view;
  // The board's squares' outline in the (distorted) image.
  const cv::Matx33d k = camera_matrix(cam);
  const cv::Mat dist(cam.distortion, false);
  const double s = o.square_m;
  const double w = o.board_columns * s, h = o.board_rows * s;
  std::vector<cv::Point3d> outline3;
  constexpr int kEdgeSamples = 16;  // per side: the outline stays close under distortion
  for (int i = 0; i < kEdgeSamples; ++i)
    outline3.emplace_back(-s + (w + s) * i / kEdgeSamples, -s, 0);
  for (int i = 0; i < kEdgeSamples; ++i)
    outline3.emplace_back(w, -s + (h + s) * i / kEdgeSamples, 0);
  for (int i = 0; i < kEdgeSamples; ++i)
    outline3.emplace_back(w - (w + s) * i / kEdgeSamples, h, 0);
  for (int i = 0; i < kEdgeSamples; ++i)
    outline3.emplace_back(-s, h - (h + s) * i / kEdgeSamples, 0);
  std::vector<cv::Point2d> outline2;
  cv::projectPoints(outline3, bv.rvec, bv.tvec, k, dist, outline2);
  std::vector<cv::Point2f> outline(outline2.begin(), outline2.end());

  // The detector sees the board only: the scene around it cannot take the line's place among a
  // column's candidates.
  cv::Mat image;  // a new buffer: the view's images are the caller's
  if (view.laser_off.empty()) {
    image = view.laser_on.clone();
  } else {
    cv::subtract(view.laser_on, view.laser_off, image);  // saturating at 0
  }
  cv::Mat outside(image.size(), CV_8UC1, cv::Scalar(255));
  std::vector<cv::Point> polygon;
  for (const auto& p : outline)
    polygon.emplace_back(cvRound(p.x), cvRound(p.y));
  cv::fillPoly(outside, std::vector<std::vector<cv::Point>>{polygon}, cv::Scalar(0));
  image.setTo(0, outside);
  const pipeline::ImageView iv{image.data, image.cols, image.rows, static_cast<int>(image.step)};
  profile.clear();
  detector.reset(image.cols, image.rows);  // each view on its own: no previous frame to follow
  detector.detect(iv, pipeline::FrameContext{0, true}, profile);

  std::vector<cv::Point2d> raw;
  for (const auto& p : profile.points()) {
    if (!p.valid || !std::isfinite(p.v)) continue;
    const cv::Point2f at(static_cast<float>(p.u), p.v);
    if (cv::pointPolygonTest(outline, at, true) >= kBoardInsetPx) raw.emplace_back(p.u, p.v);
  }
  report.laser_candidates = static_cast<int>(raw.size());
  if (raw.empty()) return;
  std::vector<cv::Point2d> undistorted;
  cv::undistortPoints(raw, undistorted, k, dist, cv::noArray(), k);

  const std::vector<std::size_t> in = line_inliers(undistorted);
  for (std::size_t i : in) {
    const cv::Point2d& u = undistorted[i];
    const cv::Vec3d ray((u.x - cam.cx) / cam.fx, (u.y - cam.cy) / cam.fy, 1.0);
    const double z = bv.offset / bv.normal.dot(ray);
    if (!(z > 0)) continue;
    bv.laser_px.push_back(u);
    bv.laser_xyz.push_back(ray * z);
  }
  report.laser_points = static_cast<int>(bv.laser_px.size());
}

struct Plane {
  cv::Vec3d normal;  // unit
  double e = 0;      // normal . X + e = 0
};

// The scatter matrix of the points in use about their centroid.
cv::Matx33d scatter_of(const std::vector<cv::Vec3d>& points, const std::vector<char>& use,
                       cv::Vec3d& centroid) {
  centroid = cv::Vec3d(0, 0, 0);
  double n = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (use[i]) {
      centroid += points[i];
      n += 1;
    }
  }
  centroid /= n;
  cv::Matx33d scatter = cv::Matx33d::zeros();
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (use[i]) {
      const cv::Vec3d d = points[i] - centroid;
      scatter += d * d.t();
    }
  }
  return scatter;
}

Plane fit_plane(const std::vector<cv::Vec3d>& points, const std::vector<char>& use) {
  cv::Vec3d centroid;
  const cv::Matx33d scatter = scatter_of(points, use, centroid);
  cv::Matx31d values;
  cv::Matx33d vectors;
  cv::eigen(scatter, values, vectors);  // descending: the last row is the normal
  Plane p;
  p.normal = cv::Vec3d(vectors(2, 0), vectors(2, 1), vectors(2, 2));
  p.e = -p.normal.dot(centroid);
  if (p.e < 0) {
    p.normal = -p.normal;
    p.e = -p.e;
  }
  return p;
}

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

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

}  // namespace

PlaneCalibrationResult calibrate_laser_plane(const std::vector<CalibrationView>& views,
                                             const PlaneCalibrationOptions& o) {
  if (o.board_columns < 2 || o.board_rows < 2) fail("the board needs at least 2x2 inner corners");
  if (o.board_columns == o.board_rows) {
    // A square pattern has no defined orientation: corners may come back rotated by 90 degrees.
    fail("the board must have different numbers of inner corners across and down (e.g. 9x6)");
  }
  if (!(o.square_m > 0)) fail("the square size must be > 0");
  if (views.size() < 2) {
    fail("need at least 2 views (board poses that are not parallel), got " +
         std::to_string(views.size()));
  }
  const cv::Size size = views.front().laser_on.size();
  for (const auto& v : views) {
    if (v.laser_on.empty() || v.laser_on.type() != CV_8UC1) fail(v.name + ": not a mono8 image");
    if (v.laser_on.size() != size) {
      fail(v.name + ": image size " + std::to_string(v.laser_on.cols) + "x" +
           std::to_string(v.laser_on.rows) + " differs from the first view's " +
           std::to_string(size.width) + "x" + std::to_string(size.height));
    }
    if (!v.laser_off.empty() && (v.laser_off.size() != size || v.laser_off.type() != CV_8UC1)) {
      fail(v.name + ": its laser-off image differs in size or type from the laser-on image");
    }
  }
  if (o.intrinsics && (o.intrinsics->width != size.width || o.intrinsics->height != size.height)) {
    fail("the images are " + std::to_string(size.width) + "x" + std::to_string(size.height) +
         " but the given intrinsics are for " + std::to_string(o.intrinsics->width) + "x" +
         std::to_string(o.intrinsics->height));
  }

  // Corners in every view.
  std::vector<BoardView> boards(views.size());
  for (std::size_t i = 0; i < views.size(); ++i) {
    boards[i].view = &views[i];
    bool found = false;
    if (!views[i].laser_off.empty()) {
      found = find_corners(views[i].laser_off, o, boards[i].corners);
    } else {
      // The laser line across the board breaks up the squares' edges. The sheet contains the
      // camera's x axis, so the line runs along the rows and is a few pixels thick: an opening
      // with a vertical segment longer than that removes it and keeps the squares.
      cv::Mat without_line;
      cv::morphologyEx(views[i].laser_on, without_line, cv::MORPH_OPEN,
                       cv::getStructuringElement(cv::MORPH_RECT, cv::Size(1, kLineOpeningPx)));
      found = find_corners(without_line, o, boards[i].corners);
    }
    if (!found) {
      fail(views[i].name + ": no " + std::to_string(o.board_columns) + "x" +
           std::to_string(o.board_rows) +
           " checkerboard found (the whole board must be in view; --board counts inner "
           "corners)");
    }
  }

  PlaneCalibrationResult result;
  hal::CameraIntrinsics cam;
  const std::vector<cv::Point3f> object = board_points(o);
  if (o.intrinsics) {
    cam = *o.intrinsics;
  } else {
    std::vector<std::vector<cv::Point3f>> objects(views.size(), object);
    std::vector<std::vector<cv::Point2f>> images;
    for (const auto& b : boards)
      images.push_back(b.corners);
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
    result.camera_rms_px = cv::calibrateCamera(objects, images, size, k, dist, rvecs, tvecs, flags);
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

  // Board poses.
  const cv::Matx33d k = camera_matrix(cam);
  const cv::Mat dist(cam.distortion, false);
  double corner_sq = 0;
  std::size_t corner_count = 0;
  result.views.resize(views.size());
  for (std::size_t i = 0; i < boards.size(); ++i) {
    BoardView& b = boards[i];
    ViewReport& r = result.views[i];
    r.name = views[i].name;
    if (!cv::solvePnP(object, b.corners, k, dist, b.rvec, b.tvec, false, cv::SOLVEPNP_ITERATIVE)) {
      fail(views[i].name + ": the board's pose could not be estimated");
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

  // The laser line on each board, in 3-D.
  pipeline::DetectorOptions detector_options;
  detector_options.geometry.width = cam.width;
  detector_options.geometry.height = cam.height;
  detector_options.geometry.fx = cam.fx;
  detector_options.geometry.fy = cam.fy;
  detector_options.geometry.cx = cam.cx;
  detector_options.geometry.cy = cam.cy;
  detector_options.geometry.distortion = cam.distortion;
  detector_options.geometry.laser_plane = o.laser_prior.plane_coefficients();
  detector_options.geometry.sheet_width_m = o.laser_prior.sheet_width_m;
  detector_options.frontend = o.frontend;
  std::unique_ptr<pipeline::Detector> detector;
  try {
    detector = pipeline::make_detector(o.detector, detector_options);
  } catch (const std::invalid_argument& e) {
    fail("detector " + o.detector + ": " + e.what());
  }
  if (!detector) fail("unknown detector " + o.detector);
  detector->reset(cam.width, cam.height);
  pipeline::Profile profile(detector->max_points(cam.width, cam.height));

  std::vector<cv::Vec3d> points;
  std::vector<int> view_of;
  int views_with_line = 0;
  for (std::size_t i = 0; i < boards.size(); ++i) {
    find_laser(boards[i], o, cam, *detector, profile, result.views[i]);
    if (static_cast<int>(boards[i].laser_xyz.size()) < kMinLinePoints) {
      boards[i].laser_xyz.clear();
      boards[i].laser_px.clear();
      result.views[i].laser_points = 0;
      continue;
    }
    ++views_with_line;
    for (const auto& p : boards[i].laser_xyz) {
      points.push_back(p);
      view_of.push_back(static_cast<int>(i));
    }
  }
  if (views_with_line < 2) {
    std::string without;
    for (const auto& r : result.views) {
      if (r.laser_points == 0) without += (without.empty() ? "" : ", ") + r.name;
    }
    fail("the laser line was found on the board in " + std::to_string(views_with_line) +
         " view(s), need at least 2 (none in: " + without + ")");
  }
  result.points = static_cast<int>(points.size());

  // Plane fit with outlier rejection: 3 robust sigmas (MAD), at least 0.1 mm, until stable.
  std::vector<char> allowed(points.size(), 1), use;
  Plane plane;
  auto robust_fit = [&] {
    use = allowed;
    plane = fit_plane(points, use);
    for (int round = 0; round < 10; ++round) {
      std::vector<double> distances(points.size()), allowed_distances;
      for (std::size_t i = 0; i < points.size(); ++i) {
        distances[i] = std::abs(plane.normal.dot(points[i]) + plane.e);
        if (allowed[i]) allowed_distances.push_back(distances[i]);
      }
      const double limit = std::max(3.0 * 1.4826 * median(allowed_distances), 1e-4);
      std::vector<char> next(points.size());
      for (std::size_t i = 0; i < points.size(); ++i)
        next[i] = allowed[i] && distances[i] <= limit;
      if (next == use) break;
      use = std::move(next);
      plane = fit_plane(points, use);
    }
  };
  robust_fit();
  // A view whose line is mostly off the plane saw something else as the line (e.g. a square's
  // edge, where the line is not on the board): it is left out whole, and the plane fitted again.
  {
    std::vector<int> total(boards.size(), 0), kept(boards.size(), 0);
    for (std::size_t i = 0; i < points.size(); ++i) {
      ++total[static_cast<std::size_t>(view_of[i])];
      kept[static_cast<std::size_t>(view_of[i])] += use[i] ? 1 : 0;
    }
    bool dropped = false;
    int remaining = 0;
    for (std::size_t v = 0; v < boards.size(); ++v) {
      if (total[v] == 0) continue;
      if (2 * kept[v] < total[v]) {
        dropped = true;
        for (std::size_t i = 0; i < points.size(); ++i) {
          if (view_of[i] == static_cast<int>(v)) allowed[i] = 0;
        }
      } else {
        ++remaining;
      }
    }
    if (remaining < 2) {
      fail(
          "the laser lines found do not lie on one plane (fewer than 2 views agree): check "
          "that the line crosses the board in every view, or give --laser-off images");
    }
    if (dropped) robust_fit();
  }

  // The inliers must span a plane, not a line: at least 2 views' lines in different places.
  {
    cv::Vec3d centroid;
    const cv::Matx33d scatter = scatter_of(points, use, centroid);
    cv::Matx31d values;
    cv::eigen(scatter, values);
    if (!(values(1) > 1e-4 * values(0))) {
      fail(
          "degenerate board poses: the laser lines of all views lie on one 3-D line; move or "
          "tilt the board between views");
    }
  }

  // Residuals in mm (3-D) and px (image line of the plane on each board).
  double sq_mm = 0, sq_px = 0;
  int inliers = 0;
  std::vector<double> view_sq(boards.size(), 0.0);
  for (std::size_t i = 0, at = 0; i < boards.size(); ++i) {
    const BoardView& b = boards[i];
    // The plane through the camera centre containing the 3-D line (laser plane x board plane).
    const cv::Vec3d m = b.offset * plane.normal + plane.e * b.normal;
    const cv::Vec3d m_px = k.inv().t() * m;
    const double m_norm = std::hypot(m_px[0], m_px[1]);
    for (std::size_t j = 0; j < b.laser_xyz.size(); ++j, ++at) {
      if (!use[at]) continue;
      const double mm = 1000.0 * std::abs(plane.normal.dot(b.laser_xyz[j]) + plane.e);
      const cv::Point2d& u = b.laser_px[j];
      const double px = std::abs(m_px[0] * u.x + m_px[1] * u.y + m_px[2]) / m_norm;
      sq_mm += mm * mm;
      sq_px += px * px;
      view_sq[i] += mm * mm;
      result.plane_max_mm = std::max(result.plane_max_mm, mm);
      result.plane_max_px = std::max(result.plane_max_px, px);
      ++inliers;
      ++result.views[i].plane_inliers;
    }
  }
  result.inliers = inliers;
  result.plane_rms_mm = std::sqrt(sq_mm / inliers);
  result.plane_rms_px = std::sqrt(sq_px / inliers);
  for (std::size_t i = 0; i < boards.size(); ++i) {
    const int n = result.views[i].plane_inliers;
    result.views[i].plane_rms_mm = n > 0 ? std::sqrt(view_sq[i] / n) : 0.0;
  }
  result.normal_angle_to_y_deg = std::acos(std::clamp(std::abs(plane.normal[1]), 0.0, 1.0)) / kDeg;

  result.calibration.camera = cam;
  hal::LaserMount& laser = result.calibration.laser;
  laser = o.laser_prior;
  laser.plane = std::array<double, 4>{plane.normal[0], plane.normal[1], plane.normal[2], plane.e};
  // The paper's model Y = -d + tan(90 deg - beta) Z with the sheet along x: d where the plane
  // crosses the y axis, beta from its slope in the y-z plane. Kept within the file's limits.
  const double b = plane.normal[1];
  double baseline = b != 0 ? plane.e / b : 0.0;
  double angle = 90.0 - std::atan2(-plane.normal[2], b) / kDeg;
  result.fits_baseline_model = baseline >= 1e-3 && baseline <= 10 && angle >= 1 && angle <= 179;
  laser.baseline_m = std::clamp(baseline, 1e-3, 10.0);
  laser.angle_deg = std::clamp(angle, 1.0, 179.0);
  return result;
}

void write_calibration_file(const std::string& path, const PlaneCalibrationResult& r,
                            const std::string& provenance) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) fail(path + ": cannot be written: " + std::strerror(errno));
  const hal::CameraIntrinsics& c = r.calibration.camera;
  const hal::LaserMount& l = r.calibration.laser;
  const auto p = l.plane_coefficients();
  std::fprintf(f, "# laserline calibration written by laserline-calibrate\n");
  std::fprintf(f, "# %s\n", provenance.c_str());
  if (r.intrinsics_estimated) {
    std::fprintf(f, "# camera: estimated, calibrateCamera RMS %.3f px\n", r.camera_rms_px);
  } else {
    std::fprintf(f, "# camera: given\n");
  }
  std::fprintf(f, "# board corners reprojected: RMS %.3f px\n", r.corner_rms_px);
  std::fprintf(f,
               "# laser plane fit: %d of %d points, distance RMS %.3f mm, max %.3f mm; image RMS "
               "%.3f px, max %.3f px\n",
               r.inliers, r.points, r.plane_rms_mm, r.plane_max_mm, r.plane_rms_px, r.plane_max_px);
  std::fprintf(f,
               "camera: {width: %d, height: %d, fx: %.10g, fy: %.10g, cx: %.10g, cy: %.10g, "
               "distortion: [%.10g, %.10g, %.10g, %.10g, %.10g]}\n",
               c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.distortion[0], c.distortion[1],
               c.distortion[2], c.distortion[3], c.distortion[4]);
  std::fprintf(f, "laser:\n");
  std::fprintf(f, "  # the paper's d and beta nearest to the plane%s; `plane` is what is used\n",
               r.fits_baseline_model ? "" : " (clamped: the plane does not fit that model)");
  std::fprintf(f, "  baseline_m: %.10g\n  angle_deg: %.10g\n", l.baseline_m, l.angle_deg);
  std::fprintf(f, "  sheet_width_m: %.10g\n", l.sheet_width_m);
  std::fprintf(f, "  # a*X + b*Y + c*Z + e = 0, camera frame, metres; (a, b, c) a unit vector\n");
  std::fprintf(f, "  plane: [%.12g, %.12g, %.12g, %.12g]\n", p[0], p[1], p[2], p[3]);
  const bool ok = std::ferror(f) == 0;
  if (std::fclose(f) != 0 || !ok) fail(path + ": could not be written completely");
}

cv::Mat load_mono8(const std::string& path) {
  cv::Mat raw;
  try {
    raw = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    raw.release();
  }
  if (raw.empty()) {
    if (access(path.c_str(), R_OK) != 0) fail(path + ": cannot be read: " + std::strerror(errno));
    fail(path + ": not a readable image (corrupt or unsupported format)");
  }
  cv::Mat out;
  std::string problem;
  if (!to_laser_mono8(raw, hal::LaserChannel{}, out, problem)) fail(path + ": " + problem);
  return out;
}

std::vector<std::string> expand_image_inputs(const std::vector<std::string>& inputs) {
  static const char* const kExtensions[] = {".png", ".jpg", ".jpeg", ".tif", ".tiff",
                                            ".bmp", ".pgm", ".ppm",  ".pnm", ".webp"};
  std::vector<std::string> files;
  for (const auto& input : inputs) {
    std::error_code ec;
    if (fs::is_directory(input, ec)) {
      std::vector<std::string> found;
      for (const auto& entry : fs::directory_iterator(input, ec)) {
        std::string ext = entry.path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(),
                       [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
        if (entry.is_regular_file() && std::any_of(std::begin(kExtensions), std::end(kExtensions),
                                                   [&](const char* e) { return ext == e; })) {
          found.push_back(entry.path().string());
        }
      }
      if (ec) fail(input + ": folder cannot be read: " + ec.message());
      std::sort(found.begin(), found.end());
      if (found.empty()) fail(input + ": folder holds no image files");
      files.insert(files.end(), found.begin(), found.end());
    } else if (fs::exists(input, ec)) {
      files.push_back(input);
    } else {
      fail(input + ": no such file or folder");
    }
  }
  return files;
}

}  // namespace laserline::tools
