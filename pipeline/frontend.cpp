#include "pipeline/frontend.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "pipeline/subpixel.hpp"

// The dense kernels are compiled twice on x86-64, for the baseline and for AVX2, and the loader
// picks the one the CPU runs (GCC function multi-versioning): twice the lanes per instruction where
// the machine has them, and the same binary still runs everywhere.
// Not under ThreadSanitizer: the loader runs the version resolvers before its runtime is up.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_THREAD__)
#define LASERLINE_DENSE_KERNEL __attribute__((target_clones("avx2", "default")))
#else
#define LASERLINE_DENSE_KERNEL
#endif

namespace laserline::pipeline {

namespace {

constexpr double kFwhmToSigma = 2.3548200450309493;
// Row kernels run over blocks of this many pixels with a constant trip count: what GCC needs to
// vectorise them. Float rows are padded to a multiple of it.
constexpr int kBlock = 16;

int odd_at_least_one(double x) {
  const int n = std::max(1, static_cast<int>(std::lround(x)));
  return n % 2 == 1 ? n : n + 1;
}

// Bilinear sample of a mono8 image; (x, y) must lie within [0, w-1] x [0, h-1].
inline float bilinear(const ImageView& image, float x, float y) {
  const int ix = std::min(static_cast<int>(x), image.width - 2);
  const int iy = std::min(static_cast<int>(y), image.height - 2);
  const float fx = x - static_cast<float>(ix), fy = y - static_cast<float>(iy);
  const std::uint8_t* p = image.row(iy) + ix;
  const float top = p[0] + fx * (static_cast<float>(p[1]) - p[0]);
  const float bottom =
      p[image.stride] + fx * (static_cast<float>(p[image.stride + 1]) - p[image.stride]);
  return top + fy * (bottom - top);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// III-B

RowNormalisation::RowNormalisation(const ScannerGeometry& g, const FrontendOptions& options,
                                   int margin) {
  const auto& [a, b, c, e] = g.laser_plane;
  (void)a;  // the width is taken on the centre column, where a does not enter
  if (!(g.sheet_width_m > 0)) throw std::invalid_argument("laser.sheet_width_m must be > 0");
  if (e == 0.0) throw std::invalid_argument("laser plane passes through the camera centre");
  // l(v) = fy l_w / Z(cx, v), 1 / Z = -(b (v - cy) / fy + c) / e.
  beta_ = -g.sheet_width_m * b / e;
  alpha_ = -g.fy * g.sheet_width_m * (c - b * g.cy / g.fy) / e;
  if (std::abs(beta_) * g.height < 1e-6 * std::abs(alpha_) || !std::isfinite(beta_)) {
    throw std::invalid_argument(
        "laser plane: the sheet's depth must change along the image columns (b != 0)");
  }
  scale_ = options.normalised_width_px;
  const double l_far = g.fy * g.sheet_width_m / options.max_depth_m;
  const double l_near = g.fy * g.sheet_width_m / options.min_depth_m;
  double v_lo = (l_far - alpha_) / beta_, v_hi = (l_near - alpha_) / beta_;
  if (v_lo > v_hi) std::swap(v_lo, v_hi);
  v_lo = std::max(v_lo, 0.0);
  v_hi = std::min(v_hi, static_cast<double>(g.height - 1));
  if (!(v_lo < v_hi)) {
    throw std::invalid_argument(
        "detector.frontend: no image row sees the laser sheet between min_depth_m and "
        "max_depth_m");
  }
  r0_ = 0.0;
  r0_ = static_cast<double>(margin) - to_normalised(v_lo);
  const int count = static_cast<int>(std::ceil(to_normalised(v_hi))) + 1 + margin;
  source_row_.resize(static_cast<std::size_t>(count));
  const float last = static_cast<float>(g.height - 1);
  for (int r = 0; r < count; ++r) {
    source_row_[static_cast<std::size_t>(r)] =
        std::clamp(static_cast<float>(to_source(r)), 0.0f, last);
  }
}

double RowNormalisation::to_normalised(double v) const {
  // dr/dv = W / l(v); l(v) > 0 wherever the sheet is in front of the camera.
  return scale_ / beta_ * std::log(std::max(alpha_ + beta_ * v, 1e-12)) + r0_;
}

double RowNormalisation::to_source(double r) const {
  return (std::exp((r - r0_) * beta_ / scale_) - alpha_) / beta_;
}

// ---------------------------------------------------------------------------------------------

Frontend::Frontend(const ScannerGeometry& geometry, const FrontendOptions& options)
    : geometry_(geometry), options_(options) {
  if (!(options.min_depth_m > 0) || !(options.max_depth_m > options.min_depth_m)) {
    throw std::invalid_argument("detector.frontend: need 0 < min_depth_m < max_depth_m");
  }
  if (options.max_candidates_per_column < 1 || options.max_candidates_per_column > 255) {
    throw std::invalid_argument("detector.frontend.max_candidates_per_column must be 1..255");
  }
  inner_ = odd_at_least_one(options.normalised_width_px);
  outer_ = odd_at_least_one(options.normalised_width_px * options.passband_ratio);
  if (outer_ <= inner_) outer_ = inner_ + 2;
  // The noise window leaves out a guard band as wide as the band-pass response of a line at the
  // pixel itself (as a CFAR detector does): otherwise a strong line raises its own noise estimate
  // and scores lower than faint texture next to it.
  guard_ = inner_ / 2 + outer_ / 2;
  noise_half_ = std::max(options.noise_rows / 2, guard_ + 1);
  noise_pad_ = std::max(options.noise_columns, 1) / 2;
  noise_norm_ = 1.0f / static_cast<float>(2 * (noise_half_ - guard_) * (2 * noise_pad_ + 1));
  rows_ = RowNormalisation(geometry, options, outer_ / 2 + 2);
}

void Frontend::reset(int width, int height) {
  if (width != geometry_.width || height != geometry_.height) {
    throw std::invalid_argument("frame size " + std::to_string(width) + "x" +
                                std::to_string(height) + " differs from the calibration's " +
                                std::to_string(geometry_.width) + "x" +
                                std::to_string(geometry_.height));
  }
  if (width < 2 * kWarpBlock || height < 4) {
    throw std::invalid_argument("frame smaller than " + std::to_string(2 * kWarpBlock) +
                                "x4 pixels");
  }
  width_ = width;
  height_ = height;
  stride_ = (width + kBlock - 1) / kBlock * kBlock;
  const auto n = static_cast<std::size_t>(rows_.rows()) * stride_;
  prefix_.assign(n + stride_, 0);
  band_passed_.assign(n, 0.0f);
  abs_prefix_.assign(n + stride_, 0.0f);
  row_mask_.assign(static_cast<std::size_t>(stride_), 0u);
  column_best_.assign(static_cast<std::size_t>(width) * options_.max_candidates_per_column, {});
  column_count_.assign(static_cast<std::size_t>(width), 0);
}

namespace {

// The normalised image is held in fixed point, 1/256 grey level: interpolation weights of 8 bit
// and 16-bit lanes (twice the floats per vector), clipping at 0 by a saturating subtraction, and
// exact 32-bit column prefix sums (no rounding drift down a column).
constexpr int kFixedOne = 256;

inline std::uint16_t fixed_weight(float t) {
  return static_cast<std::uint16_t>(std::clamp(t, 0.0f, 1.0f) * kFixedOne + 0.5f);
}

// One row of the normalised image accumulated into the column prefix sums: sum = above + value,
// value = the current frame interpolated between rows a and b (weight fb of b).
void accumulate_row(const std::uint8_t* __restrict a, const std::uint8_t* __restrict b,
                    std::uint16_t fb, const std::int32_t* __restrict above, int count,
                    std::int32_t* __restrict sum) {
  const auto fa = static_cast<std::uint16_t>(kFixedOne - fb);
  for (int u = 0; u < count; ++u) {
    const auto value = static_cast<std::uint16_t>(a[u] * fa + b[u] * fb);
    sum[u] = above[u] + value;
  }
}

// The same for one warp block, minus the background sampled bilinearly at a constant sub-pixel
// shift (rows p and q of the background, weights w summing to 256), clipped at 0.
void accumulate_difference(const std::uint8_t* __restrict a, const std::uint8_t* __restrict b,
                           std::uint16_t fb, const std::uint8_t* __restrict p,
                           const std::uint8_t* __restrict q, const std::array<std::uint16_t, 4>& w,
                           const std::int32_t* __restrict above, std::int32_t* __restrict sum) {
  const auto fa = static_cast<std::uint16_t>(kFixedOne - fb);
  const std::uint16_t w00 = w[0], w01 = w[1], w10 = w[2], w11 = w[3];
  for (int k = 0; k < Frontend::kWarpBlock; ++k) {
    const auto current = static_cast<std::uint16_t>(a[k] * fa + b[k] * fb);
    const auto warped =
        static_cast<std::uint16_t>(p[k] * w00 + p[k + 1] * w01 + q[k] * w10 + q[k + 1] * w11);
    const auto difference = static_cast<std::uint16_t>(current > warped ? current - warped : 0);
    sum[k] = above[k] + difference;
  }
}

// One row of the band-pass from box sums over the column prefix sums (inner minus outer mean),
// and the prefix sums of its magnitude.
void band_pass_row(const std::int32_t* __restrict i_hi, const std::int32_t* __restrict i_lo,
                   float wi, const std::int32_t* __restrict o_hi,
                   const std::int32_t* __restrict o_lo, float wo, const float* __restrict abs_above,
                   int count, float* __restrict out, float* __restrict abs_sum) {
  for (int u = 0; u < count; ++u) {
    const float band =
        static_cast<float>(i_hi[u] - i_lo[u]) * wi - static_cast<float>(o_hi[u] - o_lo[u]) * wo;
    out[u] = band;
    abs_sum[u] = abs_above[u] + std::abs(band);
  }
}

// Flags the pixels of a band-pass row at or above the threshold and above their neighbours in the
// rows above and below. 32-bit flags: what a vector float comparison yields, so it vectorises.
void mark_peaks(const float* __restrict row, const float* __restrict up,
                const float* __restrict down, float threshold, int count,
                std::uint32_t* __restrict mask) {
  for (int u = 0; u < count; ++u) {
    const float x = row[u];
    mask[u] = (x >= threshold ? 1u : 0u) & (x > up[u] ? 1u : 0u) & (x >= down[u] ? 1u : 0u);
  }
}

inline std::array<std::uint16_t, 4> bilinear_weights(float tx, float ty) {
  const float one = kFixedOne;
  const auto w00 = static_cast<std::uint16_t>((1.0f - tx) * (1.0f - ty) * one + 0.5f);
  const auto w01 = static_cast<std::uint16_t>(tx * (1.0f - ty) * one + 0.5f);
  const auto w10 = static_cast<std::uint16_t>((1.0f - tx) * ty * one + 0.5f);
  // The four sum to 256 (w11 absorbs the rounding; it cannot go below 0 by more than rounding).
  const int w11 = std::max(kFixedOne - w00 - w01 - w10, 0);
  return {w00, w01, w10, static_cast<std::uint16_t>(w11)};
}

// The two rows of the frame a normalised row is interpolated from, and the weight of the lower.
struct SourceRow {
  SourceRow(const ImageView& image, float v) {
    const int last = image.height - 1;
    const int v0 = std::min(static_cast<int>(v), last);
    a = image.row(v0);
    b = image.row(std::min(v0 + 1, last));
    f = v - static_cast<float>(v0);
    fb = fixed_weight(f);
  }
  const std::uint8_t* a;
  const std::uint8_t* b;
  float f;
  std::uint16_t fb;
};

}  // namespace

LASERLINE_DENSE_KERNEL
void Frontend::normalise(const ImageView& current) {
  current_ = current;
  subtracting_ = false;
  const std::size_t s = static_cast<std::size_t>(stride_);
  for (int r = 0; r < rows_.rows(); ++r) {
    const SourceRow row(current, rows_.source_row(r));
    accumulate_row(row.a, row.b, row.fb, prefix_.data() + r * s, width_,
                   prefix_.data() + (r + 1) * s);
  }
}

LASERLINE_DENSE_KERNEL
void Frontend::normalise_subtracting(const ImageView& current, const ImageView& background,
                                     const Homography& current_to_background) {
  current_ = current;
  background_ = background;
  to_background_ = current_to_background;
  subtracting_ = true;
  // The background may be a band of rows of the frame (its own size; the homography says where).
  const auto bg_width = static_cast<float>(background.width);
  const auto bg_height = static_cast<float>(background.height);
  const std::size_t s = static_cast<std::size_t>(stride_);
  for (int r = 0; r < rows_.rows(); ++r) {
    const float v = rows_.source_row(r);
    const SourceRow row(current, v);
    const std::uint8_t* a = row.a;
    const std::uint8_t* b = row.b;
    const float f = row.f;
    const std::uint16_t fb = row.fb;
    const std::int32_t* above = prefix_.data() + r * s;
    std::int32_t* sum = prefix_.data() + (r + 1) * s;
    // Along the row the background position is a ratio of linear functions of u: numerators and
    // denominator at u = 0, and their steps per pixel.
    const auto& g = current_to_background.h;
    const auto xn0 = static_cast<float>(g[1] * v + g[2]), xnu = static_cast<float>(g[0]);
    const auto yn0 = static_cast<float>(g[4] * v + g[5]), ynu = static_cast<float>(g[3]);
    const auto wn0 = static_cast<float>(g[7] * v + g[8]), wnu = static_cast<float>(g[6]);
    for (int u0 = 0; u0 < width_; u0 += kWarpBlock) {
      const int count = std::min(kWarpBlock, width_ - u0);
      // Where the block's centre was in the background; the block moves as a whole.
      const float centre = static_cast<float>(u0) + 0.5f * static_cast<float>(count - 1);
      const float inv = 1.0f / (wn0 + wnu * centre);
      const float y = (yn0 + ynu * centre) * inv;
      const float x0 = (xn0 + xnu * centre) * inv - (centre - static_cast<float>(u0));
      const float fx0 = std::floor(x0), fy0 = std::floor(y);
      if (count != kWarpBlock || !(fx0 >= 0.0f && fx0 + static_cast<float>(count) < bg_width &&
                                   fy0 >= 0.0f && fy0 + 1.0f < bg_height)) {
        // At the border of the background frame, pixel by pixel; where there is nothing to
        // compare with there is no signal.
        for (int k = 0; k < count; ++k) {
          const float xk = x0 + static_cast<float>(k);
          const float x_cur = static_cast<float>(a[u0 + k]);
          const float now = x_cur + f * (static_cast<float>(b[u0 + k]) - x_cur);
          const bool inside =
              xk >= 0.0f && xk < bg_width - 1.0f && y >= 0.0f && y < bg_height - 1.0f;
          const float difference = inside ? now - bilinear(background, xk, y) : 0.0f;
          sum[u0 + k] = above[u0 + k] + static_cast<std::int32_t>(
                                            std::lround(std::max(difference, 0.0f) * kFixedOne));
        }
        continue;
      }
      const auto ix = static_cast<int>(fx0), iy = static_cast<int>(fy0);
      const float tx = x0 - fx0, ty = y - fy0;
      const std::uint8_t* p = background.row(iy) + ix;
      accumulate_difference(a + u0, b + u0, fb, p, p + background.stride, bilinear_weights(tx, ty),
                            above + u0, sum + u0);
    }
  }
}

float Frontend::normalised_at(int r, int u) const {
  const std::size_t s = static_cast<std::size_t>(stride_);
  return static_cast<float>(prefix_[(r + 1) * s + u] - prefix_[r * s + u]) / kFixedOne;
}

LASERLINE_DENSE_KERNEL
void Frontend::band_pass() {
  const int rows = rows_.rows();
  const std::size_t s = static_cast<std::size_t>(stride_);
  const int hi = inner_ / 2, ho = outer_ / 2;
  // Boxes of any height from the column prefix sums (III-C's integral image), and the prefix
  // sums of |band| for the noise of III-D, in one pass. At the ends the boxes are cut short and
  // averaged over what they cover.
  std::fill(abs_prefix_.begin(), abs_prefix_.begin() + stride_, 0.0f);
  for (int r = 0; r < rows; ++r) {
    const int i0 = std::max(r - hi, 0), i1 = std::min(r + hi + 1, rows);
    const int o0 = std::max(r - ho, 0), o1 = std::min(r + ho + 1, rows);
    const float wi = 1.0f / static_cast<float>((i1 - i0) * kFixedOne);
    const float wo = 1.0f / static_cast<float>((o1 - o0) * kFixedOne);
    const std::int32_t* __restrict i_hi = prefix_.data() + i1 * s;
    const std::int32_t* __restrict i_lo = prefix_.data() + i0 * s;
    const std::int32_t* __restrict o_hi = prefix_.data() + o1 * s;
    const std::int32_t* __restrict o_lo = prefix_.data() + o0 * s;
    band_pass_row(i_hi, i_lo, wi, o_hi, o_lo, wo, abs_prefix_.data() + r * s, stride_,
                  band_passed_.data() + r * s, abs_prefix_.data() + (r + 1) * s);
  }
}

float Frontend::snr_at(int r, int u) const {
  const int rows = rows_.rows();
  const std::size_t s = static_cast<std::size_t>(stride_);
  const float* n_hi = abs_prefix_.data() + std::min(r + noise_half_ + 1, rows) * s;
  const float* n_lo = abs_prefix_.data() + std::max(r - noise_half_, 0) * s;
  const float* g_hi = abs_prefix_.data() + std::min(r + guard_ + 1, rows) * s;
  const float* g_lo = abs_prefix_.data() + std::max(r - guard_, 0) * s;
  float sum = 0.0f;
  for (int k = -noise_pad_; k <= noise_pad_; ++k) {
    const int c = std::clamp(u + k, 0, width_ - 1);
    sum += (n_hi[c] - n_lo[c]) - (g_hi[c] - g_lo[c]);
  }
  // III-D: the minimal noise level is 1.
  return band_passed_[r * s + u] / std::max(sum * noise_norm_, 1.0f);
}

void Frontend::signal_to_noise_image(std::span<float> out) const {
  const std::size_t s = static_cast<std::size_t>(stride_);
  if (out.size() < static_cast<std::size_t>(rows_.rows()) * s) {
    throw std::invalid_argument("signal_to_noise_image: output too small");
  }
  for (int r = 0; r < rows_.rows(); ++r) {
    for (int u = 0; u < width_; ++u)
      out[r * s + u] = snr_at(r, u);
  }
}

namespace {

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
    if (!(x >= 0.0f && x < x_max_ && y >= 0.0f && y < y_max_)) return 0.0f;
    return std::max(value - bilinear(*background_, x, y), 0.0f);
  }

 private:
  const ImageView& current_;
  const ImageView* background_;
  int u_, v0_;
  float x0_ = 0, y0_ = 0, dx_ = 0, dy_ = 0, x_max_ = 0, y_max_ = 0;
};

}  // namespace

float Frontend::refine_row(int u, float v_guess) const {
  const double width = std::max(rows_.width_px(v_guess), 1.0);
  const int last = height_ - 1;
  const double sigma = width / kFwhmToSigma;
  const int spacing = std::max(1, static_cast<int>(std::lround(sigma)));
  const int edge = static_cast<int>(std::ceil(2.5 * sigma)) + 1;
  // The guess comes from a normalised row, good to about half a normalised width.
  const int reach =
      static_cast<int>(std::ceil(0.5 * width / options_.normalised_width_px + 0.5)) + 1;
  const int centre = std::clamp(static_cast<int>(std::lround(v_guess)), 0, last);
  const ColumnSampler at(current_, subtracting_ ? &background_ : nullptr, to_background_, u,
                         centre);

  const int lo = std::max(centre - reach, 0), hi = std::min(centre + reach, last);
  int best = lo;
  float best_value = at(lo);
  for (int v = lo + 1; v <= hi; ++v) {
    const float value = at(v);
    if (value > best_value) {
      best_value = value;
      best = v;
    }
  }

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
  const float before = at(best - edge), after = at(best + edge);
  const float slope = (after - before) / static_cast<float>(2 * edge);
  const float level = 0.5f * (before + after);
  const float step = slope * static_cast<float>(spacing);
  const float a = at(best - spacing) - (level - step);
  const float b = best_value - level;
  const float c = at(best + spacing) - (level + step);
  return static_cast<float>(best) + static_cast<float>(spacing) * gaussian_offset(a, b, c);
}

LASERLINE_DENSE_KERNEL
void Frontend::find_candidates(Profile& out) {
  out.clear();
  const int rows = rows_.rows();
  const int per_column = options_.max_candidates_per_column;
  std::fill(column_count_.begin(), column_count_.end(), 0);
  const float threshold = std::pow(10.0f, static_cast<float>(options_.snr_threshold_db) / 20.0f);
  const std::size_t s = static_cast<std::size_t>(stride_);
  // Candidates are local maxima of the band-pass within one laser width along the column: the
  // noise window (guard band excluded) is the same to within a row there, so these are the
  // maxima of the SNR too. Rows in the margins are outside the depth range.
  const int reach = std::max(1, inner_ / 2 + 1);
  const int margin = outer_ / 2 + 2;
  std::uint32_t* __restrict mask = row_mask_.data();
  for (int r = std::max(margin, reach); r < rows - std::max(margin, reach); ++r) {
    const float* __restrict row = band_passed_.data() + r * s;
    const float* __restrict up = row - s;
    const float* __restrict down = row + s;
    // The dense part, branch-free so that it vectorises: above the threshold and above the
    // direct neighbours. The wider window is checked on the few pixels that pass.
    mark_peaks(row, up, down, threshold, stride_, mask);
    for (int u0 = 0; u0 < width_; u0 += kBlock) {
      std::uint32_t any = 0;
      for (int k = 0; k < kBlock; ++k)
        any |= mask[u0 + k];
      if (any == 0) continue;
      for (int u = u0; u < std::min(u0 + kBlock, width_); ++u) {
        if (!mask[u]) continue;
        const float value = row[u];
        bool peak = true;
        for (int k = 2; k <= reach && peak; ++k) {
          peak = value > row[u - static_cast<std::ptrdiff_t>(k * s)] &&
                 value >= row[u + static_cast<std::ptrdiff_t>(k * s)];
        }
        if (!peak) continue;
        const float snr = snr_at(r, u);
        if (!(snr >= threshold)) continue;
        // Keep the strongest few per column (bounded work and output). Strongest by band-pass
        // amplitude: the laser adds light, while a faint texture edge in a quiet
        // neighbourhood can have the higher SNR.
        Peak* best = column_best_.data() + static_cast<std::size_t>(u) * per_column;
        const int n = column_count_[u];
        int slot = n;
        if (n == per_column) {
          slot = 0;
          for (int i = 1; i < n; ++i)
            if (best[i].band < best[slot].band) slot = i;
          if (best[slot].band >= value) continue;
        } else {
          column_count_[u] = static_cast<std::uint8_t>(n + 1);
        }
        // Sub-row position of the band-pass peak, mapped back to an original row: the guess
        // the refinement starts from.
        const float a = up[u], c = down[u];
        const float curvature = a - 2.0f * value + c;
        const float offset =
            curvature < 0.0f ? std::clamp(0.5f * (a - c) / curvature, -0.5f, 0.5f) : 0.0f;
        best[slot] = Peak{static_cast<float>(rows_.to_source(r + offset)), snr, value};
      }
    }
  }
  for (int u = 0; u < width_; ++u) {
    Peak* best = column_best_.data() + static_cast<std::size_t>(u) * per_column;
    const int n = column_count_[u];
    std::sort(best, best + n, [](const Peak& a, const Peak& b) { return a.v < b.v; });
    // One laser point per epipolar line: the strongest candidate is the front-end's choice; the
    // others stay in the profile, not valid, for validation (Section IV) to reconsider.
    int strongest = 0;
    for (int i = 1; i < n; ++i)
      if (best[i].band > best[strongest].band) strongest = i;
    for (int i = 0; i < n; ++i) {
      ProfilePoint point;
      point.u = u;
      // Only the chosen point gets the sub-pixel fit (the costly part of this stage); the others
      // keep the band-pass peak's row, good to about half a laser width.
      point.v = i == strongest ? refine_row(u, best[i].v) : best[i].v;
      point.snr_db = 20.0f * std::log10(best[i].snr);
      point.valid = i == strongest;
      if (!out.add(point)) return;
    }
  }
}

}  // namespace laserline::pipeline
