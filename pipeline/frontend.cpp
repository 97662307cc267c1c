#include "pipeline/frontend.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <type_traits>

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
// Row kernels and the helpers of a dense kernel are inlined into it, so that they are compiled
// for the target of each of its versions.
#define LASERLINE_ROW_KERNEL __attribute__((always_inline)) inline
#define LASERLINE_ROW_LAMBDA __attribute__((always_inline))
// Where auto-vectorisation falls short, a kernel is written in AVX2 intrinsics, in functions
// compiled for AVX2 and chosen at run time (the CPU is asked once, in the constructor).
#if LASERLINE_AVX2_KERNELS
#include <immintrin.h>
#endif

namespace laserline::pipeline {

namespace {

constexpr double kSigmaPerFwhm = 1.0 / 2.3548200450309493;  // a Gaussian's sigma per FWHM
constexpr float kDecibelsPerNeper = 8.68588963806503655f;   // 20 / ln 10
// Interpolation is done in fixed point, 1/128 grey level (see the row kernels).
constexpr int kFixedOne = 128;
constexpr int kFixedBits = 7;
// Row kernels run over blocks of this many pixels with a constant trip count: what GCC needs to
// vectorise them. Float rows are padded to a multiple of it.
constexpr int kBlock = 16;

int odd_at_least_one(double x) {
  const int n = std::max(1, static_cast<int>(std::lround(x)));
  return n % 2 == 1 ? n : n + 1;
}

// std::ceil(x) for 0 <= x < 2^31, without the call the baseline x86-64 makes for it.
inline int ceil_positive(double x) {
  const int whole = static_cast<int>(x);
  return whole + (static_cast<double>(whole) < x ? 1 : 0);
}

// Bilinear sample of a mono8 image; (x, y) must lie within [0, w-1) x [0, h-1).
inline float bilinear(const ImageView& image, float x, float y) {
  const int ix = static_cast<int>(x);
  const int iy = static_cast<int>(y);
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
  if (!(g.sheet_width_m > 0)) throw std::invalid_argument("the sheet width must be > 0");
  if (e == 0.0) throw std::invalid_argument("laser plane passes through the camera centre");
  // l(v) = fy l_w / Z(cx, v), 1 / Z = -(b (v - cy) / fy + c) / e: the width is modelled on the
  // centre column. The columns are searched when the sheet's depth changes along them within a
  // few degrees (pipeline/search_axes.hpp), so a changes it across the image only a little:
  // l(u, v) = l(v) + gamma (u - cx).
  beta_ = -g.sheet_width_m * b / e;
  alpha_ = -g.fy * g.sheet_width_m * (c - b * g.cy / g.fy) / e;
  if (std::abs(beta_) * g.height < 1e-6 * std::abs(alpha_) || !std::isfinite(beta_)) {
    throw std::invalid_argument(
        "laser plane: the sheet's depth must change along the epipolar lines (its normal must "
        "not be along the optical axis)");
  }
  const double gamma = -g.fy * g.sheet_width_m * a / (e * g.fx);
  scale_ = options.normalised_width_px;
  const double l_far = g.fy * g.sheet_width_m / options.max_depth_m;
  const double l_near = g.fy * g.sheet_width_m / options.min_depth_m;
  // The rows where some column sees the sheet within the depth range: the union over the first
  // and last column (l is affine in u), kept where the centre column's width stays positive.
  double v_lo = std::numeric_limits<double>::infinity(), v_hi = -v_lo;
  for (const double u : {0.0, static_cast<double>(g.width - 1)}) {
    const double offset = alpha_ + gamma * (u - g.cx);
    for (const double l : {l_far, l_near}) {
      v_lo = std::min(v_lo, (l - offset) / beta_);
      v_hi = std::max(v_hi, (l - offset) / beta_);
    }
  }
  const double positive = (0.5 * l_far - alpha_) / beta_;  // centre column at twice max_depth
  if (beta_ > 0) v_lo = std::max(v_lo, positive);
  if (beta_ < 0) v_hi = std::min(v_hi, positive);
  v_lo = std::max(v_lo, 0.0);
  v_hi = std::min(v_hi, static_cast<double>(g.height - 1));
  if (!(v_lo < v_hi)) {
    throw std::invalid_argument(
        "no image row sees the laser sheet between min_depth_m and max_depth_m");
  }
  r0_ = 0.0;
  r0_ = static_cast<double>(margin) - to_normalised(v_lo);
  const int count = static_cast<int>(std::ceil(to_normalised(v_hi))) + 1 + margin;
  single_alpha_ = static_cast<float>(alpha_);
  single_inverse_beta_ = static_cast<float>(1.0 / beta_);
  single_rate_ = static_cast<float>(beta_ / scale_);
  single_r0_ = static_cast<float>(r0_);
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

float RowNormalisation::to_source_single(float r) const {
  return (std::exp((r - single_r0_) * single_rate_) - single_alpha_) * single_inverse_beta_;
}

// ---------------------------------------------------------------------------------------------

Frontend::Frontend(const ScannerGeometry& geometry, const FrontendOptions& options)
    : geometry_(geometry), options_(options), selector_(options.selection) {
  options.validate();
  use_intrinsics(true);
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
  // The band-pass as an integer: inner mean - outer mean = g (a S_inner - b S_outer) /
  // (inner outer one), with a = outer / g, b = inner / g (g their gcd) and one the normalised
  // rows' fixed-point one. Its extremes are +-255 (1 - inner / outer) grey levels, so it fits
  // 16-bit lanes when 255 one (outer - inner) inner / g does (and the outer box's sum,
  // 255 one outer, fits 16 unsigned bits): with the most fractional bits of the normalised rows
  // (at most 4, at least 2) for which that holds, else 32-bit lanes and the 7 of the
  // interpolation.
  const int g = std::gcd(inner_, outer_);
  band_a_ = outer_ / g;
  band_b_ = inner_ / g;
  const long extreme = 255L * (outer_ - inner_) * inner_ / g;
  int bits = kFixedBits;
  narrow_band_ = false;
  for (int narrow_bits = 4; narrow_bits >= 2 && !narrow_band_; --narrow_bits) {
    if ((extreme << narrow_bits) <= 32767 && (255L << narrow_bits) * outer_ <= 65535) {
      narrow_band_ = true;
      bits = narrow_bits;
    }
  }
  normalised_shift_ = kFixedBits - bits;
  band_unit_ = static_cast<float>(g) / static_cast<float>(inner_ * outer_ * (1 << bits));
  // Candidates are local maxima of the band-pass within one laser width along the column: the
  // noise window (guard band excluded) is the same to within a row there, so these are the
  // maxima of the SNR too.
  reach_ = std::max(1, inner_ / 2 + 1);
  // A line's band-pass is negative on both sides, most so about an inner box away (the outer box
  // holds the line, the inner one not), an edge's on one side only: the ridge test looks for the
  // negative lobe within half an outer box beyond where the band-pass crosses zero (farther out
  // for a line wider than the model: a clipped or blurred one).
  ridge_ = outer_ / 2 + 1;
  half_per_normalised_width_ = 0.5 / options.normalised_width_px;
  margin_ = outer_ / 2 + 2;
  rows_ = RowNormalisation(geometry, options, margin_);
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
  // Each strip's band-pass ring holds the rows from the oldest the noise window of the block's
  // first row r reaches (r - noise/2; a peak is compared with fewer) to the newest the block's
  // last row looks at; the normalised ring the rows the band-pass boxes of the block's rows reach.
  // (A row's slot in a ring is looked up once per block of rows, so the rings are no larger than
  // they must be: they stay in the cache.)
  const int look = std::max({noise_half_, reach_, ridge_});
  band_ring_rows_ = kRowBlock + 2 * look;
  normalised_ring_rows_ = kRowBlock + look + outer_ + 2;
  const int strips = (width + kStripColumns - 1) / kStripColumns;
  // A strip holds its columns and the noise window's reach on either side, the same count for
  // every strip (a constant trip count for its kernels): the normalised rows are padded with
  // zeros on both sides for the strips at the image's edges to read.
  ring_stride_ = (kStripColumns + 2 * noise_pad_ + kBlock - 1) / kBlock * kBlock;
  normalised_pad_ = (noise_pad_ + kBlock - 1) / kBlock * kBlock;
  normalised_stride_ = normalised_pad_ + strips * kStripColumns + ring_stride_;
  const auto ring = static_cast<std::size_t>(ring_stride_);
  const auto s = static_cast<std::size_t>(normalised_stride_);
  normalised_ring_.assign(static_cast<std::size_t>(normalised_ring_rows_) * s, 0);
  band_most_.assign(static_cast<std::size_t>(strips * (band_ring_rows_ + 1)), 0);
  // Each strip's rings end with a row of zeros (the rows beyond the ends); the last, with a
  // register's lanes more for the noise sums to read past it.
  const auto band_ring = static_cast<std::size_t>(strips * (band_ring_rows_ + 1)) * ring + kBlock;
  narrow_.assign(narrow_band_ ? band_ring : 0, narrow_band_ ? strips * ring : 0);
  wide_.assign(narrow_band_ ? 0 : band_ring, narrow_band_ ? 0 : strips * ring);
  band_rows_.assign(static_cast<std::size_t>(kRowBlock + 2 * look), 0);
  band_slots_.assign(band_rows_.size(), 0);
  normalised_rows_.assign(static_cast<std::size_t>(kRowBlock + look + outer_ + 3), nullptr);
  const auto blocks = static_cast<std::size_t>((width + kWarpBlock - 1) / kWarpBlock);
  warp_left_.assign(blocks, 0);
  warp_top_.assign(blocks, 0);
  warp_whole_.assign(blocks, 0);
  warp_offset_.assign(blocks, 0);
  warp_pairs_.assign(2 * blocks, 0);
  zero_normalised_.assign(s, 0);
  peak_flags_.assign(ring + 8, 0u);
  peak_bits_.assign((ring + 63) / 64, 0u);
  column_best_.assign(static_cast<std::size_t>(width) * options_.max_candidates_per_column, {});
  column_count_.assign(static_cast<std::size_t>(width), 0);
  line_candidates_.assign(static_cast<std::size_t>(width) * options_.max_candidates_per_column, {});
  eligible_.assign(line_candidates_.size(), {});
  eligible_count_.assign(static_cast<std::size_t>(width), 0);
  eligible_point_.assign(line_candidates_.size(), 0);
  chosen_.assign(static_cast<std::size_t>(width), -1);
  selector_.reset(width, options_.max_candidates_per_column);
  probe_count_ = 0;
  refine_columns_.assign(static_cast<std::size_t>(width), 0);
  refine_guesses_.assign(static_cast<std::size_t>(width), 0.0f);
  refine_points_.assign(static_cast<std::size_t>(width), 0);
}

namespace {

// Interpolation is done in fixed point, 1/128 grey level: weights of 7 bits (summing to 128),
// so that a pixel's weighted sum fits 16 signed bits, as AVX2's multiply-add of bytes wants.
// (The warp is a translation per block, off by up to 0.05 pixel: at an edge of 255 grey levels,
// 13 of them, against at most 1 for weights rounded to 1/256 instead of 1/128.) Clipped at 0.
// The normalised rows keep 7 - shift fractional bits of it, rounded (fewer where the band-pass
// is to fit 16-bit lanes: see the constructor).

LASERLINE_ROW_KERNEL std::uint16_t to_precision(unsigned value, int shift) {
  return static_cast<std::uint16_t>((value + ((1u << shift) >> 1)) >> shift);
}

// Two weights as the byte pair AVX2's multiply-add of bytes takes (the first in the low byte of a
// 16-bit word), negated: -128 fits a signed byte, +128 does not.
LASERLINE_ROW_KERNEL std::int32_t negated_pair(std::int32_t first, std::int32_t second) {
  return (-first & 0xff) | ((-second & 0xff) << 8);
}

inline std::uint16_t fixed_weight(float t) {
  return static_cast<std::uint16_t>(std::clamp(t, 0.0f, 1.0f) * kFixedOne + 0.5f);
}

// Row kernels. Each runs over whole rows with __restrict pointers so that GCC vectorises it.

// A normalised row: the current frame interpolated between rows a and b (weight fb of b).
LASERLINE_ROW_KERNEL void interpolate_row(const std::uint8_t* __restrict a,
                                          const std::uint8_t* __restrict b, std::uint16_t fb,
                                          int shift, int count, std::uint16_t* __restrict out) {
  const auto fa = static_cast<std::uint16_t>(kFixedOne - fb);
  for (int u = 0; u < count; ++u)
    out[u] = to_precision(static_cast<std::uint16_t>(a[u] * fa + b[u] * fb), shift);
}

// The four bilinear weights of a warp block (summing to 128).
struct BlockWeights {
  std::uint16_t w00, w01, w10, w11;
};

// `count` pixels of one warp block, minus the background sampled bilinearly at a constant
// sub-pixel shift (rows p and q of the background), clipped at 0.
LASERLINE_ROW_KERNEL void difference_block(const std::uint8_t* __restrict a,
                                           const std::uint8_t* __restrict b, std::uint16_t fb,
                                           const std::uint8_t* __restrict p,
                                           const std::uint8_t* __restrict q, BlockWeights w,
                                           int shift, int count, std::uint16_t* __restrict out) {
  const auto fa = static_cast<std::uint16_t>(kFixedOne - fb);
  for (int k = 0; k < count; ++k) {
    const auto current = static_cast<std::uint16_t>(a[k] * fa + b[k] * fb);
    const auto warped = static_cast<std::uint16_t>(p[k] * w.w00 + p[k + 1] * w.w01 + q[k] * w.w10 +
                                                   q[k + 1] * w.w11);
    out[k] = to_precision(current > warped ? current - warped : 0u, shift);
  }
}

// A normalised row being made: rows a and b of the current frame (weight fb of b), background
// rows `stride` apart, the output row (`shift` bits of the fixed point dropped).
struct RowDifference {
  const std::uint8_t* a;
  const std::uint8_t* b;
  std::uint16_t fb;
  std::ptrdiff_t stride;
  int shift;
  std::uint16_t* out;
};

// difference_block() as the functor difference_blocks() takes.
struct DifferenceGeneric : RowDifference {
  LASERLINE_ROW_KERNEL void operator()(int u, const std::uint8_t* p, BlockWeights w, int count) {
    difference_block(a + u, b + u, fb, p, p + stride, w, shift, count, out + u);
  }
};

// The warp blocks of a normalised row (see Frontend::normalise_row()).
struct WarpBlocks {
  const std::int32_t* left;
  const std::int32_t* top;
  const std::int32_t* whole;
  const std::int32_t* offset;  // of the first pixel's background pixel, where whole
  const std::int32_t* pairs;   // negated_pair(w00, w01), negated_pair(w10, w11) of each block
  const std::uint8_t* background;
  std::ptrdiff_t stride;
  int blocks, width, last_column, last_row;
  int partial;  // blocks not whole

  BlockWeights weights_of(int j) const {
    return {weight(pairs[2 * j], 0), weight(pairs[2 * j], 8), weight(pairs[2 * j + 1], 0),
            weight(pairs[2 * j + 1], 8)};
  }
  static std::uint16_t weight(std::int32_t pair, int at) {
    return static_cast<std::uint16_t>(-static_cast<std::int8_t>((pair >> at) & 0xff));
  }
};

// The blocks partly or wholly outside the background, through `difference`: pixels [f, e) have
// their four neighbours inside it; elsewhere there is nothing to compare with, so no signal.
// (Few or none: the scan stops after the last.)
template <class Difference>
LASERLINE_ROW_KERNEL void difference_partial_blocks(const WarpBlocks& w, Difference& difference,
                                                    std::uint16_t* out) {
  constexpr int kWarp = Frontend::kWarpBlock;
  for (int j = 0, partial = w.partial; partial > 0; ++j) {
    if (w.whole[j]) continue;
    --partial;
    const int u0 = j * kWarp;
    const int count = std::min(kWarp, w.width - u0);
    const int ix = w.left[j], iy = w.top[j];
    const bool rows_inside = iy >= 0 && iy < w.last_row;
    const int f = rows_inside ? std::clamp(-ix, 0, count) : count;
    const int e = rows_inside ? std::clamp(w.last_column - ix, f, count) : count;
    std::fill(out + u0, out + u0 + f, std::uint16_t{0});
    std::fill(out + u0 + e, out + u0 + count, std::uint16_t{0});
    if (f < e) {
      difference(u0 + f, w.background + static_cast<std::ptrdiff_t>(iy) * w.stride + ix + f,
                 w.weights_of(j), e - f);
    }
  }
}

// The row, block by block, through DifferenceGeneric.
template <class Difference>
LASERLINE_ROW_KERNEL void difference_blocks(const WarpBlocks& w, Difference& difference,
                                            std::uint16_t* out) {
  constexpr int kWarp = Frontend::kWarpBlock;
  for (int j = 0; j < w.blocks; ++j) {
    if (w.whole[j]) difference(j * kWarp, w.background + w.offset[j], w.weights_of(j), kWarp);
  }
  difference_partial_blocks(w, difference, out);
}

#if LASERLINE_AVX2_KERNELS
// Sixteen bytes widened to 16-bit lanes.
__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256i widen(const std::uint8_t* x) {
  return _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(x)));
}

// difference_blocks()'s functor in AVX2: a whole block, 32 pixels, with multiply-adds of byte
// pairs (a pixel and its right neighbour, or the pixel in rows a and b); the rest sixteen pixels
// to a register (GCC's own vectorisation of this register-hungry loop widens each load in three
// steps and spills).
struct DifferenceAvx2 : RowDifference {
  __m256i weight_a, weight_b, half, w00, w01, w10, w11, rows_pair;
  __m128i bits;

  __attribute__((target("avx2"))) explicit DifferenceAvx2(const RowDifference& row)
      : RowDifference(row),
        weight_a(_mm256_set1_epi16(static_cast<short>(kFixedOne - row.fb))),
        weight_b(_mm256_set1_epi16(static_cast<short>(row.fb))),
        half(_mm256_set1_epi16(static_cast<short>((1 << row.shift) >> 1))),
        rows_pair(_mm256_set1_epi16(static_cast<short>(negated_pair(kFixedOne - row.fb, row.fb)))),
        bits(_mm_cvtsi32_si128(row.shift)) {}

  // Thirty-two pixels from column u (p the background pixel under it), weights w, into the row.
  // Loaded as 16-bit words, the bytes of a row pair up: word i holds pixels 2i and 2i + 1, which
  // the multiply-add weights as pixel 2i and its right neighbour; loaded a pixel on, the same for
  // pixel 2i + 1. The current frame's rows a and b pair up as (a, b) by masks and shifts. So the
  // even pixels and the odd ones come out in two registers, interleaved back at the end.
  __attribute__((target("avx2"))) LASERLINE_ROW_KERNEL void thirty_two(
      int u, const std::uint8_t* p, std::int32_t top_pair, std::int32_t bottom_pair) const {
    const __m256i low_bytes = _mm256_set1_epi16(0x00ff);
    const __m256i x = load(a + u), y = load(b + u);
    const __m256i even_rows =
        _mm256_or_si256(_mm256_and_si256(x, low_bytes), _mm256_slli_epi16(y, 8));
    const __m256i odd_rows =
        _mm256_or_si256(_mm256_srli_epi16(x, 8), _mm256_andnot_si256(low_bytes, y));
    const __m256i top = _mm256_set1_epi16(static_cast<short>(top_pair));
    const __m256i bottom = _mm256_set1_epi16(static_cast<short>(bottom_pair));
    const std::uint8_t* q = p + stride;
    // Each -(weighted sum): at least -255 x 128, within 16 signed bits.
    const __m256i even = difference_of(_mm256_maddubs_epi16(even_rows, rows_pair),
                                       _mm256_add_epi16(_mm256_maddubs_epi16(load(p), top),
                                                        _mm256_maddubs_epi16(load(q), bottom)));
    const __m256i odd = difference_of(_mm256_maddubs_epi16(odd_rows, rows_pair),
                                      _mm256_add_epi16(_mm256_maddubs_epi16(load(p + 1), top),
                                                       _mm256_maddubs_epi16(load(q + 1), bottom)));
    // Interleaved within 128-bit halves: pixels 0-7 and 16-23, then 8-15 and 24-31.
    const __m256i low = _mm256_unpacklo_epi16(even, odd), high = _mm256_unpackhi_epi16(even, odd);
    std::uint16_t* result = out + u;
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(result),
                        _mm256_permute2x128_si256(low, high, 0x20));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(result + 16),
                        _mm256_permute2x128_si256(low, high, 0x31));
  }

  __attribute__((target("avx2"))) static LASERLINE_ROW_KERNEL __m256i load(const std::uint8_t* x) {
    return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(x));
  }

  // current - warped from their negations, clipped at 0 and rounded to the row's precision.
  __attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256i
  difference_of(__m256i negated_current, __m256i negated_warped) const {
    const __m256i difference =
        _mm256_max_epi16(_mm256_sub_epi16(negated_warped, negated_current), _mm256_setzero_si256());
    return _mm256_srl_epi16(_mm256_add_epi16(difference, half), bits);
  }

  __attribute__((target("avx2"))) void set_weights(BlockWeights w) {
    w00 = _mm256_set1_epi16(static_cast<short>(w.w00));
    w01 = _mm256_set1_epi16(static_cast<short>(w.w01));
    w10 = _mm256_set1_epi16(static_cast<short>(w.w10));
    w11 = _mm256_set1_epi16(static_cast<short>(w.w11));
  }

  // Sixteen pixels: of the current rows x and y, the background rows p and q, into result.
  __attribute__((target("avx2"))) LASERLINE_ROW_KERNEL void sixteen(const std::uint8_t* x,
                                                                    const std::uint8_t* y,
                                                                    const std::uint8_t* p,
                                                                    const std::uint8_t* q,
                                                                    std::uint16_t* result) const {
    const __m256i current = _mm256_add_epi16(_mm256_mullo_epi16(widen(x), weight_a),
                                             _mm256_mullo_epi16(widen(y), weight_b));
    const __m256i warped = _mm256_add_epi16(
        _mm256_add_epi16(_mm256_mullo_epi16(widen(p), w00), _mm256_mullo_epi16(widen(p + 1), w01)),
        _mm256_add_epi16(_mm256_mullo_epi16(widen(q), w10), _mm256_mullo_epi16(widen(q + 1), w11)));
    // The laser only adds light: clipped at 0 (a saturating subtraction).
    const __m256i difference = _mm256_subs_epu16(current, warped);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(result),
                        _mm256_srl_epi16(_mm256_add_epi16(difference, half), bits));
  }

  // Pixels [u, u + count) of the row as difference_block(), p the background pixel under pixel
  // u: sixteen at a time, the last sixteen overlapping the ones before (they read no further
  // than difference_block would); fewer than sixteen one by one. (Inlined where
  // difference_blocks() is: in an AVX2 function.)
  __attribute__((target("avx2"))) void operator()(int u, const std::uint8_t* p, BlockWeights w,
                                                  int count) {
    if (count < 16) {
      difference_block(a + u, b + u, fb, p, p + stride, w, shift, count, out + u);
      return;
    }
    set_weights(w);
    for (int k = 0;; k += 16) {
      const int i = u + std::min(k, count - 16);
      sixteen(a + i, b + i, p + (i - u), p + (i - u) + stride, out + i);
      if (i == u + count - 16) break;
    }
  }
};

// A normalised row's warp blocks in AVX2. (Not forced inline: the function it is called from is
// also compiled for the baseline.)
__attribute__((target("avx2"))) inline void difference_blocks_avx2(const WarpBlocks& w,
                                                                   const RowDifference& row) {
  DifferenceAvx2 difference(row);
  constexpr int kWarp = Frontend::kWarpBlock;
  for (int j = 0; j < w.blocks; ++j) {
    if (w.whole[j]) {
      difference.thirty_two(j * kWarp, w.background + w.offset[j], w.pairs[2 * j],
                            w.pairs[2 * j + 1]);
    }
  }
  difference_partial_blocks(w, difference, row.out);
}
#endif

// The band-pass row from the box sums of the normalised rows, each box sliding one row on:
// sum += entering - leaving (rows of zeros beyond the ends). The band-pass, inner mean minus outer
// mean, is held as the integer a * inner sum - b * outer sum (the constructor picks a and b and
// the unit): exact, and in 16-bit lanes (sixteen to an AVX2 register) wherever it and the sums
// fit (a * inner sum alone may not: that arithmetic is modulo 2^16, and the result fits).
// `most` is the row's largest band-pass (candidates need the threshold).
template <class Lane, class Sum = std::make_unsigned_t<Lane>>
LASERLINE_ROW_KERNEL void band_pass_row(Sum* __restrict inner,
                                        const std::uint16_t* __restrict inner_entering,
                                        const std::uint16_t* __restrict inner_leaving,
                                        Sum* __restrict outer,
                                        const std::uint16_t* __restrict outer_entering,
                                        const std::uint16_t* __restrict outer_leaving, Sum a, Sum b,
                                        int count, Lane* __restrict out, int& most) {
  Lane largest = std::numeric_limits<Lane>::min();
  for (int u = 0; u < count; ++u) {
    const auto i = static_cast<Sum>(inner[u] + inner_entering[u] - inner_leaving[u]);
    const auto o = static_cast<Sum>(outer[u] + outer_entering[u] - outer_leaving[u]);
    inner[u] = i;
    outer[u] = o;
    const auto band = static_cast<Lane>(static_cast<Sum>(a * i - b * o));
    out[u] = band;
    largest = std::max(largest, band);
  }
  most = largest;
}

// The same where a box is cut short by an end of the rows (a few rows at either end): the means
// over what each box covers (inner weight wi, outer wo per unit of sum), in the band-pass's unit.
template <class Lane, class Sum = std::make_unsigned_t<Lane>>
LASERLINE_ROW_KERNEL void band_pass_row_cut_short(
    Sum* __restrict inner, const std::uint16_t* __restrict inner_entering,
    const std::uint16_t* __restrict inner_leaving, Sum* __restrict outer,
    const std::uint16_t* __restrict outer_entering, const std::uint16_t* __restrict outer_leaving,
    float wi, float wo, int count, Lane* __restrict out, int& most) {
  Lane largest = std::numeric_limits<Lane>::min();
  for (int u = 0; u < count; ++u) {
    const auto i = static_cast<Sum>(inner[u] + inner_entering[u] - inner_leaving[u]);
    const auto o = static_cast<Sum>(outer[u] + outer_entering[u] - outer_leaving[u]);
    inner[u] = i;
    outer[u] = o;
    const float exact = static_cast<float>(i) * wi - static_cast<float>(o) * wo;
    // Rounded half away from zero, branch-free (the sign is random: a branch would mispredict).
    const auto band =
        static_cast<Lane>(static_cast<std::int32_t>(exact + std::copysign(0.5f, exact)));
    out[u] = band;
    largest = std::max(largest, band);
  }
  most = largest;
}

// The candidates of a band-pass row, as bits (bit i of word i / 64 for column i of the strip):
// the pixels at or above `threshold` (the noise is at least 1, so nothing below can pass the SNR
// threshold) that are a maximum of the band-pass within `reach` rows up and down (strictly above
// the rows above, at least the rows below). Row r + k is at ring + slot[k]. Few pass (a fraction
// of a percent), so the rest of the test runs on them alone.
// Portable version: byte flags, then eight at a time into bits.
template <class Lane>
LASERLINE_ROW_KERNEL void peak_bits(const Lane* ring, const std::size_t* slot, int reach,
                                    Lane threshold, int count, std::uint8_t* __restrict flags,
                                    std::uint64_t* __restrict bits) {
  const Lane* __restrict row = ring + slot[0];
  for (int u = 0; u < count; ++u)
    flags[u] = static_cast<std::uint8_t>(row[u] >= threshold);
  for (int k = 1; k <= reach; ++k) {
    const Lane* __restrict above = ring + slot[-k];
    const Lane* __restrict below = ring + slot[k];
    for (int u = 0; u < count; ++u)
      flags[u] = static_cast<std::uint8_t>(flags[u] & (row[u] > above[u]) & (row[u] >= below[u]));
  }
  for (int w = 0; w * 64 < count; ++w)
    bits[w] = 0;
  for (int c = 0; c < count; c += 8) {
    std::uint64_t eight = 0;
    std::memcpy(&eight, flags + c, sizeof eight);
    // Flags of 0 or 1 in the bytes: the product gathers flag k into bit k of its top byte.
    static_assert(std::endian::native == std::endian::little);
    const std::uint64_t gathered = (eight * 0x0102040810204080u) >> 56;
    bits[c / 64] |= gathered << (c % 64);
  }
}

#if LASERLINE_AVX2_KERNELS
// peak_bits() of sixteen 16-bit lanes from column u: a compare mask.
template <int kReach = 0>  // the reach if known at compile time
__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256i peaks_of_sixteen(
    const std::int16_t* ring, const std::size_t* slot, int reach, __m256i below_threshold, int u) {
  if constexpr (kReach > 0) reach = kReach;
  const std::int16_t* column = ring + u;
  const __m256i centre = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(column + slot[0]));
  __m256i peak = _mm256_cmpgt_epi16(centre, below_threshold);
  for (int k = 1; k <= reach; ++k) {
    const __m256i above = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(column + slot[-k]));
    const __m256i below = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(column + slot[k]));
    const __m256i higher = _mm256_cmpgt_epi16(centre, above);
    const __m256i lower = _mm256_cmpgt_epi16(below, centre);
    peak = _mm256_and_si256(peak, _mm256_andnot_si256(lower, higher));
  }
  return peak;
}

// peak_bits() for 16-bit lanes in AVX2: compare masks packed to bytes and their top bits taken
// (count a multiple of 16).
template <int kReach>
__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL void peak_bits_avx2_with(
    const std::int16_t* ring, const std::size_t* slot, int reach, std::int16_t threshold, int count,
    std::uint64_t* bits) {
  const __m256i below_threshold = _mm256_set1_epi16(static_cast<short>(threshold - 1));
  for (int w = 0; w * 64 < count; ++w)
    bits[w] = 0;
  for (int u = 0; u < count; u += 32) {
    const __m256i first = peaks_of_sixteen<kReach>(ring, slot, reach, below_threshold, u);
    const __m256i second =
        u + 16 < count ? peaks_of_sixteen<kReach>(ring, slot, reach, below_threshold, u + 16)
                       : _mm256_setzero_si256();
    // packs interleaves the 128-bit halves: the permutation puts the bytes back in order.
    const __m256i bytes = _mm256_permute4x64_epi64(_mm256_packs_epi16(first, second), 0xd8);
    const auto mask = static_cast<std::uint32_t>(_mm256_movemask_epi8(bytes));
    bits[u / 64] |= static_cast<std::uint64_t>(mask) << (u % 64);
  }
}

__attribute__((target("avx2"))) inline void peak_bits_avx2(const std::int16_t* ring,
                                                           const std::size_t* slot, int reach,
                                                           std::int16_t threshold, int count,
                                                           std::uint64_t* bits) {
  // (The usual reach, 2 rows for a 3-row laser width, unrolled.)
  if (reach == 2) {
    peak_bits_avx2_with<2>(ring, slot, reach, threshold, count, bits);
  } else {
    peak_bits_avx2_with<0>(ring, slot, reach, threshold, count, bits);
  }
}
#endif

// The two rows of the frame a normalised row is interpolated from, and the weight of the lower.
struct SourceRow {
  SourceRow(const ImageView& image, float v) {
    const int last = image.height - 1;
    const int v0 = std::min(static_cast<int>(v), last);
    a = image.row(v0);
    b = image.row(std::min(v0 + 1, last));
    fb = fixed_weight(v - static_cast<float>(v0));
  }
  const std::uint8_t* a;
  const std::uint8_t* b;
  std::uint16_t fb;
};

}  // namespace

void Frontend::use_intrinsics(bool use) {
#if LASERLINE_AVX2_KERNELS
  avx2_ = use && __builtin_cpu_supports("avx2");
#else
  (void)use;
#endif
}

void Frontend::set_frame(const ImageView& current) {
  current_ = current;
  subtracting_ = false;
}

void Frontend::set_frame_minus_background(const ImageView& current, const ImageView& background,
                                          const Homography& current_to_background) {
  current_ = current;
  background_ = background;
  to_background_ = current_to_background;
  subtracting_ = true;
}

LASERLINE_DENSE_KERNEL
void Frontend::normalise_row(int r, std::uint16_t* out) {
  const float v = rows_.source_row(r);
  const SourceRow row(current_, v);
  if (!subtracting_) {
    interpolate_row(row.a, row.b, row.fb, normalised_shift_, width_, out);
    return;
  }
  // The background may be a band of rows of the frame (its own size; the homography says where).
  const ImageView& background = background_;
  const auto bg_width = static_cast<float>(background.width);
  const auto bg_height = static_cast<float>(background.height);
  // Along the row the background position is a ratio of linear functions of u: numerators and
  // denominator at u = 0, and their steps per pixel.
  const auto& g = to_background_.h;
  const auto xn0 = static_cast<float>(g[1] * v + g[2]), xnu = static_cast<float>(g[0]);
  const auto yn0 = static_cast<float>(g[4] * v + g[5]), ynu = static_cast<float>(g[3]);
  const auto wn0 = static_cast<float>(g[7] * v + g[8]), wnu = static_cast<float>(g[6]);
  const int blocks = (width_ + kWarpBlock - 1) / kWarpBlock;
  const int width = width_, stride = background.stride, last_column = background.width - 1;
  // Where each block's centre was in the background, for all blocks of the row at once,
  // branch-free so that it vectorises: the block's first pixel's position there (the block moves
  // as a whole), its integer part and the four bilinear weights. Positions are held within two
  // background sizes (a NaN goes to the far left), so that they convert to int.
  std::int32_t* __restrict left = warp_left_.data();
  std::int32_t* __restrict top = warp_top_.data();
  // The weights as negated_pair()s, a row's two in one (32-bit, as wide as the positions, so that
  // the loop vectorises).
  std::int32_t* __restrict pairs = warp_pairs_.data();
  std::int32_t* __restrict offset = warp_offset_.data();
  std::int32_t* __restrict whole = warp_whole_.data();
  const int last_row = background.height - 1;
  const float far = 2.0f * std::max(bg_width, bg_height);
  int partial = 0;  // blocks not whole
  for (int j = 0; j < blocks; ++j) {
    const int u0 = j * kWarpBlock;
    const int count = std::min(kWarpBlock, width - u0);
    const float centre = static_cast<float>(u0) + 0.5f * static_cast<float>(count - 1);
    const float inv = 1.0f / (wn0 + wnu * centre);
    const float y = (yn0 + ynu * centre) * inv;
    const float x = (xn0 + xnu * centre) * inv - (centre - static_cast<float>(u0));
    const float xs = x > -far ? (x < far ? x : far) : -far;
    const float ys = y > -far ? (y < far ? y : far) : -far;
    const float fx = std::floor(xs), fy = std::floor(ys);
    const auto ix = static_cast<std::int32_t>(fx), iy = static_cast<std::int32_t>(fy);
    left[j] = ix;
    top[j] = iy;
    // (Where whole, it fits: unsigned, so that elsewhere it may wrap.)
    offset[j] = static_cast<std::int32_t>(static_cast<std::uint32_t>(iy) *
                                              static_cast<std::uint32_t>(stride) +
                                          static_cast<std::uint32_t>(ix));
    // Whole: all its pixels' four neighbours lie inside the background (nearly every block).
    whole[j] = (count == kWarpBlock) & (ix >= 0) & (ix + kWarpBlock <= last_column) & (iy >= 0) &
               (iy < last_row);
    partial += 1 - whole[j];
    const float tx = xs - fx, ty = ys - fy;
    const float one = kFixedOne;
    // The four sum to 128 (else the background is scaled) by construction: the rows' shares
    // rounded, then each row's share split between its two pixels.
    const auto top_share = static_cast<std::int32_t>((1.0f - ty) * one + 0.5f);
    const std::int32_t bottom_share = kFixedOne - top_share;
    const auto top_left =
        static_cast<std::int32_t>((1.0f - tx) * static_cast<float>(top_share) + 0.5f);
    const auto bottom_left =
        static_cast<std::int32_t>((1.0f - tx) * static_cast<float>(bottom_share) + 0.5f);
    const std::int32_t top_right = top_share - top_left;
    const std::int32_t bottom_right = bottom_share - bottom_left;
    pairs[2 * j] = negated_pair(top_left, top_right);
    pairs[2 * j + 1] = negated_pair(bottom_left, bottom_right);
  }
  const WarpBlocks warp{left,   top,    whole, offset,      pairs,    background.data,
                        stride, blocks, width, last_column, last_row, partial};
  const RowDifference difference_row{row.a, row.b, row.fb, stride, normalised_shift_, out};
#if LASERLINE_AVX2_KERNELS
  // Inlined into the AVX2 version of this function, a call never made in the other.
  if (avx2_) {
    difference_blocks_avx2(warp, difference_row);
    return;
  }
#endif
  DifferenceGeneric difference{difference_row};
  difference_blocks(warp, difference, out);
}

struct Frontend::StageImages {
  std::span<float> normalised, band_pass, signal_to_noise;
};

namespace {

// The sum of |band-pass| over a noise window less its guard band (see Frontend::noise_level()):
// over the `rows` rows from each of `above` and `below` (offsets into the strip's band-pass ring),
// columns [first, first + count) of the ring. Exact: 64-bit.
template <class Lane>
std::uint64_t window_sum(const Lane* ring, const Frontend::NoiseWindow& window, int first,
                         int count) {
  std::uint64_t sum = 0;
  for (const std::size_t* rows : {window.above, window.below}) {
    for (int j = 0; j < window.rows; ++j) {
      const Lane* row = ring + rows[j] + first;
      for (int i = 0; i < count; ++i)
        sum += static_cast<std::uint64_t>(row[i] < 0 ? -static_cast<std::int64_t>(row[i]) : row[i]);
    }
  }
  return sum;
}

#if LASERLINE_AVX2_KERNELS
// |band-pass| of sixteen 16-bit lanes, summed in pairs to 32-bit lanes with the weights `ones`
// (1 for the window's columns, else 0).
__attribute__((target("avx2"))) LASERLINE_ROW_KERNEL __m256i magnitude_pairs(const std::int16_t* x,
                                                                             __m256i ones) {
  return _mm256_madd_epi16(
      _mm256_abs_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(x))), ones);
}

// window_sum() of 16-bit lanes in AVX2, sixteen columns to a register, the columns beyond `count`
// weighted 0. Reads up to 15 lanes past the last column (the ring is padded for it). Each 32-bit
// lane sums two columns over the rows: at most 2 x 32767 x 1000 rows (the largest noise window)
// fits, and for a window at most sixteen columns wide (the usual case: one register, summed in
// 32 bits) so does the whole sum.
__attribute__((target("avx2"))) inline std::uint64_t window_sum_avx2(
    const std::int16_t* ring, const Frontend::NoiseWindow& window, int first, int count) {
  const __m256i lane = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const std::int16_t* columns = ring + first;
  std::uint64_t sum = 0;
  for (int c = 0; c < count; c += 16) {
    const __m256i ones =
        _mm256_and_si256(_mm256_cmpgt_epi16(_mm256_set1_epi16(static_cast<short>(count - c)), lane),
                         _mm256_set1_epi16(1));
    // (The rows above and below the guard band in two sums: two chains of additions.)
    __m256i above = _mm256_setzero_si256(), below = _mm256_setzero_si256();
    for (int j = 0; j < window.rows; ++j) {
      above = _mm256_add_epi32(above, magnitude_pairs(columns + window.above[j] + c, ones));
      below = _mm256_add_epi32(below, magnitude_pairs(columns + window.below[j] + c, ones));
    }
    const __m256i both = _mm256_add_epi32(above, below);
    if (count <= 16) {
      __m128i total =
          _mm_add_epi32(_mm256_castsi256_si128(both), _mm256_extracti128_si256(both, 1));
      total = _mm_add_epi32(total, _mm_shuffle_epi32(total, 0x4e));
      total = _mm_add_epi32(total, _mm_shuffle_epi32(total, 0xb1));
      return static_cast<std::uint32_t>(_mm_cvtsi128_si32(total));
    }
    __m256i wide = _mm256_add_epi64(_mm256_cvtepu32_epi64(_mm256_castsi256_si128(both)),
                                    _mm256_cvtepu32_epi64(_mm256_extracti128_si256(both, 1)));
    const __m128i pairs =
        _mm_add_epi64(_mm256_castsi256_si128(wide), _mm256_extracti128_si256(wide, 1));
    sum += static_cast<std::uint64_t>(_mm_cvtsi128_si64(pairs)) +
           static_cast<std::uint64_t>(_mm_extract_epi64(pairs, 1));
  }
  return sum;
}
#endif

}  // namespace

template <class Lane>
float Frontend::noise_level(const Lane* ring, const NoiseWindow& window, int u, int begin) const {
  std::uint64_t sum = 0;
  const int count = 2 * noise_pad_ + 1;
  if (u >= noise_pad_ && u + noise_pad_ < width_) {
    const int first = u - noise_pad_ - begin;
    bool summed = false;
#if LASERLINE_AVX2_KERNELS
    if constexpr (std::is_same_v<Lane, std::int16_t>) {
      if (avx2_) {
        sum = window_sum_avx2(ring, window, first, count);
        summed = true;
      }
    }
#endif
    if (!summed) sum = window_sum(ring, window, first, count);
  } else {  // at the image's sides the window repeats the edge column
    for (int k = -noise_pad_; k <= noise_pad_; ++k)
      sum += window_sum(ring, window, std::clamp(u + k, 0, width_ - 1) - begin, 1);
  }
  // III-D: the minimal noise level is 1.
  return std::max(static_cast<float>(sum) * band_unit_ * noise_norm_, 1.0f);
}

template <class Lane>
LASERLINE_ROW_KERNEL void Frontend::roll_with(const StageImages* images, BandRings<Lane>& rings) {
  using Sum = std::make_unsigned_t<Lane>;
  const int rows = rows_.rows();
  const int hi = inner_ / 2, ho = outer_ / 2, nh = noise_half_, gh = guard_;
  // band-pass rows needed below the row under test
  const int look = std::max({nh, reach_, ridge_});
  const bool near_down = rows_.near_side() > 0;  // glow below the line (see water_glows())
  const int saturation = options_.saturation_level;
  const auto image_stride = static_cast<std::size_t>(stride_);
  const auto ring = static_cast<std::size_t>(ring_stride_);
  const float threshold = std::pow(10.0f, static_cast<float>(options_.snr_threshold_db) / 20.0f);
  // In band-pass units: at or above it exactly where the band-pass is at or above the threshold.
  // (Beyond the lanes' range, as a high threshold in 16-bit lanes can be: never reached.)
  const float lanes = std::ceil(threshold / band_unit_);
  constexpr Lane kMostLane = std::numeric_limits<Lane>::max();
  const Lane lane_threshold =
      lanes < static_cast<float>(kMostLane) ? static_cast<Lane>(lanes) : kMostLane;
  const float unit = band_unit_;
  const auto a = static_cast<Sum>(band_a_), b_coefficient = static_cast<Sum>(band_b_);
  const int per_column = options_.max_candidates_per_column;
  const int strips = (width_ + kStripColumns - 1) / kStripColumns;
  std::fill(column_count_.begin(), column_count_.end(), 0);
  std::fill(rings.inner.begin(), rings.inner.end(), Sum{0});
  std::fill(rings.outer.begin(), rings.outer.end(), Sum{0});
  const bool want_snr = images != nullptr && !images->signal_to_noise.empty();
  const float normalised_one = static_cast<float>(1 << (kFixedBits - normalised_shift_));

  // Rows beyond the ends are rows of zeros: a box cut short sums what it covers. The normalised
  // ring is as wide as the image; each strip has its own band-pass ring and sums.
  // Column 0 of normalised row r.
  auto normalised_slot = [&](int r) LASERLINE_ROW_LAMBDA -> std::uint16_t* {
    return normalised_ring_.data() + normalised_pad_ +
           static_cast<std::size_t>(r % normalised_ring_rows_) * normalised_stride_;
  };
  auto normalised = [&](int r) LASERLINE_ROW_LAMBDA -> const std::uint16_t* {
    if (r < 0 || r >= rows) return zero_normalised_.data() + normalised_pad_;
    return normalised_slot(r);
  };
  int next_normalised = 0;
  auto normalise_until = [&](int last) LASERLINE_ROW_LAMBDA {
    for (; next_normalised <= std::min(last, rows - 1); ++next_normalised) {
      std::uint16_t* out = normalised_slot(next_normalised);
      normalise_row(next_normalised, out);
      if (images != nullptr && !images->normalised.empty()) {
        float* dst = images->normalised.data() + next_normalised * image_stride;
        for (int u = 0; u < width_; ++u)
          dst[u] = static_cast<float>(out[u]) / normalised_one;
      }
    }
  };

  // Rows go in blocks: the block's normalised rows across the whole image (long runs through the
  // frame), then strip by strip the band-pass, noise and candidates of the block's rows (the
  // strip's rings stay in the first-level cache for the whole block).
  int next_band = 0;
  for (int r_begin = 0; r_begin < rows; r_begin += kRowBlock) {
    const int r_end = std::min(r_begin + kRowBlock, rows);
    const int band_end = std::min(r_end + look, rows);  // band-pass rows [next_band, band_end)
    normalise_until(band_end - 1 + ho);
    // Where the rows the block touches are, the same in every strip: as offsets into a strip's
    // rings (rows beyond the ends: the zero row after the ring's last), and the normalised rows.
    const int band_base = r_begin - look, band_top = r_end + look;
    // (Slots counted on from the first, wrapping: a division per row and strip was 2% of the
    // time.)
    for (int r = band_base, slot = band_base < 0 ? 0 : band_base % band_ring_rows_; r < band_top;
         ++r) {
      const int at = r < 0 || r >= rows ? band_ring_rows_ : slot;
      band_slots_[r - band_base] = at;
      band_rows_[r - band_base] = static_cast<std::size_t>(at) * ring;
      if (r >= 0) slot = slot + 1 == band_ring_rows_ ? 0 : slot + 1;
    }
    const int normalised_base = next_band - ho - 1;
    for (int r = normalised_base; r <= band_end + ho; ++r)
      normalised_rows_[r - normalised_base] = normalised(r);
    for (int strip = 0; strip < strips; ++strip) {
      // The strip's columns [c0, c1), and from `begin` on `count` columns with the noise
      // window's reach on either side: what its rings and sums hold (beyond the image: zeros).
      const int c0 = strip * kStripColumns, c1 = std::min(c0 + kStripColumns, width_);
      const int begin = c0 - noise_pad_;
      const int count = ring_stride_;
      const std::size_t state = static_cast<std::size_t>(strip) * ring;
      int* most = band_most_.data() + static_cast<std::size_t>(strip) * (band_ring_rows_ + 1);
      Sum* inner = rings.inner.data() + state;
      Sum* outer = rings.outer.data() + state;
      Lane* band_ring = rings.band.data() + state * static_cast<std::size_t>(band_ring_rows_ + 1);
      auto band = [&](int r) LASERLINE_ROW_LAMBDA -> Lane* {
        return band_ring + band_rows_[r - band_base];
      };
      auto x = [&](int r)
                   LASERLINE_ROW_LAMBDA { return normalised_rows_[r - normalised_base] + begin; };

      // III-C: box means down the columns; at the ends the boxes are cut short and averaged over
      // what they cover. The sums of row b are those of row b - 1 plus the row that enters the
      // box and minus the one that leaves it; they start holding rows 0 .. half - 1.
      if (next_band == 0) {
        for (int j = 0; j < std::min(ho, rows); ++j) {
          const std::uint16_t* row = x(j);
          for (int u = 0; u < count; ++u) {
            if (j < hi) inner[u] = static_cast<Sum>(inner[u] + row[u]);
            outer[u] = static_cast<Sum>(outer[u] + row[u]);
          }
        }
      }
      for (int b = next_band; b < band_end; ++b) {
        Lane* out = band(b);
        int& row_most = most[band_slots_[b - band_base]];
        if (b >= ho && b + ho < rows) {
          if (count == kRingColumns) {
            band_pass_row(inner, x(b + hi), x(b - hi - 1), outer, x(b + ho), x(b - ho - 1), a,
                          b_coefficient, kRingColumns, out, row_most);
          } else {
            band_pass_row(inner, x(b + hi), x(b - hi - 1), outer, x(b + ho), x(b - ho - 1), a,
                          b_coefficient, count, out, row_most);
          }
        } else {
          const int i0 = std::max(b - hi, 0), i1 = std::min(b + hi + 1, rows);
          const int o0 = std::max(b - ho, 0), o1 = std::min(b + ho + 1, rows);
          const float wi = 1.0f / (static_cast<float>(i1 - i0) * normalised_one * unit);
          const float wo = 1.0f / (static_cast<float>(o1 - o0) * normalised_one * unit);
          band_pass_row_cut_short(inner, x(b + hi), x(b - hi - 1), outer, x(b + ho), x(b - ho - 1),
                                  wi, wo, count, out, row_most);
        }
        if (images != nullptr && !images->band_pass.empty()) {
          float* dst = images->band_pass.data() + b * image_stride;
          for (int u = c0; u < c1; ++u)
            dst[u] = static_cast<float>(out[u - begin]) * unit;
        }
      }
      // III-D/E for the block's rows. Rows in the margins are outside the depth range: no
      // candidates there.
      for (int r = r_begin; r < r_end; ++r) {
        const Lane* row = band(r);
        // The noise window of row r, rows [r - nh, r + nh], less its guard band.
        const NoiseWindow noise{band_rows_.data() + (r - nh - band_base),
                                band_rows_.data() + (r + gh + 1 - band_base), nh - gh};
        auto noise_at = [&](int u) LASERLINE_ROW_LAMBDA {
          return noise_level(band_ring, noise, u, begin);
        };
        if (want_snr) {
          float* dst = images->signal_to_noise.data() + r * image_stride;
          for (int u = c0; u < c1; ++u)
            dst[u] = static_cast<float>(row[u - begin]) * unit / noise_at(u);
        }
        const int edge = std::max({margin_, reach_, ridge_});
        const bool searched = r >= edge && r < rows - edge;
        if (!searched || most[band_slots_[r - band_base]] < lane_threshold) continue;
        // Candidates: maxima of the band-pass within `reach` rows at or above the threshold.
        const std::size_t* rows_at = band_rows_.data() + (r - band_base);
        std::uint64_t* bits = peak_bits_.data();
#if LASERLINE_AVX2_KERNELS
        if constexpr (std::is_same_v<Lane, std::int16_t>) {
          if (avx2_) {
            peak_bits_avx2(band_ring, rows_at, reach_, lane_threshold, count, bits);
          } else {
            peak_bits(band_ring, rows_at, reach_, lane_threshold, count, peak_flags_.data(), bits);
          }
        } else
#endif
        {
          peak_bits(band_ring, rows_at, reach_, lane_threshold, count, peak_flags_.data(), bits);
        }
        const Lane* up = band(r - 1);
        const Lane* down = band(r + 1);

        // From set bit to set bit over the strip's own columns [first, end) (a branch per pixel
        // would mispredict).
        const int first = c0 - begin, end = c1 - begin;
        for (int w = first / 64; w * 64 < end; ++w) {
          std::uint64_t word = bits[w];
          if (first > w * 64) word &= ~std::uint64_t{0} << (first - w * 64);
          if (end < w * 64 + 64) word &= (std::uint64_t{1} << (end - w * 64)) - 1;
          for (; word != 0; word &= word - 1) {
            const int i = w * 64 + std::countr_zero(word);
            const Lane lane = row[i];
            const int u = begin + i;
            const float value = static_cast<float>(lane) * unit;
            // Keep the strongest few per column (bounded work and output). Strongest by
            // band-pass amplitude: the laser adds light, while a faint texture edge in a quiet
            // neighbourhood can have the higher SNR. (Checked first: it is the cheapest test.)
            Peak* best = column_best_.data() + static_cast<std::size_t>(u) * per_column;
            const int n = column_count_[u];
            int slot = n;
            if (n == per_column) {
              slot = 0;
              for (int j = 1; j < n; ++j)
                if (best[j].band < best[slot].band) slot = j;
              if (best[slot].band >= value) continue;
            }
            // A ridge, not an edge: the band-pass an eighth of the peak below zero on both sides
            // (a line gives a half to three quarters, a line lying on a texture edge less on the
            // edge's bright side; an edge nothing on its bright side).
            // Each side: out to where the band-pass crosses zero (farther for a line wider than
            // the model), then the lowest value within half an outer box beyond.
            const int enough = -static_cast<int>(lane) / 8;  // (rounded toward zero)
            auto lowest = [&](int side) LASERLINE_ROW_LAMBDA {
              int d = reach_ + 1;
              while (d < look && band(r + side * d)[i] > 0)
                ++d;
              int low = 0;
              for (const int last_row = std::min(d + ridge_, look); d <= last_row; ++d) {
                low = std::min<int>(low, band(r + side * d)[i]);
                if (low < enough) break;  // low enough: no need to look farther
              }
              return low;
            };
            const int lowest_up = glowing_ && !near_down ? 0 : lowest(-1);
            const int lowest_down = glowing_ && near_down ? 0 : lowest(+1);
            const int needed =
                glowing_ ? (near_down ? lowest_up : lowest_down) : std::max(lowest_up, lowest_down);
            // (A clipped core much wider than the model is flat: the band-pass sees its two
            // flanks as edges. Its run is found and centred by the refinement.)
            if (8 * needed > -static_cast<int>(lane) &&
                current_.at(u, static_cast<int>(rows_.source_row(r) + 0.5f)) < saturation) {
              continue;
            }
            const float snr = value / noise_at(u);
            if (!(snr >= threshold)) continue;
            if (n < per_column) column_count_[u] = static_cast<std::uint8_t>(n + 1);
            // Sub-row position of the band-pass peak, mapped back to an original row: the
            // guess the refinement starts from.
            const auto above = static_cast<float>(up[i]), below = static_cast<float>(down[i]);
            const auto centre = static_cast<float>(lane);
            const float curvature = above - 2.0f * centre + below;
            const float offset = curvature < 0.0f
                                     ? std::clamp(0.5f * (above - below) / curvature, -0.5f, 0.5f)
                                     : 0.0f;
            best[slot] = Peak{static_cast<float>(r) + offset, snr, value};
          }
        }
      }
    }
    next_band = band_end;
  }
}

void Frontend::roll(const StageImages* images) {
  if (narrow_band_) {
    roll_narrow(images);
  } else {
    roll_wide(images);
  }
}

LASERLINE_DENSE_KERNEL
void Frontend::roll_narrow(const StageImages* images) {
  roll_with(images, narrow_);
}

LASERLINE_DENSE_KERNEL
void Frontend::roll_wide(const StageImages* images) {
  roll_with(images, wide_);
}

void Frontend::stage_images(std::span<float> normalised, std::span<float> band_pass,
                            std::span<float> signal_to_noise) {
  const std::size_t size = static_cast<std::size_t>(rows_.rows()) * stride_;
  for (std::span<float> image : {normalised, band_pass, signal_to_noise}) {
    if (!image.empty() && image.size() < size) {
      throw std::invalid_argument("Frontend::stage_images: an output is smaller than " +
                                  std::to_string(rows_.rows()) + " x " + std::to_string(stride_));
    }
  }
  const StageImages images{normalised, band_pass, signal_to_noise};
  roll(&images);
}

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

bool Frontend::water_glows(const ImageView& frame) const {
  if (probe_count_ == 0 || frame.data == nullptr) return false;
  // At each point where the line was last found: the mean brightness of the few widths just in
  // front of it (the near side) and just behind it, and the line's own brightness.
  const int near = rows_.near_side();
  std::array<float, kProbes> excess{}, line{};
  std::size_t n = 0;
  for (std::size_t i = 0; i < probe_count_; ++i) {
    const int u = std::clamp(static_cast<int>(std::lround(probes_[i][0])), 0, frame.width - 1);
    const double v = probes_[i][1];
    const int w = std::max(1, static_cast<int>(std::lround(rows_.width_px(v))));
    const int centre = static_cast<int>(std::lround(v));
    auto mean = [&](int side) {
      int sum = 0, count = 0;
      for (int d = w; d <= 4 * w; ++d) {
        const int r = centre + side * d;
        if (r < 0 || r >= frame.height) continue;
        sum += frame.at(u, r);
        ++count;
      }
      return count > 0 ? static_cast<float>(sum) / static_cast<float>(count) : -1.0f;
    };
    const float in_front = mean(near), behind = mean(-near);
    if (in_front < 0 || behind < 0 || centre < 0 || centre >= frame.height) continue;
    excess[n] = in_front - behind;
    line[n] = static_cast<float>(frame.at(u, centre)) - behind;
    ++n;
  }
  if (n == 0) return false;
  const auto middle = static_cast<std::ptrdiff_t>(n / 2);
  std::nth_element(excess.begin(), excess.begin() + middle, excess.begin() + n);
  std::nth_element(line.begin(), line.begin() + middle, line.begin() + n);
  return excess[middle] > 0.25f * std::max(line[middle], 1.0f);
}

void Frontend::find_candidates(Profile& out) {
  collect_candidates(out);
  select_line(out);
}

void Frontend::collect_candidates(Profile& out) {
  out.clear();
  glowing_ = water_glows(current_);
  roll(nullptr);
  const int per_column = options_.max_candidates_per_column;
  for (int u = 0; u < width_; ++u) {
    Peak* best = column_best_.data() + static_cast<std::size_t>(u) * per_column;
    LineCandidate* line = line_candidates_.data() + static_cast<std::size_t>(u) * per_column;
    const int n = column_count_[u];
    // By row (normalised rows grow with the original rows).
    std::sort(best, best + n, [](const Peak& a, const Peak& b) { return a.r < b.r; });
    for (int i = 0; i < n; ++i) {
      // The band-pass peak's row, good to about half a laser width: only the chosen point gets
      // the sub-pixel fit (the costly part of this stage, done for all columns at the end).
      line[i].position = rows_.to_source_single(best[i].r);
      line[i].snr_db = kDecibelsPerNeper * std::log(best[i].snr);  // 20 log10 (cheaper)
      line[i].amplitude_db = kDecibelsPerNeper * std::log(std::max(best[i].band, 1e-3f));
      ProfilePoint point;
      point.u = u;
      point.v = line[i].position;
      point.snr_db = line[i].snr_db;
      point.valid = true;  // eligible, until validation or the line selection says otherwise
      if (!out.add(point)) break;
    }
  }
  collected_ = out.size();
}

void Frontend::select_line(Profile& out) {
  // The eligible candidates of each column, in the order collect_candidates() added them.
  const int per_column = options_.max_candidates_per_column;
  std::fill(eligible_count_.begin(), eligible_count_.end(), 0);
  const std::span<ProfilePoint> points = out.mutable_points();
  const std::size_t collected = std::min(collected_, points.size());
  for (std::size_t k = 0; k < collected; ++k) {
    ProfilePoint& p = points[k];
    if (!p.valid || p.u < 0 || p.u >= width_) continue;
    const auto u = static_cast<std::size_t>(p.u);
    const std::size_t slot = u * static_cast<std::size_t>(per_column) + eligible_count_[u];
    if (eligible_count_[u] == per_column) continue;  // (never: one column gives at most that)
    const LineCandidate* line = line_candidates_.data() + u * static_cast<std::size_t>(per_column);
    // The candidate itself: its column's candidates were added in order, by position.
    for (int i = 0; i < column_count_[u]; ++i) {
      if (line[i].position == p.v) {
        eligible_[slot] = line[i];
        break;
      }
    }
    eligible_point_[slot] = k;
    ++eligible_count_[u];
    p.valid = false;
  }
  // One laser point per epipolar line; the others stay in the profile, not valid.
  selector_.select(eligible_, eligible_count_, static_cast<float>(options_.snr_threshold_db),
                   chosen_);
  std::size_t waiting = 0;  // valid points waiting for their sub-pixel row
  for (int u = 0; u < width_; ++u) {
    const int i = chosen_[static_cast<std::size_t>(u)];
    if (i < 0) continue;
    const std::size_t k =
        eligible_point_[static_cast<std::size_t>(u) * static_cast<std::size_t>(per_column) +
                        static_cast<std::size_t>(i)];
    points[k].valid = true;
    refine_columns_[waiting] = u;
    refine_guesses_[waiting] = points[k].v;
    refine_points_[waiting] = k;
    ++waiting;
  }
  refine(points, waiting);
  // Where the line is now: where the next frame looks for the glow (and the background detector
  // measures the motion across the line).
  if (waiting > 0) {
    const std::size_t step = std::max<std::size_t>(1, waiting / kProbes);
    probe_count_ = 0;
    for (std::size_t k = 0; k < waiting && probe_count_ < kProbes; k += step) {
      const ProfilePoint& p = points[refine_points_[k]];
      probes_[probe_count_++] = {static_cast<float>(p.u), p.v};
    }
  }
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
