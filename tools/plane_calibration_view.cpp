#include "tools/plane_calibration_view.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "daemon/config.hpp"
#include "tools/frame_channel.hpp"
#include "tools/laser_line_removal.hpp"

namespace laserline::tools {

namespace {

// A view's laser line: points within this distance (undistorted pixels) of the RANSAC line.
constexpr double kLineInlierPx = 2.0;
// Candidates closer to the board's outline than this (pixels) are left out: the line's end on
// the board's edge and the edge itself are not reliable.
constexpr double kBoardInsetPx = 6.0;
// On a laser-on image alone, the detector's points count within this distance of the band the
// line was taken out of.
constexpr int kGateMarginPx = 2;

// What the detector is told about the scanner: the nominal mount decides which way its epipolar
// lines run (columns, rows for a projector beside the camera, or at an angle).
pipeline::DetectorOptions detector_options(const PlaneCalibrationOptions& o,
                                           const hal::CameraIntrinsics& cam) {
  pipeline::DetectorOptions d;
  d.geometry = daemon::scanner_geometry(hal::Calibration{cam, o.laser_prior});
  d.frontend = o.frontend;
  return d;
}

}  // namespace

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
  // The quad-based detector first (fast); then the sector-based one, which also finds boards
  // that are small, blurred, dim or crossed by what is left of the line (a quarter of a second
  // per megapixel, more where there is no board).
  const bool found =
      cv::findChessboardCorners(grey, pattern, corners,
                                cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE) ||
      cv::findChessboardCornersSB(grey, pattern, corners,
                                  cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_EXHAUSTIVE);
  if (!found) return false;
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

// Corners the removed line covered: the band lost the squares' edges that ran along the line, so
// what was found there is where the band put them, not where they are. Each is placed instead
// by the homography of its board's neighbours outside the band (within two squares, else three:
// near enough that the lens bends them little); returns how many were.
int place_hidden_corners(std::vector<cv::Point2f>& corners, const cv::Mat& band,
                         const PlaneCalibrationOptions& o) {
  if (band.empty()) return 0;
  constexpr int kMarginPx = 2;  // cornerSubPix's gradients reach this far into the band
  cv::Mat near_band;
  cv::dilate(
      band, near_band,
      cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * kMarginPx + 1, 2 * kMarginPx + 1)));
  const int columns = o.board_columns, rows = o.board_rows;
  std::vector<char> hidden(corners.size(), 0);
  for (std::size_t i = 0; i < corners.size(); ++i) {
    const int x = cvRound(corners[i].x), y = cvRound(corners[i].y);
    hidden[i] =
        x >= 0 && y >= 0 && x < band.cols && y < band.rows && near_band.at<std::uint8_t>(y, x) != 0;
  }
  std::vector<cv::Point2f> placed = corners;
  int count = 0;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < columns; ++c) {
      const std::size_t i = static_cast<std::size_t>(r * columns + c);
      if (!hidden[i]) continue;
      for (int reach = 2; reach <= 3; ++reach) {
        std::vector<cv::Point2f> grid, image;
        std::vector<int> rows_used, columns_used;
        for (int rr = std::max(0, r - reach); rr <= std::min(rows - 1, r + reach); ++rr) {
          for (int cc = std::max(0, c - reach); cc <= std::min(columns - 1, c + reach); ++cc) {
            const std::size_t j = static_cast<std::size_t>(rr * columns + cc);
            if (hidden[j]) continue;
            grid.emplace_back(static_cast<float>(cc), static_cast<float>(rr));
            image.push_back(corners[j]);
            rows_used.push_back(rr);
            columns_used.push_back(cc);
          }
        }
        // A homography needs the neighbours to span both directions of the board.
        const auto spans = [](std::vector<int> v) {
          std::sort(v.begin(), v.end());
          return std::unique(v.begin(), v.end()) - v.begin() >= 2;
        };
        if (grid.size() < 6 || !spans(rows_used) || !spans(columns_used)) continue;
        const cv::Mat h = cv::findHomography(grid, image, 0);
        if (h.empty()) continue;
        std::vector<cv::Point2f> at;
        cv::perspectiveTransform(
            std::vector<cv::Point2f>{{static_cast<float>(c), static_cast<float>(r)}}, at, h);
        placed[i] = at[0];
        ++count;
        break;
      }
    }
  }
  corners = std::move(placed);
  return count;
}

LineFinder::LineFinder(const PlaneCalibrationOptions& o, const hal::CameraIntrinsics& cam,
                       const std::string& detector)
    : width_(cam.width), height_(cam.height) {
  const pipeline::DetectorOptions d = detector_options(o, cam);
  detector_ = pipeline::make_detector(detector, d);
  if (!detector_) throw std::invalid_argument("unknown detector");
  detector_->reset(width_, height_);
  profile_ = pipeline::Profile(detector_->max_points(width_, height_));
}

std::vector<cv::Point2d> LineFinder::find(const cv::Mat& image, bool candidates) {
  const pipeline::ImageView iv{image.data, image.cols, image.rows, static_cast<int>(image.step)};
  profile_.clear();
  detector_->reset(width_, height_);  // each view on its own: no previous frame to follow
  detector_->detect(iv, pipeline::FrameContext{0, true}, profile_);
  std::vector<cv::Point2d> points;
  for (const auto& p : profile_.points()) {
    if ((!p.valid && !candidates) || !std::isfinite(p.v)) continue;
    const auto [x, y] = profile_.image_point(p);
    points.emplace_back(x, y);
  }
  return points;
}

void find_laser(BoardView& bv, const ViewImages& images, const PlaneCalibrationOptions& o,
                const hal::CameraIntrinsics& cam, LineFinder& finder, ViewReport& report) {
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
  if (images.laser_off.empty()) {
    image = images.laser_on.clone();
  } else {
    cv::subtract(images.laser_on, images.laser_off, image);  // saturating at 0
  }
  cv::Mat outside(image.size(), CV_8UC1, cv::Scalar(255));
  std::vector<cv::Point> polygon;
  for (const auto& p : outline)
    polygon.emplace_back(cvRound(p.x), cvRound(p.y));
  cv::fillPoly(outside, std::vector<std::vector<cv::Point>>{polygon}, cv::Scalar(0));
  image.setTo(0, outside);

  // On a laser-on image alone the squares' edges compete with the line: only the points where
  // the line was found before (its band, a little wider) are the line's.
  cv::Mat near_line;
  if (bv.gated && !bv.line_band.empty()) {
    cv::dilate(bv.line_band, near_line,
               cv::getStructuringElement(cv::MORPH_ELLIPSE,
                                         cv::Size(2 * kGateMarginPx + 1, 2 * kGateMarginPx + 1)));
  }
  std::vector<cv::Point2d> raw;
  for (const auto& p : finder.find(image)) {
    const cv::Point2f at(static_cast<float>(p.x), static_cast<float>(p.y));
    if (cv::pointPolygonTest(outline, at, true) < kBoardInsetPx) continue;
    if (bv.gated) {
      const int x = cvRound(p.x), y = cvRound(p.y);
      if (near_line.empty() || x < 0 || y < 0 || x >= near_line.cols || y >= near_line.rows ||
          near_line.at<std::uint8_t>(y, x) == 0) {
        continue;
      }
    }
    raw.push_back(p);
  }
  report.laser_candidates = static_cast<int>(raw.size());
  if (raw.empty()) return;
  std::vector<cv::Point2d> undistorted;
  cv::undistortPoints(raw, undistorted, k, dist, cv::noArray(), k);

  const std::vector<std::size_t> in = straight_line_inliers(undistorted, kLineInlierPx);
  // The line's direction in the image, for its width across it.
  cv::Point2d across(0, 1);
  if (in.size() >= 2) {
    std::vector<cv::Point2f> on_line;
    for (std::size_t i : in)
      on_line.emplace_back(static_cast<float>(raw[i].x), static_cast<float>(raw[i].y));
    cv::Vec4f fitted;
    cv::fitLine(on_line, fitted, cv::DIST_L2, 0, 0.01, 0.01);
    across = cv::Point2d(-fitted[1], fitted[0]);
  }
  for (std::size_t i : in) {
    const cv::Point2d& u = undistorted[i];
    const cv::Vec3d ray((u.x - cam.cx) / cam.fx, (u.y - cam.cy) / cam.fy, 1.0);
    const double z = bv.offset / bv.normal.dot(ray);
    if (!(z > 0)) continue;
    bv.laser_px.push_back(u);
    bv.laser_xyz.push_back(ray * z);
    // The sheet's projected width is f l_w / Z (pipeline/geometry.hpp), f along the normal.
    const double f = std::hypot(cam.fx * across.x, cam.fy * across.y);
    bv.sheet_width_m.push_back(
        full_width_at_half_maximum(image, raw[i], across, o.frontend.saturation_level) * z / f);
  }
  report.laser_points = static_cast<int>(bv.laser_px.size());
}

ViewImages images_of(const CalibrationView& v, const hal::LaserChannel& laser,
                     const hal::LaserChannel& board, int clipped_from) {
  ViewImages im;
  std::string problem;
  // A 10- to 14-bit camera's 16-bit files read on its own range; the view's two images alike, so
  // that one is subtracted from the other.
  const int bits = std::max(significant_bits(v.laser_on),
                            v.laser_off.empty() ? 8 : significant_bits(v.laser_off));
  auto convert = [&](const cv::Mat& raw, const hal::LaserChannel& channel, cv::Mat& out,
                     const char* which) {
    if (!to_laser_mono8(raw, channel, clipped_from, bits, out, problem)) {
      throw PlaneCalibrationError(v.name + which + ": " + problem);
    }
  };
  convert(v.laser_on, laser, im.laser_on, "");
  convert(v.laser_on, board, im.board_on, "");
  if (!v.laser_off.empty()) {
    convert(v.laser_off, laser, im.laser_off, " (laser off)");
    convert(v.laser_off, board, im.board_off, " (laser off)");
  }
  return im;
}

}  // namespace laserline::tools
