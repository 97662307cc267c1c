#include "tools/laser_line_removal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "tools/laser_plane_calibration.hpp"

namespace laserline::tools {

namespace {

constexpr int kLineRansacIterations = 300;
// Removal of the line before the corner search (raw pixels, the lens still in them): points
// within this distance of the course followed, at least this many of them.
constexpr double kRemovalInlierPx = 3.0;
constexpr int kMinRemovalPoints = 12;
// The band filled is at most this wide on either side of the line's centre, and ends where the
// line's brightness above its surroundings has fallen to this fraction of its peak.
constexpr int kMaxHalfWidthPx = 40;
constexpr double kWidthLevel = 0.1;
// The profile across the line has stopped falling where it falls by less than this fraction of
// the line's height per pixel.
constexpr double kFootSlope = 0.02;
// A line stands at least this high (grey levels) above its foot on either side, and on its lower
// side at least this fraction of its height on the other.
constexpr double kMinRise = 8.0;
constexpr double kRiseBalance = 0.25;

[[noreturn]] void fail(const std::string& message) {
  throw PlaneCalibrationError(message);
}

// The laser's line as a polynomial across its straight course: s = sum c_k tau^k in the frame of
// the straight line (t along it from `origin`, s along its normal), tau = (t - t_mid) / t_scale
// so that the fit is well conditioned. The lens bends a straight line into nearly a parabola
// (k1), with a fourth-order part (k2) toward the image's edges.
struct LineCourse {
  static constexpr int kTerms = 5;
  cv::Point2d origin, direction, normal;
  double t_mid = 0, t_scale = 1, t_min = 0, t_max = 0;
  cv::Vec<double, kTerms> c{};
  double rms = 0;

  double across(double t) const {
    const double tau = (t - t_mid) / t_scale;
    double s = 0;
    for (int k = kTerms - 1; k >= 0; --k)
      s = s * tau + c[k];
    return s;
  }
  cv::Point2d at(double t, double s) const { return origin + t * direction + s * normal; }
};

// The points of (t, s) within kRemovalInlierPx of the course; sets its t range and RMS.
std::vector<std::size_t> near_course(LineCourse& course, const std::vector<double>& t,
                                     const std::vector<double>& s) {
  std::vector<std::size_t> near;
  double sq = 0;
  course.t_min = 1e300;
  course.t_max = -1e300;
  for (std::size_t i = 0; i < t.size(); ++i) {
    const double r = s[i] - course.across(t[i]);
    if (std::abs(r) > kRemovalInlierPx) continue;
    near.push_back(i);
    sq += r * r;
    course.t_min = std::min(course.t_min, t[i]);
    course.t_max = std::max(course.t_max, t[i]);
  }
  course.rms = near.empty() ? 0.0 : std::sqrt(sq / static_cast<double>(near.size()));
  return near;
}

// Least squares of the course's polynomial (`terms` of them) through the points `use`.
void fit_course(LineCourse& course, const std::vector<double>& t, const std::vector<double>& s,
                const std::vector<std::size_t>& use, int terms) {
  double lo = 1e300, hi = -1e300;
  for (std::size_t i : use) {
    lo = std::min(lo, t[i]);
    hi = std::max(hi, t[i]);
  }
  course.t_mid = 0.5 * (lo + hi);
  course.t_scale = std::max(0.5 * (hi - lo), 1.0);
  cv::Mat a(static_cast<int>(use.size()), terms, CV_64F),
      b(static_cast<int>(use.size()), 1, CV_64F);
  for (std::size_t k = 0; k < use.size(); ++k) {
    const double tau = (t[use[k]] - course.t_mid) / course.t_scale;
    double power = 1.0;
    for (int j = 0; j < terms; ++j, power *= tau)
      a.at<double>(static_cast<int>(k), j) = power;
    b.at<double>(static_cast<int>(k)) = s[use[k]];
  }
  cv::Mat c;
  cv::solve(a, b, c, cv::DECOMP_SVD);
  course.c = {};
  for (int j = 0; j < terms; ++j)
    course.c[j] = c.at<double>(j);
}

// The line's course through `points`, or false when fewer than kMinRemovalPoints lie on one.
// The frame is the straight line through most points; the parabola through most points in that
// frame (RANSAC: a distorted line may leave the straight one's tolerance long before its ends),
// refined by least squares.
bool follow_line(const std::vector<cv::Point2d>& points, LineCourse& course,
                 std::vector<std::size_t>& near) {
  const std::vector<std::size_t> straight = straight_line_inliers(points, kRemovalInlierPx);
  if (static_cast<int>(straight.size()) < kMinRemovalPoints) return false;
  std::vector<cv::Point2f> fit;
  for (std::size_t i : straight)
    fit.emplace_back(static_cast<float>(points[i].x), static_cast<float>(points[i].y));
  cv::Vec4f line;
  cv::fitLine(fit, line, cv::DIST_L2, 0, 0.01, 0.01);
  course.origin = cv::Point2d(line[2], line[3]);
  course.direction = cv::Point2d(line[0], line[1]);
  course.normal = cv::Point2d(-line[1], line[0]);
  std::vector<double> t(points.size()), s(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const cv::Point2d d = points[i] - course.origin;
    t[i] = d.dot(course.direction);
    s[i] = d.dot(course.normal);
  }
  near = near_course(course, t, s);  // the straight line itself (c = 0)
  cv::RNG rng(0x636f7572);           // fixed: the same views give the same calibration
  const int count = static_cast<int>(points.size());
  for (int k = 0; k < kLineRansacIterations; ++k) {
    std::vector<std::size_t> three = {static_cast<std::size_t>(rng.uniform(0, count)),
                                      static_cast<std::size_t>(rng.uniform(0, count)),
                                      static_cast<std::size_t>(rng.uniform(0, count))};
    std::sort(three.begin(), three.end(),
              [&](std::size_t i, std::size_t j) { return t[i] < t[j]; });
    if (t[three[1]] - t[three[0]] < 10.0 || t[three[2]] - t[three[1]] < 10.0) continue;
    LineCourse trial = course;
    fit_course(trial, t, s, three, 3);
    std::vector<std::size_t> in = near_course(trial, t, s);
    if (in.size() > near.size()) {
      near = std::move(in);
      course = trial;
    }
  }
  for (int round = 0; round < 5 && static_cast<int>(near.size()) >= kMinRemovalPoints; ++round) {
    fit_course(course, t, s, near, near.size() >= 30 ? LineCourse::kTerms : 3);
    std::vector<std::size_t> next = near_course(course, t, s);
    const bool same = next == near;
    near = std::move(next);
    if (same) break;
  }
  return static_cast<int>(near.size()) >= kMinRemovalPoints;
}

// The mean brightness across a line (over its length, so that the squares average out) at each
// offset from its centre: how high it stands above its feet on either side, and how far out it
// reaches (where it has fallen to kWidthLevel of its height above its foot).
struct AcrossLine {
  double rise[2] = {0, 0};
  int reach[2] = {0, 0};
};

AcrossLine across_line(const cv::Mat& image, const LineCourse& course) {
  constexpr int kS = kMaxHalfWidthPx;
  std::vector<double> profile(2 * kS + 1, 0.0);
  int lengthwise = 0;
  for (double t = course.t_min; t <= course.t_max; t += 2.0, ++lengthwise) {
    const double centre = course.across(t);
    for (int s = -kS; s <= kS; ++s) {
      const cv::Point2d p = course.at(t, centre + s);
      profile[static_cast<std::size_t>(s + kS)] += sample_bilinear(image, p.x, p.y);
    }
  }
  for (double& v : profile)
    v /= std::max(lengthwise, 1);
  const int spread = static_cast<int>(std::ceil(2.0 * course.rms));
  double peak = 0;
  for (int s = -1 - spread; s <= 1 + spread; ++s)
    peak = std::max(peak, profile[static_cast<std::size_t>(s + kS)]);
  AcrossLine a;
  for (int side = 0; side < 2; ++side) {
    const int sign = side == 0 ? -1 : 1;
    const auto at = [&](int k) { return profile[static_cast<std::size_t>(kS + sign * k)]; };
    double lowest = peak;
    for (int k = 1; k <= kS; ++k)
      lowest = std::min(lowest, at(k));
    // The line's foot: past its upper half, where the profile stops falling (what lies beyond,
    // e.g. the dark edge of the board, is not the line's).
    const double flat = kFootSlope * (peak - lowest);
    int foot = kS;
    for (int k = 1; k <= kS; ++k) {
      if (at(k) < 0.5 * (peak + lowest) && at(k) > at(k - 1) - flat) {
        foot = k - 1;
        break;
      }
    }
    a.rise[side] = peak - at(foot);
    const double level = at(foot) + kWidthLevel * a.rise[side];
    a.reach[side] = foot;
    for (int k = 1; k <= foot; ++k) {
      if (at(k) <= level) {
        a.reach[side] = k;
        break;
      }
    }
  }
  return a;
}

}  // namespace

std::vector<std::size_t> straight_line_inliers(const std::vector<cv::Point2d>& points,
                                               double tolerance) {
  std::vector<std::size_t> best;
  if (points.size() < 2) return best;
  cv::RNG rng(0x6c617365);  // fixed: the same views give the same calibration
  auto inliers_of = [&](const cv::Point2d& p, const cv::Point2d& direction) {
    std::vector<std::size_t> in;
    const cv::Point2d n(-direction.y, direction.x);
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (std::abs((points[i] - p).dot(n)) <= tolerance) in.push_back(i);
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

double sample_bilinear(const cv::Mat& image, double x, double y) {
  x = std::clamp(x, 0.0, image.cols - 1.001);
  y = std::clamp(y, 0.0, image.rows - 1.001);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const double fx = x - x0, fy = y - y0;
  const std::uint8_t* r0 = image.ptr<std::uint8_t>(y0) + x0;
  const std::uint8_t* r1 = image.ptr<std::uint8_t>(y0 + 1) + x0;
  return (1 - fy) * ((1 - fx) * r0[0] + fx * r0[1]) + fy * ((1 - fx) * r1[0] + fx * r1[1]);
}

double full_width_at_half_maximum(const cv::Mat& image, cv::Point2d p, cv::Point2d normal,
                                  double saturation, double peak_within_px) {
  constexpr double kStep = 0.25;
  constexpr int kReach = static_cast<int>(kMaxHalfWidthPx / kStep);
  auto at = [&](int k) {
    const cv::Point2d q = p + normal * (k * kStep);
    if (q.x < 0 || q.y < 0 || q.x > image.cols - 2 || q.y > image.rows - 2) {
      return std::numeric_limits<double>::quiet_NaN();
    }
    return sample_bilinear(image, q.x, q.y);
  };
  int centre = 0;
  double peak = -1;
  const int peak_reach =
      static_cast<int>(std::clamp(peak_within_px, 0.0, 0.5 * kMaxHalfWidthPx) / kStep);
  for (int k = -peak_reach; k <= peak_reach; ++k) {
    const double v = at(k);
    if (v > peak) {
      peak = v;
      centre = k;
    }
  }
  if (!(peak >= 0) || peak >= saturation) return std::numeric_limits<double>::quiet_NaN();
  // Each side's floor: where the profile stops falling (beyond lies other light).
  double floor_level[2] = {peak, peak};
  for (const int side : {0, 1}) {
    const int sign = side == 0 ? -1 : 1;
    double lowest = peak;
    for (int k = 1; k <= kReach; ++k) {
      const double v = at(centre + sign * k);
      if (!(v <= lowest + 0.5)) break;  // rising again, or off the image
      lowest = std::min(lowest, v);
    }
    floor_level[side] = lowest;
  }
  if (!(peak - std::max(floor_level[0], floor_level[1]) >= kMinRise)) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  // Each side half way down from the peak to its own floor: a line at the end of a glow (the
  // water in front of the surface lit by the sheet) or beside a brighter surface stands higher on
  // that side, and half way down to the other side's floor would lie out in the glow.
  double width = 0;
  for (const int side : {0, 1}) {
    const int sign = side == 0 ? -1 : 1;
    const double half = 0.5 * (peak + floor_level[side]);
    double previous = peak, crossing = std::numeric_limits<double>::quiet_NaN();
    for (int k = 1; k <= kReach; ++k) {
      const double v = at(centre + sign * k);
      if (std::isnan(v)) break;
      if (v <= half) {
        crossing = (k - 1 + (previous - half) / std::max(previous - v, 1e-9)) * kStep;
        break;
      }
      previous = v;
    }
    if (std::isnan(crossing)) return crossing;
    width += crossing;
  }
  return width;
}

LineRemoval remove_laser_line(const cv::Mat& board, const cv::Mat& laser,
                              const std::vector<cv::Point2d>& points, cv::Mat& out) {
  if (board.type() != CV_8UC1 || laser.type() != CV_8UC1 || board.size() != laser.size() ||
      board.cols < 2 || board.rows < 2) {
    fail("remove_laser_line: the board and laser images must be mono8 of one size, at least 2x2");
  }
  LineRemoval removal;
  out = board.clone();
  LineCourse course;
  std::vector<std::size_t> near;
  if (!follow_line(points, course, near)) return removal;
  // A laser line stands out of its surroundings on both sides in its own light; a step (the
  // board's edge) or a row of squares' edges taken for one does not.
  const AcrossLine light = across_line(laser, course);
  const double low = std::min(light.rise[0], light.rise[1]);
  const double high = std::max(light.rise[0], light.rise[1]);
  if (!(low >= kMinRise && low >= kRiseBalance * high)) return removal;
  // Its width where it matters, in the board's image.
  const AcrossLine seen = across_line(board, course);
  for (int side = 0; side < 2; ++side) {
    // One pixel more for the tail below the level, and the course's own scatter.
    removal.half_width_px[side] =
        std::min(static_cast<double>(kMaxHalfWidthPx), seen.reach[side] + 1.0 + 2.0 * course.rms);
  }

  // The band, filled along the normal from its two sides. It runs a half width beyond the
  // points found, where the line fades out.
  const double h0 = removal.half_width_px[0], h1 = removal.half_width_px[1];
  const double t0 = course.t_min - std::max(h0, h1), t1 = course.t_max + std::max(h0, h1);
  std::vector<cv::Point2f> hull;
  for (double t = t0;; t += 4.0) {
    const double tt = std::min(t, t1), centre = course.across(tt);
    const cv::Point2d a = course.at(tt, centre - h0 - 1), b = course.at(tt, centre + h1 + 1);
    hull.emplace_back(static_cast<float>(a.x), static_cast<float>(a.y));
    hull.emplace_back(static_cast<float>(b.x), static_cast<float>(b.y));
    if (tt >= t1) break;
  }
  const cv::Rect box = cv::boundingRect(hull) & cv::Rect(0, 0, board.cols, board.rows);
  removal.band = cv::Mat::zeros(board.size(), CV_8UC1);
  for (int y = box.y; y < box.y + box.height; ++y) {
    std::uint8_t* row = out.ptr<std::uint8_t>(y);
    std::uint8_t* filled = removal.band.ptr<std::uint8_t>(y);
    for (int x = box.x; x < box.x + box.width; ++x) {
      const cv::Point2d d = cv::Point2d(x, y) - course.origin;
      const double t = d.dot(course.direction);
      if (t < t0 || t > t1) continue;
      const double centre = course.across(t);
      const double s = d.dot(course.normal) - centre;
      if (s < -h0 || s > h1) continue;
      const double lo = -h0 - 1, hi = h1 + 1;
      const cv::Point2d a = course.at(t, centre + lo), b = course.at(t, centre + hi);
      const double w = (s - lo) / (hi - lo);
      row[x] = cv::saturate_cast<std::uint8_t>((1 - w) * sample_bilinear(board, a.x, a.y) +
                                               w * sample_bilinear(board, b.x, b.y));
      filled[x] = 255;
    }
  }
  removal.points = static_cast<int>(near.size());
  return removal;
}

}  // namespace laserline::tools
