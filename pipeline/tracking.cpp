// Tracking for the motion stage: the previous frame's features followed into the current one by
// pyramidal Lucas-Kanade (translation only), the homography fitted to the tracks, and the camera
// estimator's points followed for its relative scale.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "pipeline/motion.hpp"
#include "pipeline/motion_internal.hpp"

namespace laserline::pipeline {

using namespace motion_detail;

namespace {

// Samples a (2n+1)^2 patch of `image` centred on (x, y) with bilinear interpolation; every
// sample shares the same sub-pixel weights, so rows are interpolated once and blended. False when
// a sample would fall outside. kN: n when known at compile time (0: runtime_n), so that the loops
// over a row unroll into whole vectors.
template <int kN>
bool sample_patch(const ImageView& image, float x, float y, int runtime_n, float* out) {
  const int n = kN > 0 ? kN : runtime_n;
  const float fx = std::floor(x), fy = std::floor(y);
  if (!(fx - n >= 0 && fy - n >= 0 && fx + n + 1 < image.width && fy + n + 1 < image.height))
    return false;
  const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
  const float ax = x - fx, ay = y - fy;
  const int side = 2 * n + 1;
  std::array<float, kMaxPatch + 2> rows[2];
  const auto interpolate_row = [&](int v, float* row) {
    const std::uint8_t* p = image.row(v) + (ix - n);
    for (int i = 0; i < side; ++i) {
      const float a = p[i];
      row[i] = a + ax * (static_cast<float>(p[i + 1]) - a);
    }
  };
  float* upper = rows[0].data();
  float* lower = rows[1].data();
  interpolate_row(iy - n, upper);
  for (int j = 0; j < side; ++j) {
    interpolate_row(iy - n + j + 1, lower);
    float* o = out + j * side;
    for (int i = 0; i < side; ++i)
      o[i] = upper[i] + ay * (lower[i] - upper[i]);
    std::swap(upper, lower);
  }
  return true;
}

// Pyramidal Lucas-Kanade (translation only) of the point (pu, pv), full-size whole pixels, from
// the previous frame into the current one, coarse to fine. Below full size both frames are
// pyramid levels; at full size the previous frame is the (2r+3)^2 patch around the point kept
// when it was detected, the current frame is the frame itself. Coarse levels where the window
// does not fit are skipped; the full-size level must fit.
// kRadius: the window radius when known at compile time (0: o.window_radius).
template <int kRadius>
TrackResult track_point(const Pyramid& previous, const Pyramid& current,
                        const std::uint8_t* full_size_patch, const ImageView& frame,
                        const MotionOptions& o, float pu, float pv) {
  const int r = kRadius > 0 ? kRadius : o.window_radius;
  constexpr int kTemplateN = kRadius > 0 ? kRadius + 1 : 0;
  const int side = 2 * r + 1;
  const int patch_side = side + 2;
  std::array<float, kMaxPatch * kMaxPatch> templ;
  std::array<float, kMaxPatch * kMaxPatch> grad_x, grad_y;
  std::array<float, kMaxPatch * kMaxPatch> warped;
  float du = 0, dv = 0;  // displacement, full-size pixels
  TrackResult result;
  for (int l = o.pyramid_levels - 1; l >= 0; --l) {
    const float scale = 1.0f / static_cast<float>(1 << l);
    const ImageView cur_level = l == 0 ? frame : current.levels[l].view();
    if (l == 0) {
      for (int k = 0; k < patch_side * patch_side; ++k)
        templ[k] = full_size_patch[k];
    } else {
      const float x = (pu + 0.5f) * scale - 0.5f, y = (pv + 0.5f) * scale - 0.5f;
      if (!sample_patch<kTemplateN>(previous.levels[l].view(), x, y, r + 1, templ.data())) continue;
    }
    // Template gradients (central differences) and the 2x2 normal matrix.
    float gxx = 0, gxy = 0, gyy = 0;
    for (int j = 0; j < side; ++j) {
      const float* t = templ.data() + (j + 1) * patch_side + 1;
      float* out_x = grad_x.data() + j * side;
      float* out_y = grad_y.data() + j * side;
      for (int i = 0; i < side; ++i) {
        const float gx = 0.5f * (t[i + 1] - t[i - 1]);
        const float gy = 0.5f * (t[i + patch_side] - t[i - patch_side]);
        out_x[i] = gx;
        out_y[i] = gy;
        gxx += gx * gx;
        gxy += gx * gy;
        gyy += gy * gy;
      }
    }
    const double det = static_cast<double>(gxx) * gyy - static_cast<double>(gxy) * gxy;
    const double trace = static_cast<double>(gxx) + gyy;
    // Flat or edge-only window: this level cannot tell where the point went.
    if (!(det > 1e-6 * trace * trace) || trace < 1e-3) {
      if (l == 0) return result;
      continue;
    }
    const auto inv_det = static_cast<float>(1.0 / det);
    float cx = (pu + du + 0.5f) * scale - 0.5f, cy = (pv + dv + 0.5f) * scale - 0.5f;
    // Coarse levels only need to land within the next level's reach.
    const float stop_step = l == 0 ? kStopStep : kCoarseStopStep;
    float last_step = 1e9f;
    bool inside = true;
    for (int iteration = 0; iteration < o.max_iterations; ++iteration) {
      if (!sample_patch<kRadius>(cur_level, cx, cy, r, warped.data())) {
        inside = false;
        break;
      }
      float bx = 0, by = 0;
      for (int j = 0; j < side; ++j) {
        const float* t = templ.data() + (j + 1) * patch_side + 1;
        const float* w = warped.data() + j * side;
        const float* gx = grad_x.data() + j * side;
        const float* gy = grad_y.data() + j * side;
        for (int i = 0; i < side; ++i) {
          const float e = t[i] - w[i];
          bx += e * gx[i];
          by += e * gy[i];
        }
      }
      const float step_x = inv_det * (gyy * bx - gxy * by);
      const float step_y = inv_det * (gxx * by - gxy * bx);
      cx += step_x;
      cy += step_y;
      last_step = std::sqrt(step_x * step_x + step_y * step_y);
      if (last_step < stop_step) break;
    }
    if (!inside) {
      if (l == 0) return result;
      continue;
    }
    du = (cx + 0.5f) / scale - 0.5f - pu;
    dv = (cy + 0.5f) / scale - 0.5f - pv;
    if (l == 0) {
      result.u = pu + du;
      result.v = pv + dv;
      result.converged = last_step < kConvergedStep;
    }
  }
  return result;
}

// track_point() with the window radius of the default options fixed at compile time.
TrackResult track_point(const Pyramid& previous, const Pyramid& current,
                        const std::uint8_t* full_size_patch, const ImageView& frame,
                        const MotionOptions& o, float pu, float pv) {
  constexpr int kDefaultRadius = MotionOptions{}.window_radius;
  if (o.window_radius == kDefaultRadius) {
    return track_point<kDefaultRadius>(previous, current, full_size_patch, frame, o, pu, pv);
  }
  return track_point<0>(previous, current, full_size_patch, frame, o, pu, pv);
}

}  // namespace

MotionEstimate MotionEstimator::estimate_from_previous() {
  State& s = *state_;
  const MotionOptions& o = options_;
  MotionEstimate estimate;
  const int previous = s.previous;
  estimate.detected = s.feature_count[previous] + s.rejected_count[previous];
  estimate.rejected_on_laser = s.rejected_count[previous];

  // The tracks track_part() found, in the order of the features.
  int n = 0;
  for (int i = 0; i < s.feature_count[previous]; ++i) {
    const Point p = s.features[previous][i];
    const TrackResult t = s.feature_tracks[static_cast<std::size_t>(i)];
    if (!t.converged) continue;
    FeatureTrack& track = s.tracks[s.track_count++];
    track = FeatureTrack{p[0], p[1], t.u, t.v, false};
    s.px[n] = p[0];
    s.py[n] = p[1];
    s.cx[n] = t.u;
    s.cy[n] = t.v;
    s.all_index[n] = n;
    ++n;
  }
  estimate.tracked = n;
  if (s.has_camera) {
    const int followed = follow_points();
    estimate.camera = camera_.estimate({s.tracks.data(), static_cast<std::size_t>(s.track_count)},
                                       {s.followed.data(), static_cast<std::size_t>(followed)});
  }
  if (n < std::max(4, o.min_inliers)) return estimate;

  Homography h;
  int inliers = 0;
  if (!fit_homography(n, h, inliers)) return estimate;

  double sum_squared = 0;
  for (int i = 0; i < n; ++i) {
    s.tracks[i].inlier = s.is_inlier[i] != 0;
    if (!s.is_inlier[i]) continue;
    const auto q = h.map(s.px[i], s.py[i]);
    sum_squared += (q[0] - s.cx[i]) * (q[0] - s.cx[i]) + (q[1] - s.cy[i]) * (q[1] - s.cy[i]);
  }
  estimate.inliers = inliers;
  estimate.rms_px = static_cast<float>(std::sqrt(sum_squared / std::max(inliers, 1)));
  estimate.previous_to_current = h;
  // A frame-to-frame motion never mirrors the image: the local scale at the centre is positive.
  const double cu = 0.5 * (s.width - 1), cv = 0.5 * (s.height - 1);
  const double w = h.h(2, 0) * cu + h.h(2, 1) * cv + h.h(2, 2);
  const double determinant = to_matrix(h).determinant();
  estimate.valid = inliers >= o.min_inliers && w > 0 && determinant > 0;
  return estimate;
}

void MotionEstimator::track_part(int current, const ImageView& frame, int part) {
  State& s = *state_;
  const int previous = s.previous;
  const auto [first, end] = part_range(s.feature_count[previous], part, s.parts);
  for (int i = first; i < end; ++i) {
    const Point p = s.features[previous][i];
    s.feature_tracks[static_cast<std::size_t>(i)] =
        track_point(s.pyramids[previous], s.pyramids[current],
                    s.patches[previous].data() + static_cast<std::ptrdiff_t>(i) * s.patch_bytes,
                    frame, options_, p[0], p[1]);
  }
  if (!s.has_camera) return;
  const auto [first_followed, end_followed] = part_range(s.follow_count, part, s.parts);
  for (int k = first_followed; k < end_followed; ++k) {
    if (!s.follow_has_patch[k]) continue;
    const Point from = s.follow_pixel[k];
    s.follow_tracks[static_cast<std::size_t>(k)] =
        track_point(s.pyramids[previous], s.pyramids[current],
                    s.follow_patches.data() + static_cast<std::ptrdiff_t>(k) * s.patch_bytes, frame,
                    options_, from[0], from[1]);
  }
}

int MotionEstimator::follow_points() {
  State& s = *state_;
  constexpr float kLost = std::numeric_limits<float>::quiet_NaN();
  for (int k = 0; k < s.follow_count; ++k) {
    s.followed[k] = {kLost, kLost};
    if (!s.follow_has_patch[k]) continue;
    const Point from = s.follow_pixel[k];
    const TrackResult t = s.follow_tracks[static_cast<std::size_t>(k)];
    // The point moves like the whole pixel next to it: the same sub-pixel offset.
    if (t.converged) {
      s.followed[k] = {t.u + (s.follow_from[k][0] - from[0]),
                       t.v + (s.follow_from[k][1] - from[1])};
    }
  }
  return s.follow_count;
}

void MotionEstimator::keep_follow_patches(const ImageView& frame) {
  State& s = *state_;
  const std::span<const std::array<float, 2>> points = camera_.to_follow();
  const int n = options_.window_radius + 1;
  const int count =
      std::min(static_cast<int>(points.size()), static_cast<int>(s.follow_from.size()));
  for (int k = 0; k < count; ++k) {
    const Point p = points[k];
    const Point pixel{std::round(p[0]), std::round(p[1])};
    const int u = static_cast<int>(pixel[0]), v = static_cast<int>(pixel[1]);
    s.follow_from[k] = p;
    s.follow_pixel[k] = pixel;
    s.follow_has_patch[k] = u - n >= 0 && v - n >= 0 && u + n < s.width && v + n < s.height;
    if (!s.follow_has_patch[k]) continue;
    std::uint8_t* patch = s.follow_patches.data() + static_cast<std::ptrdiff_t>(k) * s.patch_bytes;
    for (int j = -n; j <= n; ++j) {
      std::memcpy(patch, frame.row(v + j) + (u - n), static_cast<std::size_t>(2 * n + 1));
      patch += 2 * n + 1;
    }
  }
  s.follow_count = count;
}

}  // namespace laserline::pipeline
