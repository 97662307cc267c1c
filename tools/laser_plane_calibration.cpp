// Laser-plane calibration (laser_plane_calibration.hpp): the intrinsics, the boards' poses, the
// line's points on the boards in 3-D and the plane through them. Each view's images, corners and
// line are found in plane_calibration_view.cpp, the line's removal from a board image in
// laser_line_removal.cpp, the files in laser_plane_calibration_files.cpp. Over 600 lines:
// calibrate_laser_plane runs its stages in turn on the views' shared state (corners, poses, the
// line's points), each leaving views out.
#include "tools/laser_plane_calibration.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <numbers>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "tools/laser_line_removal.hpp"
#include "tools/plane_calibration_view.hpp"

namespace laserline::tools {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
// Boards whose normals differ by less than this are parallel for the purpose of calibration.
constexpr double kMinPoseSpreadDeg = 3.0;
// A view needs this many points on its line to take part.
constexpr int kMinLinePoints = 20;
// A board seen more obliquely than this gives its line's points as rays that graze it: a small
// error in the pose moves them far along the board.
constexpr double kMaxTiltDeg = 75.0;
// A view's line agrees with a plane when its points lie within this distance (pixels, median) of
// the line where the plane meets its board.
constexpr double kAgreePx = 3.0;

[[noreturn]] void fail(const std::string& message) {
  throw PlaneCalibrationError(message);
}

std::string format(const char* fmt, double a, double b = 0, double c = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
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

// "3 without a 9x6 checkerboard, 1 without the laser line on the board": how many views were
// left out for each reason.
std::string tally(const std::vector<std::string>& reasons) {
  std::map<std::string, int> count;
  std::vector<std::string> order;
  for (const auto& r : reasons) {
    if (r.empty()) continue;
    if (count[r]++ == 0) order.push_back(r);
  }
  std::string out;
  for (const auto& r : order)
    out += (out.empty() ? "" : ", ") + std::to_string(count[r]) + " " + r;
  return out;
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
  const auto detectors = pipeline::detector_names();
  if (std::find(detectors.begin(), detectors.end(), o.detector) == detectors.end()) {
    std::string known;
    for (const auto& d : detectors)
      known += (known.empty() ? "" : ", ") + d;
    fail("unknown detector " + o.detector + " (known: " + known + ")");
  }
  if (views.size() < 2) {
    fail("need at least 2 views (board poses that are not parallel), got " +
         std::to_string(views.size()));
  }
  const cv::Size size = views.front().laser_on.size();
  for (const auto& v : views) {
    if (v.laser_on.empty()) fail(v.name + ": empty image");
    if (v.laser_on.size() != size) {
      fail(v.name + ": image size " + std::to_string(v.laser_on.cols) + "x" +
           std::to_string(v.laser_on.rows) + " differs from the first view's " +
           std::to_string(size.width) + "x" + std::to_string(size.height));
    }
    if (!v.laser_off.empty() &&
        (v.laser_off.size() != size || v.laser_off.type() != v.laser_on.type())) {
      fail(v.name + ": its laser-off image differs in size or type from the laser-on image");
    }
  }
  if (size.width < 16 || size.height < 16) {
    fail(views.front().name + ": image smaller than 16x16");
  }
  if (o.intrinsics && (o.intrinsics->width != size.width || o.intrinsics->height != size.height)) {
    fail("the images are " + std::to_string(size.width) + "x" + std::to_string(size.height) +
         " but the given intrinsics are for " + std::to_string(o.intrinsics->width) + "x" +
         std::to_string(o.intrinsics->height));
  }
  // The board is black and white, so it is in every channel of a colour image: luma (mostly
  // green, two of a Bayer sensor's four sites) gives it with the least noise. The laser's part of
  // luma is taken out with the line. (The channels without the laser found fewer real boards:
  // dim blue is noisy.)
  const hal::LaserChannel board_light = hal::parse_laser_channel("grey");
  const std::string pattern = std::to_string(o.board_columns) + "x" + std::to_string(o.board_rows);

  PlaneCalibrationResult result;
  result.views.resize(views.size());
  // Why each view does not contribute to the plane, as counted in a fatal error's summary.
  std::vector<std::string> left_out(views.size());
  auto skip = [&](std::size_t i, const std::string& why, const std::string& kind) {
    result.views[i].skipped = why;
    left_out[i] = kind;
    if (o.on_skip) o.on_skip(views[i].name + ": " + why);
  };
  for (std::size_t i = 0; i < views.size(); ++i)
    result.views[i].name = views[i].name;

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
  std::vector<ViewImages> images(views.size());
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
      skip(i,
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

  // Board poses.
  const cv::Matx33d k = camera_matrix(cam);
  const cv::Mat dist(cam.distortion, false);
  double corner_sq = 0;
  std::size_t corner_count = 0;
  std::vector<BoardView> posed;
  for (BoardView& b : boards) {
    ViewReport& r = result.views[b.index];
    if (!cv::solvePnP(object, b.corners, k, dist, b.rvec, b.tvec, false, cv::SOLVEPNP_ITERATIVE)) {
      skip(b.index, "the board's pose could not be estimated", "whose board's pose failed");
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
         std::to_string(views.size()) + " views, need at least 2: " + tally(left_out));
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
  std::optional<LineFinder> finder;
  try {
    finder.emplace(o, cam, o.detector);
  } catch (const std::invalid_argument& e) {
    fail("detector " + o.detector + ": " + e.what());
  }

  std::vector<cv::Vec3d> points;
  std::vector<int> view_of;  // index into boards
  int views_with_line = 0;
  for (std::size_t i = 0; i < boards.size(); ++i) {
    BoardView& b = boards[i];
    ViewReport& r = result.views[b.index];
    if (r.tilt_deg > kMaxTiltDeg) {
      skip(b.index,
           format("the board is seen nearly edge-on (tilted %.0f deg, at most %.0f)", r.tilt_deg,
                  kMaxTiltDeg),
           "with the board seen edge-on");
      continue;
    }
    find_laser(b, images[b.index], o, cam, *finder, r);
    if (static_cast<int>(b.laser_xyz.size()) < kMinLinePoints) {
      if (r.laser_candidates == 0) {
        skip(b.index, "no laser line on the board", "without the laser line on the board");
      } else {
        skip(b.index,
             "too few points on the laser line (" + std::to_string(b.laser_xyz.size()) + ", need " +
                 std::to_string(kMinLinePoints) + ")",
             "with too few points on the line");
      }
      b.laser_xyz.clear();
      b.laser_px.clear();
      r.laser_points = 0;
      continue;
    }
    ++views_with_line;
    for (const auto& p : b.laser_xyz) {
      points.push_back(p);
      view_of.push_back(static_cast<int>(i));
    }
  }
  if (views_with_line < 2) {
    fail("the laser line was found on the board in " + std::to_string(views_with_line) + " of " +
         std::to_string(views.size()) + " views, need at least 2: " + tally(left_out));
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
  // The views whose lines agree on one plane, found before any least squares: a view that took
  // something else for the line would pull a fit toward it, and several such views could
  // outweigh the rest. Of the planes through the lines of two views, the one most points agree
  // with: a view agrees when its points lie, in the median, within kAgreePx of the line where the
  // plane meets its board in the image.
  {
    std::vector<std::size_t> first(boards.size(), 0), count(boards.size(), 0);
    for (std::size_t i = points.size(); i-- > 0;) {
      first[static_cast<std::size_t>(view_of[i])] = i;
      ++count[static_cast<std::size_t>(view_of[i])];
    }
    auto median_px = [&](std::size_t v, const Plane& p) {
      const BoardView& b = boards[v];
      const cv::Vec3d m = b.offset * p.normal + p.e * b.normal;
      const cv::Vec3d m_px = k.inv().t() * m;
      const double norm = std::hypot(m_px[0], m_px[1]);
      std::vector<double> d;
      for (const auto& u : b.laser_px)
        d.push_back(std::abs(m_px[0] * u.x + m_px[1] * u.y + m_px[2]) / norm);
      return median(d);
    };
    std::vector<std::size_t> lined;
    for (std::size_t v = 0; v < boards.size(); ++v) {
      if (count[v] > 0) lined.push_back(v);
    }
    std::vector<char> agree(boards.size(), 0), best(boards.size(), 0);
    std::size_t best_points = 0;
    std::vector<char> pair(points.size());
    for (std::size_t i = 0; i < lined.size(); ++i) {
      for (std::size_t j = i + 1; j < lined.size(); ++j) {
        std::fill(pair.begin(), pair.end(), 0);
        for (std::size_t v : {lined[i], lined[j]})
          std::fill_n(pair.begin() + static_cast<std::ptrdiff_t>(first[v]), count[v], 1);
        cv::Vec3d centroid;
        cv::Matx31d spread_values;
        cv::eigen(scatter_of(points, pair, centroid), spread_values);
        if (!(spread_values(1) > 1e-4 * spread_values(0))) continue;  // the two lines are one
        const Plane trial = fit_plane(points, pair);
        std::size_t agreeing = 0;
        for (std::size_t v : lined) {
          agree[v] = median_px(v, trial) <= kAgreePx;
          agreeing += agree[v] ? count[v] : 0;
        }
        if (agreeing > best_points) {
          best_points = agreeing;
          best = agree;
        }
      }
    }
    int remaining = 0;
    for (std::size_t v : lined) {
      if (best[v]) {
        ++remaining;
        continue;
      }
      std::fill_n(allowed.begin() + static_cast<std::ptrdiff_t>(first[v]), count[v], 0);
    }
    if (remaining < 2) {
      fail(
          "the laser lines found do not lie on one plane (no 2 views agree): check that the "
          "line crosses the board in every view, or give --laser-off images; " +
          tally(left_out));
    }
    robust_fit();
    for (std::size_t v : lined) {
      if (best[v]) continue;
      skip(boards[v].index,
           format("its laser line is off the plane the other views agree on (%.1f px from it "
                  "in the median): something else was taken for the line",
                  median_px(v, plane)),
           "with the line off the plane");
    }
  }
  // A view whose line is mostly off the plane even so saw something else as the line (e.g. a
  // square's edge beside it): it is left out whole, and the plane fitted again.
  {
    std::vector<int> total(boards.size(), 0), kept(boards.size(), 0);
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (!allowed[i]) continue;
      ++total[static_cast<std::size_t>(view_of[i])];
      kept[static_cast<std::size_t>(view_of[i])] += use[i] ? 1 : 0;
    }
    bool dropped = false;
    int remaining = 0;
    for (std::size_t v = 0; v < boards.size(); ++v) {
      if (total[v] == 0) continue;
      if (2 * kept[v] < total[v]) {
        dropped = true;
        skip(boards[v].index,
             "its laser line is off the plane the other views agree on (" +
                 std::to_string(kept[v]) + " of " + std::to_string(total[v]) +
                 " points on it): something else was taken for the line",
             "with the line off the plane");
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
          "that the line crosses the board in every view, or give --laser-off images; " +
          tally(left_out));
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
  std::vector<double> widths;  // of the inliers whose width could be measured
  result.depth_min_m = std::numeric_limits<double>::infinity();
  result.depth_max_m = 0;
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
      if (std::isfinite(b.sheet_width_m[j])) widths.push_back(b.sheet_width_m[j]);
      result.depth_min_m = std::min(result.depth_min_m, b.laser_xyz[j][2]);
      result.depth_max_m = std::max(result.depth_max_m, b.laser_xyz[j][2]);
      sq_mm += mm * mm;
      sq_px += px * px;
      view_sq[i] += mm * mm;
      result.plane_max_mm = std::max(result.plane_max_mm, mm);
      result.plane_max_px = std::max(result.plane_max_px, px);
      ++inliers;
      ++result.views[b.index].plane_inliers;
    }
  }
  result.inliers = inliers;
  result.plane_rms_mm = std::sqrt(sq_mm / inliers);
  result.plane_rms_px = std::sqrt(sq_px / inliers);
  for (std::size_t i = 0; i < boards.size(); ++i) {
    ViewReport& r = result.views[boards[i].index];
    r.plane_rms_mm = r.plane_inliers > 0 ? std::sqrt(view_sq[i] / r.plane_inliers) : 0.0;
  }
  result.normal_angle_to_y_deg = std::acos(std::clamp(std::abs(plane.normal[1]), 0.0, 1.0)) / kDeg;

  result.calibration.camera = cam;
  hal::LaserMount& laser = result.calibration.laser;
  laser = o.laser_prior;
  laser.plane = Eigen::Vector4d{plane.normal[0], plane.normal[1], plane.normal[2], plane.e};
  // The sheet's width as the camera sees it (its thickness, blurred by the optics): the
  // front-end's band-pass is made for it. A third of the inliers must give it.
  result.width_points = static_cast<int>(widths.size());
  if (o.measure_sheet_width && 3 * widths.size() >= static_cast<std::size_t>(inliers)) {
    result.sheet_width_measured = true;
    laser.sheet_width_m = std::clamp(median(widths), 1e-5, 0.1);
  }
  // The paper's model Y = -d + tan(90 deg - beta) Z with the sheet along x, turned to the side
  // of the camera the projector is on: the axis the plane's normal leans to most (y above or
  // below, x left or right; e > 0 gives the sign). d where the plane crosses that axis, beta
  // from its slope toward the optical axis. Kept within the file's limits.
  const double a = plane.normal[0], b = plane.normal[1];
  double along = 0;
  if (std::abs(b) >= std::abs(a)) {
    laser.side = b > 0 ? hal::LaserSide::kAbove : hal::LaserSide::kBelow;
    along = std::abs(b);
  } else {
    laser.side = a > 0 ? hal::LaserSide::kLeft : hal::LaserSide::kRight;
    along = std::abs(a);
  }
  const double baseline = along > 0 ? plane.e / along : 0.0;
  const double angle = 90.0 - std::atan2(-plane.normal[2], along) / kDeg;
  result.fits_baseline_model = baseline >= 1e-3 && baseline <= 10 && angle >= 1 && angle <= 179;
  laser.baseline_m = std::clamp(baseline, 1e-3, 10.0);
  laser.angle_deg = std::clamp(angle, 1.0, 179.0);
  return result;
}

}  // namespace laserline::tools
