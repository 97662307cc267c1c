// The laser plane through the lines' points, fitted to the views that agree on one plane.
#include <algorithm>
#include <cmath>

#include "tools/plane_calibration_stages.hpp"

namespace laserline::tools {

namespace {

// A view's line agrees with a plane when its points lie within this distance (pixels, median) of
// the line where the plane meets its board.
constexpr double kAgreePx = 3.0;

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

}  // namespace

Plane fit_laser_plane(CalibrationRun& run, const std::vector<BoardView>& boards,
                      const LinePoints& line_points, const hal::CameraIntrinsics& cam,
                      std::vector<char>& use) {
  const std::vector<cv::Vec3d>& points = line_points.xyz;
  const std::vector<int>& view_of = line_points.view_of;
  const cv::Matx33d k = camera_matrix(cam);
  // Plane fit with outlier rejection: 3 robust sigmas (MAD), at least 0.1 mm, until stable.
  std::vector<char> allowed(points.size(), 1);
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
          run.tally());
    }
    robust_fit();
    for (std::size_t v : lined) {
      if (best[v]) continue;
      run.skip(boards[v].index,
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
        run.skip(boards[v].index,
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
          run.tally());
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
  return plane;
}

}  // namespace laserline::tools
