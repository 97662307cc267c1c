// The front end's sub-pixel refinement (paper III-F): per chosen column, the peak near the
// candidate's row in the source frame (the background subtracted along the column's line through
// it), a Gaussian fit of three samples over a sloping baseline; eight columns at a time in AVX2
// where the CPU has it.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <span>

#include "pipeline/frontend.hpp"
#include "pipeline/frontend_common.hpp"
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
    const float difference = value - bilinear(*background_, x, y);
    return difference > 0.0f ? difference : 0.0f;
  }

  // The samples of rows [first, first + count) into out, and the index of the first largest
  // (count >= 1).
  int run(int first, int count, float* out) const {
    for (int k = 0; k < count; ++k)
      out[k] = (*this)(first + k);
    return first_largest(out, count);
  }

  // Whether the AVX2 kernels can take the samples of rows [first, last] without a check each
  // (there is a background): the run is a straight segment in the background, so where both its
  // ends lie inside, all of it does; their gathers read four bytes, so the positions stay four
  // columns from the background's right side, and column u four from the frame's.
  bool gatherable(int first, int last) const {
    const auto k0 = static_cast<float>(first - v0_), k1 = static_cast<float>(last - v0_);
    const float x_first = x0_ + dx_ * k0, x_last = x0_ + dx_ * k1;
    const float gathered = static_cast<float>(background_->width - 4);
    return u_ + 4 <= current_.width && inside(x_first, y0_ + dy_ * k0) &&
           inside(x_last, y0_ + dy_ * k1) && x_first < gathered && x_last < gathered;
  }

  // The column's path through the background: row v is at (x0 + dx k, y0 + dy k), k = v - v0.
  struct Line {
    float x0, y0, dx, dy;
  };
  Line line() const { return {x0_, y0_, dx_, dy_}; }

 private:
  // The four neighbours of background position (x, y) lie inside the background.
  bool inside(float x, float y) const { return x >= 0.0f && x < x_max_ && y >= 0.0f && y < y_max_; }

  const ImageView& current_;
  const ImageView* background_;
  int u_, v0_;
  float x0_ = 0, y0_ = 0, dx_ = 0, dy_ = 0, x_max_ = 0, y_max_ = 0;
};

#if LASERLINE_AVX2_KERNELS
// Eight columns refined at once (refine_avx2()): per lane the column, the refinement's start
// (see Frontend::RefineStart; count = hi - lo + 1 rows searched, at most 32) and the column's
// line through the background (ColumnSampler::Line).
struct RefineLanes {
  alignas(32) std::array<std::int32_t, 8> u, centre, lo, count, spacing, edge;
  alignas(32) std::array<float, 8> x0, y0, dx, dy;
};

__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256i
lanes_of(const std::array<std::int32_t, 8>& values) {
  return _mm256_load_si256(reinterpret_cast<const __m256i*>(values.data()));
}

__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256
lanes_of(const std::array<float, 8>& values) {
  return _mm256_load_ps(values.data());
}

// Four bytes from each of base + offset (lanes `wanted`; the others 0), as a gather does but by
// eight loads: gathers are slow on this machine's CPU (an Ice Lake server; measured: 24 cycles a
// gather, 10 for eight loads). The lanes not wanted read from base itself.
__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256i four_bytes_at(const std::uint8_t* base,
                                                                           __m256i offset,
                                                                           __m256i wanted) {
  alignas(32) std::array<std::int32_t, 8> at;
  _mm256_store_si256(reinterpret_cast<__m256i*>(at.data()), _mm256_and_si256(offset, wanted));
  std::array<std::int32_t, 8> value;
  for (std::size_t j = 0; j < 8; ++j)
    std::memcpy(&value[j], base + at[j], sizeof value[j]);
  const __m256i loaded = _mm256_setr_epi32(value[0], value[1], value[2], value[3], value[4],
                                           value[5], value[6], value[7]);
  return _mm256_and_si256(loaded, wanted);
}

// The eight columns of RefineLanes in registers: their samples as ColumnSampler gives them (the
// same arithmetic, so the same values). Every row asked for must be one whose samples
// ColumnSampler::gatherable() allows.
class RefineColumnsAvx2 {
 public:
  __attribute__((target("avx2")))
  RefineColumnsAvx2(const RefineLanes& lanes, const ImageView& current, const ImageView& background)
      : column_(lanes_of(lanes.u)),
        centre_(lanes_of(lanes.centre)),
        x0_(lanes_of(lanes.x0)),
        y0_(lanes_of(lanes.y0)),
        dx_(lanes_of(lanes.dx)),
        dy_(lanes_of(lanes.dy)),
        current_stride_(_mm256_set1_epi32(current.stride)),
        background_stride_(_mm256_set1_epi32(background.stride)),
        current_(current.data),
        top_row_(background.data),
        bottom_row_(background.data + background.stride) {}

  // The current frame at `rows` of the columns (lanes not `wanted`: 0).
  __attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256i current(__m256i rows,
                                                                       __m256i wanted) const {
    const __m256i offset = _mm256_add_epi32(_mm256_mullo_epi32(rows, current_stride_), column_);
    return _mm256_and_si256(four_bytes_at(current_, offset, wanted), _mm256_set1_epi32(0xff));
  }

  // The background-free samples at `rows`: ColumnSampler::operator() (lanes not `wanted`: 0).
  __attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256 sample(__m256i rows,
                                                                     __m256i wanted) const {
    const __m256i low_byte = _mm256_set1_epi32(0xff);
    const __m256 k = _mm256_cvtepi32_ps(_mm256_sub_epi32(rows, centre_));
    const __m256 x = _mm256_add_ps(x0_, _mm256_mul_ps(dx_, k));
    const __m256 y = _mm256_add_ps(y0_, _mm256_mul_ps(dy_, k));
    const __m256i ix = _mm256_cvttps_epi32(x), iy = _mm256_cvttps_epi32(y);
    const __m256 fx = _mm256_sub_ps(x, _mm256_cvtepi32_ps(ix));
    const __m256 fy = _mm256_sub_ps(y, _mm256_cvtepi32_ps(iy));
    const __m256i offset = _mm256_add_epi32(_mm256_mullo_epi32(iy, background_stride_), ix);
    const __m256i top = four_bytes_at(top_row_, offset, wanted);
    const __m256i bottom = four_bytes_at(bottom_row_, offset, wanted);
    const __m256 p00 = _mm256_cvtepi32_ps(_mm256_and_si256(top, low_byte));
    const __m256 p01 = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(top, 8), low_byte));
    const __m256 p10 = _mm256_cvtepi32_ps(_mm256_and_si256(bottom, low_byte));
    const __m256 p11 = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(bottom, 8), low_byte));
    const __m256 upper = _mm256_add_ps(p00, _mm256_mul_ps(fx, _mm256_sub_ps(p01, p00)));
    const __m256 lower = _mm256_add_ps(p10, _mm256_mul_ps(fx, _mm256_sub_ps(p11, p10)));
    const __m256 warped = _mm256_add_ps(upper, _mm256_mul_ps(fy, _mm256_sub_ps(lower, upper)));
    const __m256 value = _mm256_cvtepi32_ps(current(rows, wanted));
    return _mm256_max_ps(_mm256_sub_ps(value, warped), _mm256_setzero_ps());
  }

 private:
  __m256i column_, centre_;
  __m256 x0_, y0_, dx_, dy_;
  __m256i current_stride_, background_stride_;
  const std::uint8_t* current_;
  const std::uint8_t* top_row_;
  const std::uint8_t* bottom_row_;
};

__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256i select(__m256i mask, __m256i yes,
                                                                    __m256i no) {
  return _mm256_blendv_epi8(no, yes, mask);
}

__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256 select(__m256i mask, __m256 yes,
                                                                   __m256 no) {
  return _mm256_blendv_ps(no, yes, _mm256_castsi256_ps(mask));
}

// Where a flank of a clipped run crosses `level` (refine_row()'s crossing()): from the sample
// next to the run, `inside` (value inside_value), one row further by `step` (-1 or +1).
__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256
crossing_avx2(const RefineColumnsAvx2& columns, __m256i inside, int step, __m256 inside_value,
              __m256 level, __m256i wanted) {
  const __m256 at_inside = _mm256_cvtepi32_ps(inside);
  const __m256 outside = _mm256_cvtepi32_ps(
      columns.current(_mm256_add_epi32(inside, _mm256_set1_epi32(step)), wanted));
  const __m256 t =
      _mm256_div_ps(_mm256_sub_ps(inside_value, level), _mm256_sub_ps(inside_value, outside));
  const __m256 moved =
      _mm256_add_ps(at_inside, _mm256_mul_ps(_mm256_set1_ps(static_cast<float>(step)),
                                             _mm256_min_ps(t, _mm256_set1_ps(1.0f))));
  const __m256 stays = _mm256_or_ps(_mm256_cmp_ps(inside_value, level, _CMP_LE_OQ),
                                    _mm256_cmp_ps(outside, inside_value, _CMP_GE_OQ));
  return _mm256_blendv_ps(moved, at_inside, stays);
}

// refine_row() of eight columns, lanes side by side: the same arithmetic on the same samples,
// so the same results. `last` is the frame's last row.
__attribute__((target("avx2"))) inline void refine_eight_avx2(const RefineLanes& lanes,
                                                              const ImageView& current,
                                                              const ImageView& background, int last,
                                                              int saturation,
                                                              std::array<float, 8>& result) {
  const RefineColumnsAvx2 columns(lanes, current, background);
  const __m256i one = _mm256_set1_epi32(1);
  const __m256i all = _mm256_set1_epi32(-1);
  const __m256i lo = lanes_of(lanes.lo), count = lanes_of(lanes.count);
  const __m256i last_row = _mm256_set1_epi32(last);
  // The search window: the first largest sample of each lane.
  __m256 most = _mm256_set1_ps(-1.0f);
  __m256i best = lo;
  const int longest = *std::max_element(lanes.count.begin(), lanes.count.end());
  for (int k = 0; k < longest; ++k) {
    const __m256i step = _mm256_set1_epi32(k);
    const __m256i wanted = _mm256_cmpgt_epi32(count, step);
    const __m256i rows = _mm256_add_epi32(lo, step);
    const __m256 value = columns.sample(rows, wanted);
    const __m256i larger =
        _mm256_and_si256(_mm256_castps_si256(_mm256_cmp_ps(value, most, _CMP_GT_OQ)), wanted);
    most = select(larger, value, most);
    best = select(larger, rows, best);
  }

  // A clipped core: the run of saturated rows around the peak, walked out from it.
  const __m256i below_saturation = _mm256_set1_epi32(saturation - 1);
  const __m256i clipped = _mm256_cmpgt_epi32(columns.current(best, all), below_saturation);
  __m256i top = best, bottom = best;
  for (__m256i going = clipped; !_mm256_testz_si256(going, going);) {
    const __m256i next = _mm256_sub_epi32(top, one);
    going = _mm256_and_si256(going, _mm256_cmpgt_epi32(top, _mm256_setzero_si256()));
    going =
        _mm256_and_si256(going, _mm256_cmpgt_epi32(columns.current(next, going), below_saturation));
    top = select(going, next, top);
  }
  for (__m256i going = clipped; !_mm256_testz_si256(going, going);) {
    const __m256i next = _mm256_add_epi32(bottom, one);
    going = _mm256_and_si256(going, _mm256_cmpgt_epi32(last_row, bottom));
    going =
        _mm256_and_si256(going, _mm256_cmpgt_epi32(columns.current(next, going), below_saturation));
    bottom = select(going, next, bottom);
  }
  // Runs that reach within two rows of an end: their middle.
  const __m256i near_end = _mm256_or_si256(_mm256_cmpgt_epi32(_mm256_set1_epi32(2), top),
                                           _mm256_cmpgt_epi32(bottom, _mm256_set1_epi32(last - 2)));
  const __m256 middle =
      _mm256_mul_ps(_mm256_set1_ps(0.5f), _mm256_cvtepi32_ps(_mm256_add_epi32(top, bottom)));
  // Else midway between the crossings of the flanks.
  const __m256i flanked = _mm256_andnot_si256(near_end, clipped);
  const __m256i above_run = _mm256_sub_epi32(top, one), below_run = _mm256_add_epi32(bottom, one);
  const __m256 above = _mm256_cvtepi32_ps(columns.current(above_run, flanked));
  const __m256 below = _mm256_cvtepi32_ps(columns.current(below_run, flanked));
  const __m256 level = _mm256_min_ps(above, below);
  const __m256 crossings =
      _mm256_mul_ps(_mm256_set1_ps(0.5f),
                    _mm256_add_ps(crossing_avx2(columns, above_run, -1, above, level, flanked),
                                  crossing_avx2(columns, below_run, +1, below, level, flanked)));
  const __m256 clipped_row = select(near_end, middle, crossings);

  // Else the Gaussian 3-point fit on the baseline-free samples, where the baseline's samples lie
  // inside the frame.
  const __m256i edge = lanes_of(lanes.edge), spacing = lanes_of(lanes.spacing);
  const __m256i off_frame = _mm256_or_si256(
      _mm256_cmpgt_epi32(edge, best), _mm256_cmpgt_epi32(_mm256_add_epi32(best, edge), last_row));
  const __m256i fitted = _mm256_andnot_si256(_mm256_or_si256(clipped, off_frame), all);
  const __m256 before = columns.sample(_mm256_sub_epi32(best, edge), fitted);
  const __m256 after = columns.sample(_mm256_add_epi32(best, edge), fitted);
  const __m256 slope =
      _mm256_div_ps(_mm256_sub_ps(after, before), _mm256_cvtepi32_ps(_mm256_add_epi32(edge, edge)));
  const __m256 baseline = _mm256_mul_ps(_mm256_set1_ps(0.5f), _mm256_add_ps(before, after));
  const __m256 rise = _mm256_mul_ps(slope, _mm256_cvtepi32_ps(spacing));
  alignas(32) std::array<float, 8> a, b, c, rows, spacings, results;
  _mm256_store_ps(a.data(), _mm256_sub_ps(columns.sample(_mm256_sub_epi32(best, spacing), fitted),
                                          _mm256_sub_ps(baseline, rise)));
  _mm256_store_ps(b.data(), _mm256_sub_ps(most, baseline));
  _mm256_store_ps(c.data(), _mm256_sub_ps(columns.sample(_mm256_add_epi32(best, spacing), fitted),
                                          _mm256_add_ps(baseline, rise)));
  _mm256_store_ps(rows.data(), _mm256_cvtepi32_ps(best));
  _mm256_store_ps(spacings.data(), _mm256_cvtepi32_ps(spacing));
  _mm256_store_ps(results.data(), select(clipped, clipped_row, _mm256_cvtepi32_ps(best)));
  alignas(32) std::array<std::int32_t, 8> fit;
  _mm256_store_si256(reinterpret_cast<__m256i*>(fit.data()), fitted);
  for (std::size_t j = 0; j < 8; ++j) {
    result[j] =
        fit[j] != 0 ? rows[j] + spacings[j] * gaussian_offset(a[j], b[j], c[j]) : results[j];
  }
}
#endif

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

float Frontend::refine_row(int u, float v_guess) const {
  const int last = height_ - 1;
  const auto [spacing, edge, centre, lo, hi] = refine_start(v_guess);
  const ColumnSampler at(current_, subtracting_ ? &background_ : nullptr, to_background_, u,
                         centre);

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
  const int saturation = options_.saturation_level;
  if (current_.at(u, best) >= saturation) {
    int top = best, bottom = best;
    while (top > 0 && current_.at(u, top - 1) >= saturation)
      --top;
    while (bottom < last && current_.at(u, bottom + 1) >= saturation)
      ++bottom;
    if (top < 2 || bottom > last - 2) return 0.5f * static_cast<float>(top + bottom);
    // Where each flank crosses the level of the lower of the two samples next to the run: by
    // symmetry the centre lies midway between the crossings.
    const float above = current_.at(u, top - 1), below = current_.at(u, bottom + 1);
    const float level = std::min(above, below);
    auto crossing = [&](int inside, int step, float inside_value) {
      if (inside_value <= level) return static_cast<float>(inside);
      const float outside = current_.at(u, inside + step);
      if (outside >= inside_value) return static_cast<float>(inside);
      const float t = (inside_value - level) / (inside_value - outside);
      return static_cast<float>(inside) + static_cast<float>(step) * std::min(t, 1.0f);
    };
    return 0.5f * (crossing(top - 1, -1, above) + crossing(bottom + 1, +1, below));
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
    float estimate = static_cast<float>(best);
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
      estimate =
          static_cast<float>(middle) + static_cast<float>(spacing) * gaussian_offset(a, b, c);
      if (std::abs(estimate - static_cast<float>(middle)) < 0.5f) break;  // centred where it is
    }
    return estimate;
  }
  const float before = sample(best - edge), after = sample(best + edge);
  const float slope = (after - before) / static_cast<float>(2 * edge);
  const float level = 0.5f * (before + after);
  const float step = slope * static_cast<float>(spacing);
  const float a = sample(best - spacing) - (level - step);
  const float b = best_value - level;
  const float c = sample(best + spacing) - (level + step);
  return static_cast<float>(best) + static_cast<float>(spacing) * gaussian_offset(a, b, c);
}

void Frontend::refine(std::span<ProfilePoint> points, std::size_t count) const {
#if LASERLINE_AVX2_KERNELS
  if (avx2_ && subtracting_ && !glowing_) {
    refine_avx2(points, count);
    return;
  }
#endif
  for (std::size_t k = 0; k < count; ++k)
    points[refine_points_[k]].v = refine_row(refine_columns_[k], refine_guesses_[k]);
}

#if LASERLINE_AVX2_KERNELS
// refine() with refine_eight_avx2(), eight columns at a time: the points whose samples can all be
// gathered (nearly all), the others through refine_row().
__attribute__((target("avx2"))) void Frontend::refine_avx2(std::span<ProfilePoint> points,
                                                           std::size_t count) const {
  const int last = height_ - 1;
  RefineLanes lanes;
  std::array<std::size_t, 8> point_of{};  // the profile's index of each lane's point
  std::array<float, 8> rows{};
  std::size_t filled = 0;
  for (std::size_t k = 0; k <= count; ++k) {
    // (After the last point, the lanes still filled run, the rest a copy of the first.)
    if (k == count) {
      if (filled == 0) break;
      for (std::size_t j = filled; j < 8; ++j) {
        for (auto* field :
             {&lanes.u, &lanes.centre, &lanes.lo, &lanes.count, &lanes.spacing, &lanes.edge})
          (*field)[j] = (*field)[0];
        for (auto* field : {&lanes.x0, &lanes.y0, &lanes.dx, &lanes.dy})
          (*field)[j] = (*field)[0];
      }
    } else {
      const int u = refine_columns_[k];
      const float guess = refine_guesses_[k];
      const RefineStart start = refine_start(guess);
      const ColumnSampler column(current_, &background_, to_background_, u, start.centre);
      // The fit's samples reach `edge` rows beyond the window (where they lie in the frame).
      const bool gathered =
          start.hi - start.lo + 1 <= 32 && column.gatherable(std::max(start.lo - start.edge, 0),
                                                             std::min(start.hi + start.edge, last));
      if (!gathered) {
        points[refine_points_[k]].v = refine_row(u, guess);
        continue;
      }
      const ColumnSampler::Line line = column.line();
      lanes.u[filled] = u;
      lanes.centre[filled] = start.centre;
      lanes.lo[filled] = start.lo;
      lanes.count[filled] = start.hi - start.lo + 1;
      lanes.spacing[filled] = start.spacing;
      lanes.edge[filled] = start.edge;
      lanes.x0[filled] = line.x0;
      lanes.y0[filled] = line.y0;
      lanes.dx[filled] = line.dx;
      lanes.dy[filled] = line.dy;
      point_of[filled] = refine_points_[k];
      if (++filled < 8) continue;
    }
    refine_eight_avx2(lanes, current_, background_, last, options_.saturation_level, rows);
    for (std::size_t j = 0; j < filled; ++j)
      points[point_of[j]].v = rows[j];
    filled = 0;
  }
}
#endif

}  // namespace laserline::pipeline
