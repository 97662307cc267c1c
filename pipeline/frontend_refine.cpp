// The front end's sub-pixel refinement (paper III-F): per chosen column, the peak near the
// candidate's row in the source frame (the background subtracted along the column's line through
// it), a Gaussian fit of three samples over a sloping baseline; many columns at a time in
// kernels::refine_columns() (pipeline/kernels/).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <span>
#include <utility>

#include <Eigen/Dense>

#include "pipeline/frontend.hpp"
#include "pipeline/frontend_common.hpp"
#include "pipeline/kernels/kernels.hpp"
#include "pipeline/subpixel.hpp"

namespace laserline::pipeline {

using namespace frontend_detail;

namespace {

// The index of the first largest of values[0, count).
inline int first_largest(const float* values, int count) {
  int best = 0;
  for (int k = 1; k < count; ++k)
    best = values[k] > values[best] ? k : best;
  return best;
}

// The background-free column u near one row: the current frame minus the background seen
// through the homography, which along a short stretch of column moves linearly with the row.
// Clipped at 0 as in normalise_subtracting(): the previous frame's laser, warped a few pixels
// away, must not pull the baseline of the fit down on one side.
class ColumnSampler {
 public:
  ColumnSampler(const ImageView& current, const ImageView* background, const Homography& h, int u,
                int v)
      : current_(current), background_(background), u_(u), v0_(v) {
    if (background_ == nullptr) return;
    const auto [x0, y0] = h.map(u, v);
    const auto [x1, y1] = h.map(u, v + 1);
    x0_ = static_cast<float>(x0);
    y0_ = static_cast<float>(y0);
    dx_ = static_cast<float>(x1 - x0);
    dy_ = static_cast<float>(y1 - y0);
    x_max_ = static_cast<float>(background->width - 1);
    y_max_ = static_cast<float>(background->height - 1);
  }

  float operator()(int v) const {
    const float value = current_.at(u_, v);
    if (background_ == nullptr) return value;
    const auto k = static_cast<float>(v - v0_);
    const float x = x0_ + dx_ * k, y = y0_ + dy_ * k;
    if (!inside(x, y)) return 0.0f;
    // (A select that compiles to maxss: as a branch its random outcome mispredicts.)
    const float difference = value - background_at(x, y);
    return difference > 0.0f ? difference : 0.0f;
  }

  // The samples of rows [first, first + count) into out, and the index of the first largest
  // (count >= 1).
  int run(int first, int count, float* out) const {
    for (int k = 0; k < count; ++k)
      out[k] = (*this)(first + k);
    return first_largest(out, count);
  }

  // Whether kernels::refine_columns() can take the samples of rows [first, last] without a check
  // each (there is a background): the run is a straight segment in the background, so where both
  // its ends lie inside, all of it does; its loads read four bytes, so the positions stay four
  // columns from the background's right side, and column u four from the frame's.
  bool gatherable(int first, int last) const {
    const auto k0 = static_cast<float>(first - v0_), k1 = static_cast<float>(last - v0_);
    const float x_first = x0_ + dx_ * k0, x_last = x0_ + dx_ * k1;
    const float gathered = static_cast<float>(background_->width - 4);
    return u_ + 4 <= current_.width && covers(first, last) && x_first < gathered &&
           x_last < gathered;
  }

  // Whether the background lies under all of rows [first, last] (a straight segment in it: both
  // ends inside).
  bool covers(int first, int last) const {
    const auto k0 = static_cast<float>(first - v0_), k1 = static_cast<float>(last - v0_);
    return inside(x0_ + dx_ * k0, y0_ + dy_ * k0) && inside(x0_ + dx_ * k1, y0_ + dy_ * k1);
  }

  // The column's path through the background: row v is at (x0 + dx k, y0 + dy k), k = v - v0.
  struct Line {
    float x0, y0, dx, dy;
  };
  Line line() const { return {x0_, y0_, dx_, dy_}; }

 private:
  // The four neighbours of background position (x, y) lie inside the background, or the left two
  // on its last column (the right two taken as they are, as the difference kernel does:
  // kernels::reference::difference_last_column()).
  bool inside(float x, float y) const {
    return x >= 0.0f && x < x_max_ + 1.0f && y >= 0.0f && y < y_max_;
  }
  float background_at(float x, float y) const {
    if (x < x_max_) return bilinear(*background_, x, y);
    const auto iy = static_cast<int>(y);
    const float fy = y - static_cast<float>(iy);
    const std::uint8_t* p = background_->row(iy) + background_->width - 1;
    return p[0] + fy * (static_cast<float>(p[background_->stride]) - p[0]);
  }

  const ImageView& current_;
  const ImageView* background_;
  int u_, v0_;
  float x0_ = 0, y0_ = 0, dx_ = 0, dy_ = 0, x_max_ = 0, y_max_ = 0;
};

// The centre of the clipped run top..bottom (2 <= top, bottom <= last - 2) from `light` (the frame,
// or the frame less the background, on the run's column): where each flank crosses the level of
// the lower of the two samples next to the run, midway between the crossings by the line's
// symmetry. On the frame less the background the flanks are the laser's light alone: a surface
// brighter on one side (a texture edge along the line), where the laser saturates farther out,
// does not lean the centre toward it.
template <class Light>
float clipped_run_centre(const Light& light, int top, int bottom) {
  const float above = light(top - 1), below = light(bottom + 1);
  const float level = std::min(above, below);
  auto crossing = [&](int inside, int step, float inside_value) {
    if (inside_value <= level) return static_cast<float>(inside);
    const float outside = light(inside + step);
    if (outside >= inside_value) return static_cast<float>(inside);
    const float t = (inside_value - level) / (inside_value - outside);
    return static_cast<float>(inside) + static_cast<float>(step) * std::min(t, 1.0f);
  };
  return 0.5f * (crossing(top - 1, -1, above) + crossing(bottom + 1, +1, below));
}

// The centre of the clipped run (pixels at or above `saturation`) through (u, v) of `frame`: on
// `laser` (the frame less the background along column u) where it lies under the run's flanks,
// else on the frame.
float clipped_core_centre(const ImageView& frame, int u, int v, int saturation,
                          const ColumnSampler* laser) {
  const int last = frame.height - 1;
  int top = v, bottom = v;
  while (top > 0 && frame.at(u, top - 1) >= saturation)
    --top;
  while (bottom < last && frame.at(u, bottom + 1) >= saturation)
    ++bottom;
  if (top < 2 || bottom > last - 2) return 0.5f * static_cast<float>(top + bottom);
  // (The run's flanks, two rows beyond it, may lie where the background does not.)
  if (laser != nullptr && laser->covers(top - 2, bottom + 2)) {
    return clipped_run_centre(*laser, top, bottom);
  }
  return clipped_run_centre([&](int t) { return static_cast<float>(frame.at(u, t)); }, top, bottom);
}

// Where the glow in front of the line ends, walking from row `from` by `step` (+1 or -1) at most
// `span` rows within [0, last]: the centroid of the fall between neighbouring samples around the
// sharpest one (a blurred step spreads its fall over two or three rows). `from` when nothing falls.
template <class Sample>
float glow_end_after(const Sample& sample, int from, int step, int span, int last) {
  std::array<float, 48> falls;  // falls[k]: from row from + k step to the next
  const int n = std::min({span, static_cast<int>(falls.size()), step > 0 ? last - from : from});
  int sharpest = -1;
  float largest = 0.0f, previous = sample(from);
  for (int k = 0; k < n; ++k) {
    const float value = sample(from + (k + 1) * step);
    falls[static_cast<std::size_t>(k)] = previous - value;
    previous = value;
    if (falls[static_cast<std::size_t>(k)] > largest) {
      largest = falls[static_cast<std::size_t>(k)];
      sharpest = k;
    }
  }
  if (sharpest < 0) return static_cast<float>(from);
  float sum = 0.0f, moment = 0.0f;
  for (int k = std::max(sharpest - 1, 0); k <= std::min(sharpest + 1, n - 1); ++k) {
    const float fall = std::max(falls[static_cast<std::size_t>(k)], 0.0f);
    sum += fall;
    moment += fall * (static_cast<float>(k) + 0.5f);
  }
  return static_cast<float>(from) + static_cast<float>(step) * moment / sum;
}

// A line in glowing water along rows [first, last]: the glow's level in front of the centre c,
// the surface's behind it (meeting at c, the centre pixel taking each side's share), and a
// Gaussian line of the model's sigma at c of amplitude >= 0.
struct GlowingLineModel {
  float sigma;
  int near;  // the side of the glow (+1: rows further down)
  int first, last;

  // The sum of squared residuals of the least-squares fit with the centre at c.
  template <class Sample>
  double residual(const Sample& sample, float c) const {
    Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
    Eigen::Vector3d right = Eigen::Vector3d::Zero();
    double squares = 0;
    const double inverse_variance = 1.0 / (2.0 * static_cast<double>(sigma) * sigma);
    for (int v = first; v <= last; ++v) {
      const double d = static_cast<double>(v) - static_cast<double>(c);
      const double front = std::clamp(0.5 + static_cast<double>(near) * d, 0.0, 1.0);
      const Eigen::Vector3d basis{1.0 - front, front, std::exp(-d * d * inverse_variance)};
      const double y = sample(v);
      squares += y * y;
      right += basis * y;
      normal += basis * basis.transpose();
    }
    // With the line (if its amplitude comes out >= 0), else the two levels alone.
    const Eigen::Vector3d x = normal.ldlt().solve(right);
    if (x[2] >= 0.0 && x.allFinite()) return squares - x.dot(right);
    const Eigen::Vector2d levels = normal.topLeftCorner<2, 2>().ldlt().solve(right.head<2>());
    return squares - levels.dot(right.head<2>());
  }
};

}  // namespace

struct Frontend::RefineStart {
  int spacing;  // rows between the samples of the Gaussian fit (about one sigma)
  int edge;     // rows from the peak to the samples of the baseline beyond the line
  int centre;   // the guess, rounded
  int lo, hi;   // the rows searched for the peak
};

Frontend::RefineStart Frontend::refine_start(float v_guess) const {
  const double width = std::max(rows_.width_px(v_guess), 1.0);
  const int last = height_ - 1;
  const double sigma = width * kSigmaPerFwhm;
  RefineStart start{};
  // Rounded by truncation after adding 0.5 (sigma > 0): what lround gives, without the call.
  start.spacing = std::max(1, static_cast<int>(sigma + 0.5));
  start.edge = ceil_positive(2.5 * sigma) + 1;
  // The guess comes from a normalised row, good to about half a normalised width.
  const int reach = ceil_positive(width * half_per_normalised_width_ + 0.5) + 1;
  // (Rounded likewise: a negative guess goes to row 0 either way.)
  start.centre = std::clamp(static_cast<int>(v_guess + 0.5f), 0, last);
  start.lo = std::max(start.centre - reach, 0);
  start.hi = std::min(start.centre + reach, last);
  return start;
}

bool Frontend::in_clipped_core(int u, int v) const {
  const int saturation = options_.saturation_level;
  if (current_.at(u, v) < saturation) return false;
  const int longest = std::max(
      1, static_cast<int>(kClippedCoreWidths * rows_.width_px(static_cast<double>(v)) + 0.5));
  int run = 1;
  for (int t = v - 1; t >= 0 && current_.at(u, t) >= saturation; --t)
    if (++run > longest) return false;
  for (int t = v + 1; t < current_.height && current_.at(u, t) >= saturation; ++t)
    if (++run > longest) return false;
  return true;
}

bool Frontend::touches_clipped_run(int u, int v) const {
  const int saturation = options_.saturation_level;
  for (int t = std::max(v - 1, 0); t <= std::min(v + 1, height_ - 1); ++t)
    if (current_.at(u, t) >= saturation) return true;
  return false;
}

float Frontend::refine_row(int u, float v_guess) const {
  const int last = height_ - 1;
  const auto [spacing, edge, centre, lo, hi] = refine_start(v_guess);
  // Where the background does not lie under every sample the fit may read (at the frame's edge,
  // after motion), the fit is made on the frame itself: a sample with nothing to subtract is 0, and
  // a fit through such samples lands on the window's first row, off the line.
  const ColumnSampler with_background(current_, fit_with_background_ ? &background_ : nullptr,
                                      to_background_, u, centre);
  const bool covered =
      fit_with_background_ &&
      with_background.covers(std::max(lo - 2 * edge - 2, 0), std::min(hi + 2 * edge + 2, last));
  const ColumnSampler at(current_, covered ? &background_ : nullptr, to_background_, u, centre);

  // The samples of the search window are kept for the fit below (its inner samples are usually
  // among them).
  std::array<float, 32> window;  // (not zeroed: run() fills what is read)
  const int count = std::min(hi - lo + 1, static_cast<int>(window.size()));
  if (count < 1) return v_guess;  // (never: lo <= centre <= hi)
  int best = at.run(lo, count, window.data());
  float best_value = window[static_cast<std::size_t>(best)];
  // (A window too long for the array, as a very wide line can give: the rest one by one.)
  for (int v = lo + count; v <= hi; ++v) {
    const float value = at(v);
    if (value > best_value) {
      best_value = value;
      best = v - lo;
    }
  }
  best += lo;
  auto sample = [&](int v) {
    return v >= lo && v < lo + count ? window[static_cast<std::size_t>(v - lo)] : at(v);
  };

  // A clipped core (real green lasers saturate): the centre of the run, located on its flanks.
  if (current_.at(u, best) >= options_.saturation_level) {
    return clipped_core_centre(current_, u, best, options_.saturation_level,
                               fit_with_background_ ? &with_background : nullptr);
  }

  // Gaussian 3-point fit (exact for a sampled Gaussian) on samples about one sigma apart, so a
  // wide line is not fitted on nearly equal samples. The baseline, the straight line through the
  // samples just beyond the line on either side, is removed first: ambient light under the line
  // would bend the logarithms.
  if (best - edge < 0 || best + edge > last) return static_cast<float>(best);
  if (glowing_ && best - 2 * edge - 2 >= 0 && best + 2 * edge + 2 <= last) {
    // Where the water glows, the glow ends at the line in a step: a straight baseline through it
    // would pull the fit toward the glow by about a pixel, and the brightest sample is often the
    // glow's last one rather than the line's centre. Each side's light is followed instead (a
    // straight line through two samples beyond the line on that side), meeting at the line's
    // centre, the centre pixel taking each side's share; the fit is centred again on its result.
    const int near = rows_.near_side();
    auto fit_from = [&](float start) {
      float estimate = start;
      bool peaked = false;
      for (int pass = 0; pass < 3; ++pass) {
        const int middle = static_cast<int>(std::lround(estimate));
        auto side_line = [&](int side) {
          const float close = sample(middle + side * edge), far = sample(middle + side * 2 * edge);
          return std::array<float, 2>{close, (far - close) / static_cast<float>(edge)};
        };
        const auto front = side_line(near), back = side_line(-near);
        auto baseline = [&](int v) {
          const float into_front = static_cast<float>(near) * (static_cast<float>(v) - estimate);
          const float share = std::clamp(0.5f + into_front, 0.0f, 1.0f);
          const float distance = static_cast<float>(std::abs(v - middle));
          const float f = front[0] + front[1] * (distance - static_cast<float>(edge));
          const float b = back[0] + back[1] * (distance - static_cast<float>(edge));
          return b + share * (f - b);
        };
        const float a = sample(middle - spacing) - baseline(middle - spacing);
        const float b = sample(middle) - baseline(middle);
        const float c = sample(middle + spacing) - baseline(middle + spacing);
        peaked = b > 1.0f && b * b > std::max(a, 1.0f) * std::max(c, 1.0f);
        estimate =
            static_cast<float>(middle) + static_cast<float>(spacing) * gaussian_offset(a, b, c);
        if (std::abs(estimate - static_cast<float>(middle)) < 0.5f) break;  // centred there
      }
      return std::pair<float, bool>{estimate, peaked};
    };
    const float from_brightest = fit_from(static_cast<float>(best)).first;
    // The sheet meets the surface at the line's centre, so the glow ends there. On a dark patch
    // the line hardly rises above the glow, and the brightest sample can be noise on the glow,
    // pixels before its end. So the glow's end (the sharpest fall on the far side, located at the
    // centroid of the fall around it) is a second guess, refined the same way where a line rises
    // there; of the two, the one the model of a line in glowing water fits better is taken.
    // (The fit's samples, up to 2 edge + 1 rows beyond its centre, and its passes' steps stay in
    // the frame.)
    const int room = (near > 0 ? best : last - best) - 2 * edge - 2 - 3 * spacing;
    const int walk = std::min(hi - lo + 1 + edge, std::max(room, 0));
    const float glow_end = glow_end_after(sample, best, -near, walk, last);
    const auto [at_end, peaked] = fit_from(glow_end);
    // (No line above the glow where it ends, or one that noise drew away from it: the end is all
    // there is.)
    const float from_glow_end =
        peaked && std::abs(at_end - glow_end) <= static_cast<float>(spacing) ? at_end : glow_end;
    if (std::abs(from_glow_end - from_brightest) < 0.5f) return from_brightest;
    // On the glow the samples stay at its level up to its end, where they fall by its step; a
    // line whose far flank is the sharpest fall stands above the samples just before that fall.
    // Then it is the line.
    const float inside = sample(static_cast<int>(std::lround(glow_end + 2.0f * near)));
    const float past = sample(static_cast<int>(std::lround(glow_end - 2.0f * near)));
    if (best_value - inside > 0.5f * (inside - past)) return from_brightest;
    const auto sigma = static_cast<float>(rows_.width_px(v_guess) * kSigmaPerFwhm);
    const int first =
        static_cast<int>(std::floor(std::min(from_glow_end, from_brightest))) - 2 * edge;
    const int end = static_cast<int>(std::ceil(std::max(from_glow_end, from_brightest))) + 2 * edge;
    const GlowingLineModel model{sigma, near, std::max(first, 0), std::min(end, last)};
    return model.residual(sample, from_glow_end) < model.residual(sample, from_brightest)
               ? from_glow_end
               : from_brightest;
  }
  const float before = sample(best - edge), after = sample(best + edge);
  const float slope = (after - before) / static_cast<float>(2 * edge);
  const float level = 0.5f * (before + after);
  const float step = slope * static_cast<float>(spacing);
  const float a = sample(best - spacing) - (level - step);
  const float b = best_value - level;
  const float c = sample(best + spacing) - (level + step);
  const float fitted =
      static_cast<float>(best) + static_cast<float>(spacing) * gaussian_offset(a, b, c);
  // Less the background, a core clipped on a bright surface has little light left (255 less the
  // surface), less than its flank on a darker side: the brightest sample and the fit are on that
  // flank, and the run beside it is the line's core.
  const int fitted_row = std::clamp(static_cast<int>(std::lround(fitted)), 0, last);
  if (fit_with_background_ && current_.at(u, fitted_row) >= options_.saturation_level) {
    return clipped_core_centre(current_, u, fitted_row, options_.saturation_level,
                               &with_background);
  }
  return fitted;
}

void Frontend::refine(std::span<ProfilePoint> points, std::size_t count) {
  // The points in parts (each writes its own points, and its own range of the lanes).
  const int parts = static_cast<int>(parts_.size());
  auto part = [&](int p) {
    const auto [first, end] = part_range(static_cast<int>(count), p, parts);
    refine_range(points, static_cast<std::size_t>(first), static_cast<std::size_t>(end));
  };
  run_parts(part);
}

void Frontend::refine_range(std::span<ProfilePoint> points, std::size_t first, std::size_t end) {
  if (!fit_with_background_ || glowing_) {
    for (std::size_t k = first; k < end; ++k)
      points[refine_points_[k]].v = refine_row(refine_columns_[k], refine_guesses_[k]);
    return;
  }
  // The points whose samples all lie inside the frame and the background (nearly all): together
  // through the vector kernel, the same arithmetic as refine_row(); the others one by one.
  const int last = height_ - 1;
  RefineLanes& lanes = refine_lanes_;
  std::size_t n = first;
  for (std::size_t k = first; k < end; ++k) {
    const int u = refine_columns_[k];
    const float guess = refine_guesses_[k];
    const RefineStart start = refine_start(guess);
    const ColumnSampler column(current_, &background_, to_background_, u, start.centre);
    // The fit's samples reach `edge` rows beyond the window (where they lie in the frame).
    if (!column.gatherable(std::max(start.lo - start.edge, 0),
                           std::min(start.hi + start.edge, last))) {
      points[refine_points_[k]].v = refine_row(u, guess);
      continue;
    }
    const ColumnSampler::Line line = column.line();
    lanes.u[n] = u;
    lanes.centre[n] = start.centre;
    lanes.lo[n] = start.lo;
    lanes.count[n] = start.hi - start.lo + 1;
    lanes.spacing[n] = start.spacing;
    lanes.edge[n] = start.edge;
    lanes.x0[n] = line.x0;
    lanes.y0[n] = line.y0;
    lanes.dx[n] = line.dx;
    lanes.dy[n] = line.dy;
    lanes.point[n] = refine_points_[k];
    ++n;
  }
  const kernels::RefineColumns columns{lanes.u.data() + first,
                                       lanes.centre.data() + first,
                                       lanes.lo.data() + first,
                                       lanes.count.data() + first,
                                       lanes.spacing.data() + first,
                                       lanes.edge.data() + first,
                                       lanes.x0.data() + first,
                                       lanes.y0.data() + first,
                                       lanes.dx.data() + first,
                                       lanes.dy.data() + first,
                                       current_.data,
                                       current_.stride,
                                       background_.data,
                                       background_.stride,
                                       last,
                                       options_.saturation_level};
  kernels::refine_columns(columns, static_cast<int>(n - first), lanes.rows.data() + first);
  const int saturation = options_.saturation_level;
  for (std::size_t j = first; j < n; ++j) {
    float row = lanes.rows[j];
    const int u = lanes.u[j];
    // The kernel leaves a clipped peak (NaN) to be centred here, one by one (few points); a fit
    // may also land beside a clipped core (see refine_row()).
    const bool clipped_peak = std::isnan(row);
    const int fitted_row =
        clipped_peak ? 0 : std::clamp(static_cast<int>(std::lround(row)), 0, last);
    if (clipped_peak || current_.at(u, fitted_row) >= saturation) {
      const ColumnSampler laser(current_, &background_, to_background_, u, lanes.centre[j]);
      int through = fitted_row;
      if (clipped_peak) {  // the window's first largest sample, as the kernel found it
        float most = -1.0f;
        for (int v = lanes.lo[j]; v < lanes.lo[j] + lanes.count[j]; ++v) {
          const float value = laser(v);
          if (value > most) {
            most = value;
            through = v;
          }
        }
      }
      row = clipped_core_centre(current_, u, through, saturation, &laser);
    }
    points[lanes.point[j]].v = row;
  }
}

}  // namespace laserline::pipeline
