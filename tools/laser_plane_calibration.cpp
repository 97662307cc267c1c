// calibrate_laser_plane: its input checked, then the stages in turn (plane_calibration_stages.hpp).
#include "tools/laser_plane_calibration.hpp"

#include <algorithm>
#include <cstdio>
#include <map>
#include <optional>

#include "tools/plane_calibration_stages.hpp"
#include "tools/plane_calibration_view.hpp"

namespace laserline::tools {

namespace {

// A view needs this many points on its line to take part.
constexpr int kMinLinePoints = 20;
// A board seen more obliquely than this gives its line's points as rays that graze it: a small
// error in the pose moves them far along the board.
constexpr double kMaxTiltDeg = 75.0;

// The laser line on each posed board, in 3-D; boards whose line is not found are left out.
LinePoints find_lines(CalibrationRun& run, std::vector<BoardView>& boards,
                      const std::vector<ViewImages>& images, const hal::CameraIntrinsics& cam) {
  const PlaneCalibrationOptions& o = run.options;
  std::optional<LineFinder> finder;
  try {
    finder.emplace(o, cam, o.detector);
  } catch (const std::invalid_argument& e) {
    fail("detector " + o.detector + ": " + e.what());
  }

  LinePoints points;
  int views_with_line = 0;
  for (std::size_t i = 0; i < boards.size(); ++i) {
    BoardView& b = boards[i];
    ViewReport& r = run.result.views[b.index];
    if (r.tilt_deg > kMaxTiltDeg) {
      run.skip(b.index,
               format("the board is seen nearly edge-on (tilted %.0f deg, at most %.0f)",
                      r.tilt_deg, kMaxTiltDeg),
               "with the board seen edge-on");
      continue;
    }
    find_laser(b, images[b.index], o, cam, *finder, r);
    if (static_cast<int>(b.laser_xyz.size()) < kMinLinePoints) {
      if (r.laser_candidates == 0) {
        run.skip(b.index, "no laser line on the board", "without the laser line on the board");
      } else {
        run.skip(b.index,
                 "too few points on the laser line (" + std::to_string(b.laser_xyz.size()) +
                     ", need " + std::to_string(kMinLinePoints) + ")",
                 "with too few points on the line");
      }
      b.laser_xyz.clear();
      b.laser_px.clear();
      r.laser_points = 0;
      continue;
    }
    ++views_with_line;
    for (const auto& p : b.laser_xyz) {
      points.xyz.push_back(p);
      points.view_of.push_back(static_cast<int>(i));
    }
  }
  if (views_with_line < 2) {
    fail("the laser line was found on the board in " + std::to_string(views_with_line) + " of " +
         std::to_string(run.views.size()) + " views, need at least 2: " + run.tally());
  }
  return points;
}

}  // namespace

void fail(const std::string& message) {
  throw PlaneCalibrationError(message);
}

std::string format(const char* fmt, double a, double b, double c) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

CalibrationRun::CalibrationRun(const std::vector<CalibrationView>& calibration_views,
                               const PlaneCalibrationOptions& calibration_options)
    : views(calibration_views), options(calibration_options), left_out(calibration_views.size()) {
  result.views.resize(views.size());
  for (std::size_t i = 0; i < views.size(); ++i)
    result.views[i].name = views[i].name;
}

void CalibrationRun::skip(std::size_t i, const std::string& why, const std::string& kind) {
  result.views[i].skipped = why;
  left_out[i] = kind;
  if (options.on_skip) options.on_skip(views[i].name + ": " + why);
}

std::string CalibrationRun::tally() const {
  std::map<std::string, int> count;
  std::vector<std::string> order;
  for (const auto& r : left_out) {
    if (r.empty()) continue;
    if (count[r]++ == 0) order.push_back(r);
  }
  std::string out;
  for (const auto& r : order)
    out += (out.empty() ? "" : ", ") + std::to_string(count[r]) + " " + r;
  return out;
}

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
  CalibrationRun run(views, o);
  std::vector<ViewImages> images(views.size());
  std::vector<BoardView> boards = find_boards(run, size, images);
  const hal::CameraIntrinsics cam = board_intrinsics(run, boards, size);
  pose_boards(run, boards, cam);
  const LinePoints points = find_lines(run, boards, images, cam);
  run.result.points = static_cast<int>(points.xyz.size());
  std::vector<char> use;
  const Plane plane = fit_laser_plane(run, boards, points, cam, use);
  report_plane(run, boards, plane, use, cam);
  return std::move(run.result);
}

}  // namespace laserline::tools
