#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "pipeline/frontend_detectors.hpp"
#include "pipeline/kernels/kernels.hpp"

namespace laserline::pipeline {

BackgroundDetector::BackgroundDetector(const DetectorOptions& options, bool estimate_camera_motion)
    : frontend_(options.geometry, options.frontend),
      geometry_(options.geometry),
      options_(options.background),
      estimate_camera_motion_(estimate_camera_motion),
      motion_(options.motion) {
  options_.validate();
}

std::size_t BackgroundDetector::max_points(int width, int /*height*/) const {
  return frontend_.max_points(width);
}

void BackgroundDetector::use_parts(PartRunner& runner) {
  runner_ = &runner;
  frontend_.use_parts(runner);
  motion_.use_parts(runner);
}

void BackgroundDetector::reset(int width, int height) {
  parts_ = std::clamp(runner_->parts(), 1, kMaxParts);
  frontend_.reset(width, height);
  motion_.reset(width, height, estimate_camera_motion_ ? &geometry_ : nullptr);
  // Only the rows the warp can reach are kept: those of the depth range, plus what the scene can
  // move between two frames (an eighth of the image: 3 degrees per frame at f = 2240 px).
  const RowNormalisation& rows = frontend_.rows();
  const float lo = std::min(rows.source_row(0), rows.source_row(rows.rows() - 1));
  const float hi = std::max(rows.source_row(0), rows.source_row(rows.rows() - 1));
  const int margin = std::max(64, height / 8);
  band_first_ = std::max(static_cast<int>(std::floor(lo)) - margin, 0);
  band_rows_ = std::min(static_cast<int>(std::ceil(hi)) + margin, height - 1) - band_first_ + 1;
  history_.assign(static_cast<std::size_t>(options_.history_frames), History{});
  for (History& h : history_)
    h.rows.assign(static_cast<std::size_t>(width) * band_rows_, 0);
  incoming_.assign(static_cast<std::size_t>(width) * band_rows_, 0);
  own_line_removed_.assign(static_cast<std::size_t>(width) * band_rows_, 0);
  line_kept_.assign(static_cast<std::size_t>(width), 0);
  for (History& h : history_)
    h.line.assign(static_cast<std::size_t>(width), std::numeric_limits<float>::quiet_NaN());
  newest_ = -1;
  width_ratios_ = {};
  width_ratio_next_ = width_ratio_count_ = 0;
  motion_width_scale_ = 1.0;
  width_ = width;
  height_ = height;
}

BackgroundDetector::Motion BackgroundDetector::motion_across_line(const History& h) const {
  const RowNormalisation& rows = frontend_.rows();
  const int far = -rows.near_side();
  Motion least{std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  // The signed motion's extremes: where it goes both ways along the line (a scene turning under
  // it), it is zero somewhere between two of the line's points, and there that frame's line lies
  // on this one's. (Not across the rows searched: a scene coming nearer moves away from the
  // middle both ways, and the line lies at one of those rows only.)
  double most_down = -std::numeric_limits<double>::infinity();
  double most_up = std::numeric_limits<double>::infinity();
  auto probe = [&](double u, double v) {
    const auto [hu, hv] = h.to_history.map(u, v);
    (void)hu;
    const double width = std::max(rows.width_px(v) * motion_width_scale_, 1.0);
    const double moved = (hv - v) / width;
    least.across = std::min(least.across, std::abs(moved));
    least.toward_far = std::min(least.toward_far, far * moved);
    most_down = std::max(most_down, moved);
    most_up = std::min(most_up, moved);
  };
  const auto probes = frontend_.probes();
  if (!probes.empty()) {
    for (const auto& [u, v] : probes)
      probe(u, v);
  } else {
    // Nowhere seen yet: across the rows searched, at both ends and the middle of the image.
    const double top = rows.source_row(0), bottom = rows.source_row(rows.rows() - 1);
    for (const double u : {0.0, 0.5 * (width_ - 1), static_cast<double>(width_ - 1)}) {
      for (const double t : {0.0, 0.5, 1.0})
        probe(u, top + t * (bottom - top));
    }
  }
  if (!probes.empty() && most_down > 0 && most_up < 0) least.across = 0;
  return least;
}

BackgroundDetector::Background BackgroundDetector::choose_background(const ImageView& image) const {
  if (newest_ < 0) return {};
  const int n = static_cast<int>(history_.size());
  const bool glow = frontend_.water_glows(image);
  // Newest first: a laser-off frame wins outright; else the first laser-on frame the scene moved
  // far enough from (toward the far side of the line where the water glows); else the newest
  // laser-on frame less its own line (not where the water glows: its glow would stay).
  const History* moved = nullptr;
  const History* newest_on = nullptr;
  for (int age = 0; age < n; ++age) {
    const History& h = history_[static_cast<std::size_t>((newest_ - age + n) % n)];
    if (!h.usable) break;  // older ones are cut off from the current frame too
    if (!h.laser_on) return {&h, false};
    if (newest_on == nullptr) newest_on = &h;
    if (moved != nullptr) continue;
    const Motion m = motion_across_line(h);
    const double needed = options_.min_motion_widths;
    if (glow ? m.toward_far >= needed : m.across >= needed) moved = &h;
  }
  if (moved != nullptr) return {moved, false};
  if (options_.remove_own_line && !glow && newest_on != nullptr && newest_on->line_points > 0 &&
      subtraction_clears(*newest_on, image)) {
    return {newest_on, true};
  }
  return {};
}

bool BackgroundDetector::subtraction_clears(const History& h, const ImageView& image) const {
  // At least half of it is taken away: with texture alone that cancels the ratio is 0.1 to 0.3,
  // with noise alone 1 (plain dark walls, marine snow at night: 0.55 to 0.9).
  constexpr double kMostLeft = 0.5;
  const RowNormalisation& rows = frontend_.rows();
  double residual = 0, texture = 0;
  for (const auto& [u, v] : frontend_.probes()) {
    const double width = std::max(rows.width_px(v) * motion_width_scale_, 1.0);
    const int along = static_cast<int>(std::ceil(2 * width));
    const int x = static_cast<int>(std::lround(u));
    for (int k = 2; k <= 8; ++k) {
      for (const int side : {-1, 1}) {
        const int y = static_cast<int>(std::lround(v + side * k * width));
        if (y < 0 || y + along >= image.height) continue;
        const auto [hu, hv] = h.to_history.map(x, y);
        const auto bu = static_cast<int>(std::lround(hu));
        const int bv = static_cast<int>(std::lround(hv)) - band_first_;
        if (bu < 0 || bu >= width_ || bv < 0 || bv >= band_rows_) continue;
        const int here = image.at(x, y);
        residual += std::abs(here - h.rows[static_cast<std::size_t>(bv) * width_ + bu]);
        texture += std::abs(here - image.at(x, y + along));
      }
    }
  }
  return residual < kMostLeft * texture;
}

void BackgroundDetector::remove_own_line(const History& h) {
  const RowNormalisation& rows = frontend_.rows();
  // The band about the line on each epipolar line, [first, last] in kept rows (first < 0: none).
  auto band = [&](int u) -> std::array<int, 2> {
    const float v = h.line[static_cast<std::size_t>(u)];
    if (!std::isfinite(v)) return {-1, -1};
    const double half = std::ceil(std::max(rows.width_px(v) * motion_width_scale_, 1.0)) + 1;
    const int first = static_cast<int>(std::floor(v - half)) - band_first_;
    const int last = static_cast<int>(std::ceil(v + half)) - band_first_;
    if (first < 0 || last >= band_rows_) return {-1, -1};
    return {first, last};
  };
  for (int u = 0; u < width_; ++u)
    line_kept_[static_cast<std::size_t>(u)] = band(u)[0] >= 0 ? 0xff : 0;
  for (int r = 0; r < band_rows_; ++r) {
    const std::size_t row = static_cast<std::size_t>(r) * width_;
    for (int u = 0; u < width_; ++u)
      own_line_removed_[row + u] = h.rows[row + u] & line_kept_[static_cast<std::size_t>(u)];
  }
  for (int u = 0; u < width_; ++u) {
    const auto [first, last] = band(u);
    if (first < 0) continue;
    std::uint8_t* column = own_line_removed_.data() + u;
    auto at = [&](int r) -> std::uint8_t& { return column[static_cast<std::size_t>(r) * width_]; };
    const std::uint8_t surface = std::max(at(first), at(last));
    for (int r = first + 1; r < last; ++r)
      at(r) = std::min(at(r), surface);
  }
}

void BackgroundDetector::detect(const ImageView& image, const FrameContext& frame, Profile& out) {
  collect_candidates(image, frame, out);
  if (frame.laser_on) select_line(image, out);
}

void BackgroundDetector::select_line(const ImageView& image, Profile& out) {
  frontend_.select_line(out);
  // Where this frame's line is, for when it is a background the scene did not move away from.
  if (newest_ >= 0) {
    History& h = history_[static_cast<std::size_t>(newest_)];
    for (const ProfilePoint& p : out.points()) {
      if (!p.valid || p.u < 0 || p.u >= width_) continue;
      h.line[static_cast<std::size_t>(p.u)] = p.v;
      ++h.line_points;
    }
  }
  measure_line_width(image);
}

namespace {

// The line's full width at half its height across column u of `image`, about row v: the peak
// within `within` rows; the floor on each side where the profile (three columns' mean, for less
// noise) stops falling (rises again, or off the peak falls less than the noise over `flat_rows`:
// the surface beside the line, not a texture edge beyond it), the higher of the two (a line
// beside a dark patch is not made wider by it). NaN where no line stands out or a side does not
// fall to half within reach.
double width_across(const ImageView& image, int u, double v, int within, int flat_rows) {
  constexpr int kReach = 96;      // rows either side
  constexpr double kRise = 6.0;   // grey levels: less is no line
  constexpr double kNoise = 1.5;  // grey levels of the mean's noise
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  const int u0 = std::max(u - 1, 0), u1 = std::min(u + 1, image.width - 1);
  auto at = [&](int r) {
    if (r < 0 || r >= image.height) return kNaN;
    int sum = 0;
    for (int c = u0; c <= u1; ++c)
      sum += image.at(c, r);
    return static_cast<double>(sum) / (u1 - u0 + 1);
  };
  const int start = static_cast<int>(std::lround(v));
  int centre = start;
  double peak = -1;
  for (int r = start - within; r <= start + within; ++r) {
    const double value = at(r);
    if (value > peak) {
      peak = value;
      centre = r;
    }
  }
  if (!(peak >= 0)) return kNaN;
  double floor_level = 0;
  for (const int side : {-1, 1}) {
    double lowest = peak;
    for (int k = 1; k <= kReach; ++k) {
      const double value = at(centre + side * k);
      if (!(value <= lowest + kNoise)) break;
      if (k > flat_rows && lowest < peak - kRise &&
          !(value < at(centre + side * (k - flat_rows)) - kNoise)) {
        break;
      }
      lowest = std::min(lowest, value);
    }
    floor_level = std::max(floor_level, lowest);
  }
  if (!(peak - floor_level >= kRise)) return kNaN;
  const double half = 0.5 * (peak + floor_level);
  double width = 0;
  for (const int side : {-1, 1}) {
    double previous = peak;
    int k = 1;
    for (; k <= kReach; ++k) {
      const double value = at(centre + side * k);
      if (!(value > half)) break;  // (NaN: off the image)
      previous = value;
    }
    const double value = at(centre + side * k);
    if (k > kReach || std::isnan(value)) return kNaN;
    width += k - 1 + (previous - half) / std::max(previous - value, 1e-9);
  }
  return width;
}

}  // namespace

void BackgroundDetector::measure_line_width(const ImageView& image) {
  // Lines measure 1.1 to 1.5 times the model at full size, up to 3 times where the model is about
  // a pixel wide (the lens's own blur) or texture crowds them; a Gaussian line's extent, where it
  // has fallen to a fifth of its height, is 1.5 times its half-maximum width.
  constexpr double kWideLine = 3.0;
  constexpr double kExtentPerWidth = 1.5;
  constexpr std::size_t kEnough = 8;
  const RowNormalisation& rows = frontend_.rows();
  std::array<double, Frontend::kProbes> ratios{};
  std::size_t count = 0;
  for (const auto& [u, v] : frontend_.probes()) {
    const double model = std::max(rows.width_px(v), 1.0);
    const double width = width_across(image, static_cast<int>(u), v,
                                      std::max(2, static_cast<int>(std::ceil(0.5 * model))),
                                      std::max(2, static_cast<int>(std::ceil(model))));
    if (std::isfinite(width)) ratios[count++] = width / model;
  }
  if (count < kEnough) return;
  const auto middle = ratios.begin() + static_cast<std::ptrdiff_t>(count / 2);
  std::nth_element(ratios.begin(), middle, ratios.begin() + static_cast<std::ptrdiff_t>(count));
  // The median of the last three frames' (one frame's texture can mislead it).
  width_ratios_[width_ratio_next_] = *middle;
  width_ratio_next_ = (width_ratio_next_ + 1) % width_ratios_.size();
  width_ratio_count_ = std::min(width_ratio_count_ + 1, width_ratios_.size());
  const auto& r = width_ratios_;
  const double ratio =
      width_ratio_count_ < 3
          ? std::max(r[0], r[1])  // (the one measured, or the larger of two: unset ones are 0)
          : std::max(std::min(r[0], r[1]), std::min(std::max(r[0], r[1]), r[2]));
  motion_width_scale_ = ratio > kWideLine ? kExtentPerWidth * ratio : 1.0;
}

void BackgroundDetector::collect_candidates(const ImageView& image, const FrameContext& frame,
                                            Profile& out) {
  out.clear();
  // The rows this frame keeps, in bands of rows (the kept frames stay as they are until it is
  // done: one of them may be its background). Past the cache: read again a frame later at the
  // soonest.
  auto keep_rows = [&](int part) {
    const auto [first, end] = part_range(band_rows_, part, parts_);
    kernels::copy_rows_past_cache(image.row(band_first_ + first), image.stride,
                                  incoming_.data() + static_cast<std::size_t>(first) * width_,
                                  width_, width_, end - first);
  };
  if (parts_ > 1 && runner_->parts() == parts_) {
    runner_->run(PartWork(keep_rows));
  } else {
    for (int part = 0; part < parts_; ++part)
      keep_rows(part);
  }
  last_motion_ = motion_.update(image);
  // Chain the kept frames' motion to this frame; without a motion estimate none of them can be
  // warped onto it.
  const Homography to_previous = last_motion_.previous_to_current.inverse();
  for (History& h : history_) {
    h.usable = h.usable && last_motion_.valid;
    if (h.usable) h.to_history = h.to_history.after(to_previous);
  }
  if (frame.laser_on) {
    const Background background = choose_background(image);
    if (background.history != nullptr) {
      const History& h = *background.history;
      if (background.own_line_removed) remove_own_line(h);
      const ImageView rows{background.own_line_removed ? own_line_removed_.data() : h.rows.data(),
                           width_, band_rows_, width_};
      // Current pixel -> the background frame -> row within the kept band.
      Homography to_band = h.to_history;
      for (int i = 0; i < 3; ++i)
        to_band.h(1, i) -= band_first_ * to_band.h(2, i);
      frontend_.set_frame_minus_background(image, rows, to_band, !background.own_line_removed);
    } else {
      frontend_.set_frame(image);
    }
    frontend_.collect_candidates(out);
    if (background.history != nullptr) {
      out.set_background(static_cast<std::int64_t>(background.history->sequence),
                         !background.history->laser_on, background.own_line_removed);
    }
  }
  // This frame joins the history, in place of the oldest.
  newest_ = (newest_ + 1) % static_cast<int>(history_.size());
  History& h = history_[static_cast<std::size_t>(newest_)];
  h.rows.swap(incoming_);
  h.sequence = frame.sequence;
  h.laser_on = frame.laser_on;
  h.usable = true;
  h.to_history = Homography{};
  std::fill(h.line.begin(), h.line.end(), std::numeric_limits<float>::quiet_NaN());
  h.line_points = 0;
}

}  // namespace laserline::pipeline
