#include "pipeline/validation.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <utility>

namespace laserline::pipeline {

namespace {

// The descriptor correlated is, per column, the segment's presence (1) and its chain code times
// this weight: straight segments (texture edges, flat walls) then match by their extent, curved
// ones by their shape as well. A step of 0.5 px weighs as much as the presence.
constexpr double kChainCodeWeight = 4.0;
// Steps are counted up to this (pixels): a segment joined to a neighbour (a texture artefact, a
// stretch beyond a depth jump) steps by up to max_neighbour_gap_px where it joins, which the
// segment found in the other frame, joined elsewhere, does not; counted in full, that one step
// outweighs hundreds of columns that agree.
constexpr float kChainCodeStepLimit = 1.0f;
constexpr double kShiftMargin = 0.05;

// Whether the bounding boxes of a and b lie more than `distance` apart.
bool boxes_farther_than(const LineSegment& a, const LineSegment& b, double distance) {
  const double du = std::max({0, a.u_min - b.u_max, b.u_min - a.u_max});
  const double dv = std::max({0.0f, a.v_min - b.v_max, b.v_min - a.v_max});
  // hypot(du, dv) is at least the larger of them, rounded too: most pairs of a frame's segments
  // are told apart without it (it was a tenth of `backprojection`'s time).
  if (du > distance || dv > distance) return true;
  return std::hypot(du, dv) > distance;
}

using Vector3 = Eigen::Vector3d;

}  // namespace

// ---------------------------------------------------------------------------------------------
// IV-B

void SegmentedFrame::reset(std::size_t max_points, double max_gap_px) {
  points.reserve(max_points);
  segments.reserve(max_points);
  // A segment spans at most max_gap columns per candidate.
  const auto span = static_cast<std::size_t>(std::ceil(std::max(max_gap_px, 1.0)));
  rows.reserve(max_points * span + 1);
  chain_code.reserve(max_points * span + 1);
  clear();
}

void SegmentedFrame::clear() {
  points.clear();
  segments.clear();
  rows.clear();
  chain_code.clear();
}

void SegmentationScratch::reset(std::size_t max_points) {
  for (std::vector<int>* v : {&order, &next, &head, &tail, &count, &active, &active_u})
    v->assign(max_points, 0);
  active_v.assign(max_points, 0.0f);
}

void segment_candidates(const Profile& profile, const ValidationOptions& options,
                        SegmentedFrame& out, SegmentationScratch& scratch) {
  out.clear();
  const std::vector<ProfilePoint>& pts = profile.points();
  const int n = static_cast<int>(
      std::min({pts.size(), scratch.order.size(), out.points.capacity(), out.segments.capacity()}));
  int* order = scratch.order.data();
  for (int i = 0; i < n; ++i)
    order[i] = i;
  auto before = [&pts](int a, int b) {
    return pts[a].u != pts[b].u ? pts[a].u < pts[b].u : pts[a].v < pts[b].v;
  };
  // The front-ends give their candidates by column; sort only when they do not.
  if (!std::is_sorted(order, order + n, before)) std::sort(order, order + n, before);

  // Link each candidate to the nearest segment end within the gap in an earlier column.
  const double gap = options.max_neighbour_gap_px;
  const double gap2 = gap * gap;
  const int column_gap = static_cast<int>(std::floor(gap));
  int* next = scratch.next.data();
  int* head = scratch.head.data();
  int* tail = scratch.tail.data();
  int* count = scratch.count.data();
  int* active = scratch.active.data();
  // Where each active segment ends (its tail's u and v), beside it: the scan below reads them for
  // every candidate.
  int* active_u = scratch.active_u.data();
  float* active_v = scratch.active_v.data();
  int building = 0, active_count = 0;
  for (int i = 0; i < n; ++i) {
    const int p = order[i];
    const ProfilePoint& point = pts[p];
    next[p] = -1;
    if (i == 0 || pts[order[i - 1]].u != point.u) {
      // New column: segments that ended too far to the left can no longer grow.
      int kept = 0;
      for (int a = 0; a < active_count; ++a) {
        if (active_u[a] >= point.u - column_gap) {
          active[kept] = active[a];
          active_u[kept] = active_u[a];
          active_v[kept] = active_v[a];
          ++kept;
        }
      }
      active_count = kept;
    }
    int best = -1;
    double best_d2 = gap2;
    for (int a = 0; a < active_count; ++a) {
      if (active_u[a] >= point.u) continue;  // already extended in this column
      const double du = point.u - active_u[a], dv = point.v - active_v[a];
      const double d2 = du * du + dv * dv;
      if (d2 <= best_d2) {
        best_d2 = d2;
        best = a;
      }
    }
    if (best >= 0) {
      const int segment = active[best];
      next[tail[segment]] = p;
      tail[segment] = p;
      ++count[segment];
      active_u[best] = point.u;
      active_v[best] = point.v;
    } else {
      head[building] = tail[building] = p;
      count[building] = 1;
      active_u[active_count] = point.u;
      active_v[active_count] = point.v;
      active[active_count++] = building++;
    }
  }

  // Keep the segments long enough; lay out their points, rows and chain codes.
  const std::size_t code_capacity = out.rows.capacity();
  for (int s = 0; s < building; ++s) {
    if (count[s] < options.min_segment_points) continue;
    LineSegment seg;
    seg.first = static_cast<int>(out.points.size());
    seg.count = count[s];
    seg.u_min = pts[head[s]].u;
    seg.u_max = pts[tail[s]].u;
    seg.v_min = seg.v_max = pts[head[s]].v;
    seg.code_first = static_cast<int>(out.rows.size());
    if (out.rows.size() + static_cast<std::size_t>(seg.u_max - seg.u_min + 1) > code_capacity)
      break;
    int previous = -1;
    for (int p = head[s]; p >= 0; p = next[p]) {
      const ProfilePoint& point = pts[p];
      out.points.push_back({point.u, point.v, p});
      seg.v_min = std::min(seg.v_min, point.v);
      seg.v_max = std::max(seg.v_max, point.v);
      if (previous >= 0) {
        // Rows of the columns between two candidates: linear.
        const ProfilePoint& from = pts[previous];
        const int steps = point.u - from.u;
        for (int k = 1; k < steps; ++k)
          out.rows.push_back(from.v + (point.v - from.v) * static_cast<float>(k) / steps);
      }
      out.rows.push_back(point.v);
      previous = p;
    }
    for (int u = seg.u_min; u < seg.u_max; ++u) {
      const auto at = static_cast<std::size_t>(seg.code_first + (u - seg.u_min));
      out.chain_code.push_back(
          std::clamp(out.rows[at + 1] - out.rows[at], -kChainCodeStepLimit, kChainCodeStepLimit));
    }
    out.chain_code.push_back(0.0f);  // keeps chain_code indexed like rows
    out.segments.push_back(seg);
  }
}

// ---------------------------------------------------------------------------------------------
// IV-C

void add_match(LineSegment& s, const SegmentMatch& m) {
  int at = s.match_count;
  if (at == LineSegment::kMaxMatches) {
    if (m.score <= s.matches[LineSegment::kMaxMatches - 1].score) return;
    --at;
  } else {
    ++s.match_count;
  }
  while (at > 0 && s.matches[static_cast<std::size_t>(at - 1)].score < m.score) {
    s.matches[static_cast<std::size_t>(at)] = s.matches[static_cast<std::size_t>(at - 1)];
    --at;
  }
  s.matches[static_cast<std::size_t>(at)] = m;
}

void match_by_chain_code(const SegmentedFrame& previous, const SegmentedFrame& current,
                         LineSegment& s, const ValidationOptions& options) {
  s.match_count = 0;
  const int min_overlap = std::max(options.min_segment_points - 1, 1);
  const float* a = current.chain_code.data() + s.code_first - s.u_min;  // a[u]: step u -> u+1
  const double w = kChainCodeWeight;
  for (std::size_t t = 0; t < previous.segments.size(); ++t) {
    const LineSegment& other = previous.segments[t];
    // (By first column: the segments from here on all start too far right.)
    if (other.u_min - s.u_max > options.max_box_distance_px) break;
    if (boxes_farther_than(s, other, options.max_box_distance_px)) continue;
    const float* b = previous.chain_code.data() + other.code_first - other.u_min;
    const double shorter = std::min(s.u_max - s.u_min, other.u_max - other.u_min);
    SegmentMatch best;
    // Offsets from 0 outwards, so that a tie (a straight segment fits at every offset) keeps the
    // smallest shift.
    for (int step = 0; step <= 2 * options.max_column_offset; ++step) {
      const int k = (step % 2 == 0 ? 1 : -1) * ((step + 1) / 2);
      const int lo = std::max(s.u_min, other.u_min + k);
      const int hi = std::min(s.u_max, other.u_max + k) - 1;  // last step
      const int length = hi - lo + 1;
      if (length < min_overlap || length * 4 < shorter) continue;
      double ab = 0, aa = 0, bb = 0;
      for (int u = lo; u <= hi; ++u) {
        const double x = a[u], y = b[u - k];
        ab += x * y;
        aa += x * x;
        bb += y * y;
      }
      // Normalised cross-correlation of the descriptors (1, w * code) where they overlap (at
      // least a quarter of the shorter segment: a piece of a segment split differently in the
      // other frame, the laser line broken by relief or joined to a neighbour, still matches).
      const double correlation =
          (length + w * ab) / std::sqrt((length + w * aa) * (length + w * bb));
      if (correlation < options.min_correlation) continue;
      // Ranked by how many columns agree: a long segment is not matched to a short straight
      // piece of texture that merely fits somewhere along it. A shift must do clearly better
      // than a smaller one: noise on a nearly straight segment would otherwise pick any.
      const double support = correlation * length;
      if (support > best.score * (1.0 + kShiftMargin)) {
        best = {static_cast<int>(t), static_cast<float>(k), 0.0f, static_cast<float>(support)};
      }
    }
    if (best.previous >= 0) add_match(s, best);
  }
}

// ---------------------------------------------------------------------------------------------
// IV-D

bool back_project(const ScannerGeometry& camera, const PairMotion& first, const PairMotion& second,
                  const std::array<double, 2>& x0, const std::array<double, 2>& x1,
                  double max_depth_baselines, std::array<double, 2>& x2, double& ray_gap_px) {
  // Rays of the raw pixels (lens distortion removed).
  Vector3 a(0, 0, 1), b(0, 0, 1);
  if (!camera.normalised(x0[0], x0[1], a(0), a(1)) ||
      !camera.normalised(x1[0], x1[1], b(0), b(1))) {
    return false;
  }
  // In frame n-1: ray 0 from camera n-2's centre t1 along R1 a, ray 1 from the origin along b.
  const Vector3 d0 = first.rotation * a;
  const Vector3 t1 = first.translation;
  // Closest points t1 + mu d0 and lambda b: least squares of mu d0 - lambda b = -t1.
  const double d0d0 = d0.dot(d0), bb = b.dot(b), d0b = d0.dot(b);
  const double d0t = d0.dot(t1), bt = b.dot(t1);
  const double det = d0d0 * bb - d0b * d0b;
  if (!(det > 1e-18)) return false;  // parallel rays: no parallax at all
  const double mu = (d0b * bt - bb * d0t) / det;
  const double lambda = (d0d0 * bt - d0b * d0t) / det;
  if (!(mu > 0) || !(lambda > 0)) return false;  // behind a camera
  const Vector3 on0 = t1 + mu * d0;
  const Vector3 x = 0.5 * (on0 + lambda * b);
  const double baseline = std::sqrt(t1.dot(t1));
  if (!(x(2) > 0) || !(x(2) <= max_depth_baselines * baseline)) return false;

  // How far the point lands from the two observations it came from.
  const Vector3 in0 = first.rotation.transpose() * (x - t1);
  if (!(in0(2) > 0)) return false;
  const auto p0 = camera.pixel(in0(0) / in0(2), in0(1) / in0(2));
  const auto p1 = camera.pixel(x(0) / x(2), x(1) / x(2));
  const double e0 = std::hypot(p0[0] - x0[0], p0[1] - x0[1]);
  const double e1 = std::hypot(p1[0] - x1[0], p1[1] - x1[1]);
  ray_gap_px = std::max(e0, e1);

  // Into frame n, with the translation in the first pair's units.
  const Vector3 in2 = second.rotation * x + second.relative_scale * second.translation;
  if (!(in2(2) > 0)) return false;
  x2 = camera.pixel(in2(0) / in2(2), in2(1) / in2(2));
  return true;
}

// ---------------------------------------------------------------------------------------------

LineValidator::LineValidator(const ScannerGeometry& geometry, const ValidationOptions& options)
    : geometry_(geometry), options_(options) {
  options.validate();
}

void LineValidator::reset(int width, int height, std::size_t max_points) {
  for (SegmentedFrame& f : frames_)
    f.reset(max_points, options_.max_neighbour_gap_px);
  scratch_.reset(max_points);
  residuals_.assign(max_points, 0.0f);
  image_motion_.assign(max_points, 0.0f);
  eligible_.assign(max_points, 0);
  if (options_.association == SegmentAssociation::image_features) {
    previous_image_.assign(static_cast<std::size_t>(width) * height, 0);
  }
  width_ = width;
  height_ = height;
  have_previous_image_ = false;
  history_ = 0;
  current_ = 0;
}

void LineValidator::validate(Profile& profile, const PairMotion& motion, const ImageView& image,
                             const Homography* homography) {
  const int previous = current_;
  const int before = (current_ + 2) % 3;
  current_ = (current_ + 1) % 3;
  SegmentedFrame& frame = frames_[current_];
  motions_[current_] = motion;
  segment_candidates(profile, options_, frame, scratch_);
  const std::vector<ProfilePoint>& candidates = profile.points();
  for (std::size_t i = 0; i < candidates.size() && i < eligible_.size(); ++i)
    eligible_[i] = candidates[i].valid ? 1 : 0;

  // Tracks run over frames with candidates linked by a motion estimate (a frame without candidates,
  // e.g. a laser-off one, breaks them).
  if (profile.size() == 0) {
    history_ = 0;
  } else {
    history_ = history_ > 0 && motion.valid ? std::min(history_ + 1, 3) : 1;
  }
  if (history_ >= 2) {
    if (options_.association == SegmentAssociation::chain_code) {
      for (LineSegment& s : frame.segments)
        match_by_chain_code(frames_[previous], frame, s, options_);
    } else if (homography != nullptr && have_previous_image_) {
      associate_by_image_features(frames_[previous], frame, image, *homography);
    }
  }
  if (history_ >= 3) {
    test_segments(frame, frames_[previous], frames_[before], motions_[previous], motion);
  } else if (history_ == 2 && laser_tracks()) {
    // Only two frames so far: what is not tracked over those is not taken for the laser yet.
    for (LineSegment& s : frame.segments)
      s.background = s.match_count == 0;
  }

  // The verdict: candidates of background segments are not laser. Where the motion let some
  // segment be tested by its parallax, candidates outside any segment are noise; where nothing
  // could be (the camera holding still, no tracks yet) they stay as the front-end left them, for
  // the line selection to weigh alone. Every other candidate stays eligible.
  bool parallax_seen = false;
  for (const LineSegment& seg : frame.segments)
    parallax_seen = parallax_seen || (seg.tested && std::isfinite(seg.residual_px));
  const std::span<ProfilePoint> points = profile.mutable_points();
  for (ProfilePoint& p : points) {
    p.segment = -1;
    if (parallax_seen) p.valid = false;
  }
  // Validation only takes points away: the front-end's eligibility of the others stands.
  for (std::size_t s = 0; s < frame.segments.size(); ++s) {
    const LineSegment& seg = frame.segments[s];
    for (int i = seg.first; i < seg.first + seg.count; ++i) {
      ProfilePoint& p = points[static_cast<std::size_t>(frame.points[i].profile_index)];
      p.segment = static_cast<std::int32_t>(s);
      p.valid = !seg.background &&
                eligible_[static_cast<std::size_t>(frame.points[i].profile_index)] != 0;
    }
  }

  if (options_.association == SegmentAssociation::image_features) {
    for (int v = 0; v < height_; ++v) {
      std::memcpy(previous_image_.data() + static_cast<std::size_t>(v) * width_, image.row(v),
                  static_cast<std::size_t>(width_));
    }
    have_previous_image_ = true;
  }
}

void LineValidator::test_segments(SegmentedFrame& current, const SegmentedFrame& previous,
                                  const SegmentedFrame& before, const PairMotion& first,
                                  const PairMotion& second) {
  if (!first.valid || !second.valid || !std::isfinite(second.relative_scale)) return;
  for (LineSegment& s : current.segments) {
    // Not tracked over the three frames: the laser line is a lasting structure, so what is seen
    // once is not taken for it.
    s.background = laser_tracks();
    // Point association through the matches: each point of s that lies within a match in frame
    // n-1 whose own match in frame n-2 covers it.
    int n = 0;
    for (int i = s.first; i < s.first + s.count; ++i) {
      const SegmentPoint& x = current.points[i];
      const LineSegment* p = nullptr;
      const LineSegment* q = nullptr;
      int u1 = 0, u0 = 0;
      for (int a = 0; a < s.match_count && q == nullptr; ++a) {
        const SegmentMatch& m = s.matches[static_cast<std::size_t>(a)];
        p = &previous.segments[static_cast<std::size_t>(m.previous)];
        u1 = static_cast<int>(std::lround(x.u - m.column_offset));
        if (u1 < p->u_min || u1 > p->u_max) continue;
        for (int b = 0; b < p->match_count; ++b) {
          const SegmentMatch& m2 = p->matches[static_cast<std::size_t>(b)];
          const LineSegment& candidate = before.segments[static_cast<std::size_t>(m2.previous)];
          u0 = static_cast<int>(std::lround(u1 - m2.column_offset));
          if (u0 >= candidate.u_min && u0 <= candidate.u_max) {
            q = &candidate;
            break;
          }
        }
      }
      if (q == nullptr) continue;
      std::array<double, 2> x2{};
      double ray_gap = 0;
      const bool physical = back_project(
          geometry_, first, second, {double(u0), before.row_at(*q, u0)},
          {double(u1), previous.row_at(*p, u1)}, options_.max_depth_baselines, x2, ray_gap);
      // Across the line only: the laser's shape slides along it as the relief passes.
      const float v1 = previous.row_at(*p, u1);
      image_motion_[static_cast<std::size_t>(n)] = std::abs(x.v - v1);
      residuals_[static_cast<std::size_t>(n++)] =
          physical ? static_cast<float>(std::max(ray_gap, std::hypot(x2[0] - x.u, x2[1] - x.v)))
                   : std::numeric_limits<float>::infinity();
    }
    if (n < options_.min_segment_points) continue;  // too little overlap: not tracked
    float* mid = residuals_.data() + n / 2;
    std::nth_element(residuals_.data(), mid, residuals_.data() + n);
    float* motion_mid = image_motion_.data() + n / 2;
    std::nth_element(image_motion_.data(), motion_mid, image_motion_.data() + n);
    s.tested = true;
    s.residual_px = *mid;
    s.image_motion_px = *motion_mid;
    // Static scene: background. Not static but moving in the image more than the laser line can
    // (it moves with the camera: only as the depth along the sheet changes): not the laser either,
    // a wrong association of texture artefacts.
    s.background =
        *mid <= options_.background_px || (laser_tracks() && options_.max_laser_motion_px > 0 &&
                                           *motion_mid > options_.max_laser_motion_px);
  }
}

bool LineValidator::track_box(const LineSegment& s, const ImageView& image, const Homography& h,
                              float& du, float& dv) const {
  // The patch: around the box centre, at most patch_columns x patch_rows, in the current image.
  const int cu = (s.u_min + s.u_max) / 2;
  const int cv = static_cast<int>(std::lround(0.5f * (s.v_min + s.v_max)));
  const int half_u = std::min(options_.patch_columns / 2, std::max((s.u_max - s.u_min) / 2, 4));
  const int half_v = options_.patch_rows / 2;
  // Where the homography puts the centre in the previous frame: the search starts there.
  const std::array<double, 2> back = h.inverse().map(cu, cv);
  if (!std::isfinite(back[0]) || !std::isfinite(back[1])) return false;
  const int su = static_cast<int>(std::lround(back[0])) - cu;
  const int sv = static_cast<int>(std::lround(back[1])) - cv;
  const int r = options_.feature_search_px;
  // Patch and every shifted patch must lie inside both images.
  if (cu - half_u < 0 || cu + half_u >= width_ || cv - half_v < 0 || cv + half_v >= height_ ||
      cu - half_u + su - r < 0 || cu + half_u + su + r >= width_ || cv - half_v + sv - r < 0 ||
      cv + half_v + sv + r >= height_) {
    return false;
  }
  // Sum of absolute differences over every other pixel, at every shift of the window.
  constexpr int kMaxWindow = 2 * 32 + 1;
  constexpr std::uint32_t kUnknown = 0xffffffffu;
  std::array<std::uint32_t, kMaxWindow * kMaxWindow> sad;  // only window^2 entries are used
  const int window = 2 * r + 1;
  if (window > kMaxWindow) return false;
  std::fill_n(sad.begin(), window * window, kUnknown);
  auto cost = [&](int ox, int oy) {
    std::uint32_t& total = sad[static_cast<std::size_t>((oy + r) * window + ox + r)];
    if (total != kUnknown) return total;
    total = 0;
    for (int y = -half_v; y <= half_v; y += 2) {
      const std::uint8_t* a = image.row(cv + y) + cu;
      const std::uint8_t* b = previous_image_.data() +
                              static_cast<std::size_t>(cv + y + sv + oy) * width_ + cu + su + ox;
      for (int x = -half_u; x <= half_u; x += 2)
        total += static_cast<std::uint32_t>(std::abs(int(a[x]) - int(b[x])));
    }
    return total;
  };
  int bx = r, by = r;  // window coordinates of the best shift
  for (int oy = -r; oy <= r; ++oy) {
    for (int ox = -r; ox <= r; ++ox) {
      if (cost(ox, oy) < cost(bx - r, by - r)) {
        bx = ox + r;
        by = oy + r;
      }
    }
  }
  // Neighbours for the sub-pixel fit.
  for (const auto& [x, y] : {std::pair{bx - 1, by}, {bx + 1, by}, {bx, by - 1}, {bx, by + 1}})
    if (x >= 0 && x < window && y >= 0 && y < window) cost(x - r, y - r);
  // Sub-pixel: a parabola through the best and its neighbours, along each axis.
  auto vertex = [](double left, double centre, double right) {
    const double curvature = left - 2 * centre + right;
    return curvature > 0 ? std::clamp(0.5 * (left - right) / curvature, -0.5, 0.5) : 0.0;
  };
  auto at = [&](int y, int x) { return double(sad[static_cast<std::size_t>(y * window + x)]); };
  double fx = 0, fy = 0;
  if (bx > 0 && bx < window - 1) fx = vertex(at(by, bx - 1), at(by, bx), at(by, bx + 1));
  if (by > 0 && by < window - 1) fy = vertex(at(by - 1, bx), at(by, bx), at(by + 1, bx));
  // The scene at (u, v) now was at (u + shift) in the previous frame.
  du = -static_cast<float>(su + (bx - r) + fx);
  dv = -static_cast<float>(sv + (by - r) + fy);
  return true;
}

void LineValidator::associate_by_image_features(const SegmentedFrame& previous,
                                                SegmentedFrame& current, const ImageView& image,
                                                const Homography& homography) {
  for (LineSegment& s : current.segments) {
    s.match_count = 0;
    float du = 0, dv = 0;
    if (!track_box(s, image, homography, du, dv)) continue;
    // The predecessors: the segments of the previous frame on which enough of s's points land when
    // moved as the texture under them moved.
    const int best_agree = std::max(options_.min_segment_points, s.count / 2) - 1;
    for (std::size_t t = 0; t < previous.segments.size(); ++t) {
      const LineSegment& p = previous.segments[t];
      if (p.u_max < s.u_min - du - 1 || p.u_min > s.u_max - du + 1 ||
          p.v_max < s.v_min - dv - options_.background_px ||
          p.v_min > s.v_max - dv + options_.background_px) {
        continue;
      }
      int agree = 0;
      for (int i = s.first; i < s.first + s.count; ++i) {
        const SegmentPoint& x = current.points[i];
        const int u1 = static_cast<int>(std::lround(x.u - du));
        if (u1 < p.u_min || u1 > p.u_max) continue;
        if (std::abs(previous.row_at(p, u1) - (x.v - dv)) <= options_.background_px) ++agree;
      }
      if (agree > best_agree) {
        add_match(s, {static_cast<int>(t), du, dv,
                      static_cast<float>(agree) / static_cast<float>(s.count)});
      }
    }
  }
}

}  // namespace laserline::pipeline
