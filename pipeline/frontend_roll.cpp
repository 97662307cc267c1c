// The front end's pass down the rows (paper III-C to III-E), after the row normalisation
// (frontend.cpp): the band-pass of the normalised rows, the noise level, the SNR, and the
// candidates per column, in blocks of rows and strips of columns (its vector kernels in
// pipeline/kernels/).
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <span>
#include <string>
#include <type_traits>

#include "pipeline/frontend.hpp"
#include "pipeline/frontend_common.hpp"
#include "pipeline/kernels/kernels.hpp"

namespace laserline::pipeline {

using namespace frontend_detail;

namespace {

// The band-pass row where a box is cut short by an end of the rows (a few rows at either end): the
// means over what each box covers (inner weight wi, outer wo per unit of sum), in the band-pass's
// unit. (Elsewhere kernels::band_pass_row(): the box sums slide one row on, sum += entering -
// leaving, and the band-pass, inner mean minus outer mean, is the exact integer
// a * inner sum - b * outer sum, in 16-bit lanes wherever it and the sums fit.)
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

}  // namespace

struct Frontend::StageImages {
  std::span<float> normalised, band_pass, signal_to_noise;
};

template <class Lane>
float Frontend::noise_level(const Lane* ring, const NoiseWindow& window, int u, int begin) const {
  // The window's rows above the pixel and those below, apart (see noise_sum()).
  std::uint64_t sum_above = 0, sum_below = 0;
  const int count = 2 * noise_pad_ + 1;
  if (u >= noise_pad_ && u + noise_pad_ < width_) {
    const int first = u - noise_pad_ - begin;
    sum_above = kernels::window_sum(ring, window.above, window.rows, first, count);
    sum_below = kernels::window_sum(ring, window.below, window.rows, first, count);
  } else {  // at the image's sides the window repeats the edge column
    for (int k = -noise_pad_; k <= noise_pad_; ++k) {
      const int column = std::clamp(u + k, 0, width_ - 1) - begin;
      sum_above += kernels::window_sum(ring, window.above, window.rows, column, 1);
      sum_below += kernels::window_sum(ring, window.below, window.rows, column, 1);
    }
  }
  const std::uint64_t sum = noise_sum(sum_above, sum_below, window.inside);
  // III-D: the minimal noise level is 1.
  return std::max(static_cast<float>(sum) * band_unit_ * noise_norm_, 1.0f);
}

// The settings of one pass down the rows, the same for each of its stages.
template <class Lane>
struct Frontend::RollPass {
  using Sum = std::make_unsigned_t<Lane>;
  int rows = 0;
  int hi = 0, ho = 0;      // half the inner and the outer band-pass box
  int nh = 0, gh = 0;      // half the noise window, its guard band
  int nw = 0;              // ... and half its width
  int look = 0;            // band-pass rows needed below the row under test
  int start = 0;           // the first band-pass row of the pass
  int edge = 0;            // rows nearer the ends are outside the depth range: no candidates there
  bool near_down = false;  // glow below the line (see water_glows())
  std::size_t image_stride = 0;
  float threshold = 0;            // SNR, as an amplitude ratio
  float near_line_threshold = 0;  // ... within near_line_px of the previous frame's line
  float near_line_px = 0;
  Lane lane_threshold = 0;  // in band-pass units: at or above it where the band-pass is
  float unit = 1;           // grey levels of a band-pass unit
  Sum a = 0, b = 0;         // the band-pass coefficients
  int per_column = 0;
  float normalised_one = 1;  // 1.0 in normalised units
};

// One strip of one block of rows: its own columns [c0, c1), and what its rings and sums hold:
// `count` columns from `begin` on, the noise window's reach on either side (beyond the image:
// zeros); where the rows the block touches are in its ring and in the normalised ring.
template <class Lane>
struct Frontend::StripRows {
  using Sum = std::make_unsigned_t<Lane>;
  int c0 = 0, c1 = 0, begin = 0, count = 0;
  int* most = nullptr;  // per band-pass slot: the row's largest value
  Sum* inner = nullptr;
  Sum* outer = nullptr;
  Lane* band_ring = nullptr;
  const std::size_t* band_rows = nullptr;  // of row band_base on
  const int* band_slots = nullptr;
  int band_base = 0;
  const std::uint16_t* const* normalised_rows = nullptr;  // of row normalised_base on
  int normalised_base = 0;
  std::uint64_t* peak_bits = nullptr;  // one row's candidates
  // One row's peaks awaiting their noise level (see Part).
  std::int32_t* peak_column = nullptr;
  std::int32_t* peak_slot = nullptr;
  std::int32_t* peak_clipped = nullptr;
  float* peak_rank = nullptr;
  std::int32_t* window_first = nullptr;
  std::uint64_t* window_sum_above = nullptr;
  std::uint64_t* window_sum_below = nullptr;

  LASERLINE_ROW_KERNEL Lane* band(int r) const { return band_ring + band_rows[r - band_base]; }
  LASERLINE_ROW_KERNEL int& row_most(int r) const { return most[band_slots[r - band_base]]; }
  // The strip's columns of normalised row r.
  LASERLINE_ROW_KERNEL const std::uint16_t* normalised(int r) const {
    return normalised_rows[r - normalised_base] + begin;
  }
};

template <class Lane>
LASERLINE_ROW_KERNEL Frontend::RollPass<Lane> Frontend::roll_pass() const {
  RollPass<Lane> pass;
  pass.rows = rows_.rows();
  pass.hi = inner_ / 2;
  pass.ho = outer_ / 2;
  pass.nh = noise_half_;
  pass.gh = guard_;
  pass.nw = noise_pad_;
  pass.look = std::max({noise_half_, reach_, ridge_});
  pass.edge = std::max({margin_, reach_, ridge_});
  pass.near_down = rows_.near_side() > 0;
  pass.image_stride = static_cast<std::size_t>(stride_);
  pass.threshold = std::pow(10.0f, static_cast<float>(options_.snr_threshold_db) / 20.0f);
  pass.near_line_threshold =
      pass.threshold / std::pow(10.0f, static_cast<float>(options_.snr_hysteresis_db) / 20.0f);
  pass.near_line_px = static_cast<float>(options_.selection.previous_tolerance_px);
  // (Beyond the lanes' range, as a high threshold in 16-bit lanes can be: never reached.)
  const float lanes = std::ceil(pass.threshold / band_unit_);
  constexpr Lane kMostLane = std::numeric_limits<Lane>::max();
  pass.lane_threshold =
      lanes < static_cast<float>(kMostLane) ? static_cast<Lane>(lanes) : kMostLane;
  pass.unit = band_unit_;
  pass.a = static_cast<typename RollPass<Lane>::Sum>(band_a_);
  pass.b = static_cast<typename RollPass<Lane>::Sum>(band_b_);
  pass.per_column = options_.max_candidates_per_column;
  pass.normalised_one = static_cast<float>(1 << (kFixedBits - normalised_shift_));
  return pass;
}

// Column 0 of normalised row r in the part's ring.
LASERLINE_ROW_KERNEL std::uint16_t* Frontend::normalised_slot(Part& part, int r) {
  return part.normalised_ring.data() + normalised_pad_ +
         static_cast<std::size_t>(r % normalised_ring_rows_) * normalised_stride_;
}

// Normalised row r; rows beyond the ends are rows of zeros (a box cut short sums what it covers).
LASERLINE_ROW_KERNEL const std::uint16_t* Frontend::normalised_at(Part& part, int r, int rows) {
  if (r < 0 || r >= rows) return zero_normalised_.data() + normalised_pad_;
  return normalised_slot(part, r);
}

// III-B: the part's columns of the normalised rows from `next` to `last` (at most the last row)
// into its ring, and its own columns into images->normalised where asked; `next` moves on past
// them.
LASERLINE_ROW_KERNEL void Frontend::normalise_until(Part& part, int last, int rows,
                                                    float normalised_one, int& next,
                                                    const StageImages* images) {
  for (; next <= std::min(last, rows - 1); ++next) {
    std::uint16_t* out = normalised_slot(part, next);
    normalise_row(part, next, out);
    if (images != nullptr && !images->normalised.empty()) {
      float* dst = images->normalised.data() + next * static_cast<std::size_t>(stride_);
      const int end = std::min(part.end_strip * kStripColumns, width_);
      for (int u = part.first_strip * kStripColumns; u < end; ++u)
        dst[u] = static_cast<float>(out[u]) / normalised_one;
    }
  }
}

// Where the rows a block touches are, the same in every strip: as offsets into a strip's rings
// (rows beyond the ends: the zero row after the ring's last) from row band_base to band_top, and
// the normalised rows from normalised_base to normalised_top.
LASERLINE_ROW_KERNEL void Frontend::place_block_rows(Part& part, int rows, int band_base,
                                                     int band_top, int normalised_base,
                                                     int normalised_top) {
  const auto ring = static_cast<std::size_t>(ring_stride_);
  // (Slots counted on from the first, wrapping: a division per row and strip was 2% of the time.)
  for (int r = band_base, slot = band_base < 0 ? 0 : band_base % band_ring_rows_; r < band_top;
       ++r) {
    const int at = r < 0 || r >= rows ? band_ring_rows_ : slot;
    part.band_slots[r - band_base] = at;
    part.band_rows[r - band_base] = static_cast<std::size_t>(at) * ring;
    if (r >= 0) slot = slot + 1 == band_ring_rows_ ? 0 : slot + 1;
  }
  for (int r = normalised_base; r <= normalised_top; ++r)
    part.normalised_rows[r - normalised_base] = normalised_at(part, r, rows);
}

// III-C: the band-pass rows [first, end) of a strip: box means down the columns; at the ends the
// boxes are cut short and averaged over what they cover. The sums of row b are those of row b - 1
// plus the row that enters the box and minus the one that leaves it; they start holding the rows
// of the boxes of the row before the pass's first (rows 0 .. half - 1 when it starts at row 0).
template <class Lane>
LASERLINE_ROW_KERNEL void Frontend::band_pass_rows(const RollPass<Lane>& pass,
                                                   const StripRows<Lane>& strip, int first, int end,
                                                   const StageImages* images) {
  using Sum = std::make_unsigned_t<Lane>;
  const int hi = pass.hi, ho = pass.ho, rows = pass.rows, count = strip.count;
  Sum* inner = strip.inner;
  Sum* outer = strip.outer;
  if (first == pass.start) {
    for (int j = std::max(first - ho - 1, 0); j < std::min(first + ho, rows); ++j) {
      const std::uint16_t* row = strip.normalised(j);
      const bool in_inner = j >= first - hi - 1 && j < first + hi;
      for (int u = 0; u < count; ++u) {
        if (in_inner) inner[u] = static_cast<Sum>(inner[u] + row[u]);
        outer[u] = static_cast<Sum>(outer[u] + row[u]);
      }
    }
  }
  for (int b = first; b < end; ++b) {
    Lane* out = strip.band(b);
    int& row_most = strip.row_most(b);
    const std::uint16_t* inner_in = strip.normalised(b + hi);
    const std::uint16_t* inner_out = strip.normalised(b - hi - 1);
    const std::uint16_t* outer_in = strip.normalised(b + ho);
    const std::uint16_t* outer_out = strip.normalised(b - ho - 1);
    if (b >= ho && b + ho < rows) {
      row_most = kernels::band_pass_row(inner, inner_in, inner_out, outer, outer_in, outer_out,
                                        pass.a, pass.b, count, out);
    } else {
      const int i0 = std::max(b - hi, 0), i1 = std::min(b + hi + 1, rows);
      const int o0 = std::max(b - ho, 0), o1 = std::min(b + ho + 1, rows);
      const float wi = 1.0f / (static_cast<float>(i1 - i0) * pass.normalised_one * pass.unit);
      const float wo = 1.0f / (static_cast<float>(o1 - o0) * pass.normalised_one * pass.unit);
      band_pass_row_cut_short(inner, inner_in, inner_out, outer, outer_in, outer_out, wi, wo, count,
                              out, row_most);
    }
    if (images != nullptr && !images->band_pass.empty()) {
      float* dst = images->band_pass.data() + b * pass.image_stride;
      for (int u = strip.c0; u < strip.c1; ++u)
        dst[u] = static_cast<float>(out[u - strip.begin]) * pass.unit;
    }
  }
}

// The lowest band-pass at ring column i on one side of row r (side -1: up, +1: down): out to
// where the band-pass crosses zero (farther for a line wider than the model), then the lowest
// value within half an outer box beyond; it stops once below `enough`.
template <class Lane>
LASERLINE_ROW_KERNEL int Frontend::lowest_beside(const RollPass<Lane>& pass,
                                                 const StripRows<Lane>& strip, int r, int i,
                                                 int side, int enough) const {
  int d = reach_ + 1;
  while (d < pass.look && strip.band(r + side * d)[i] > 0)
    ++d;
  int low = 0;
  for (const int last_row = std::min(d + ridge_, pass.look); d <= last_row; ++d) {
    low = std::min<int>(low, strip.band(r + side * d)[i]);
    if (low < enough) break;  // low enough: no need to look farther
  }
  return low;
}

// III-D/E for row r of a strip: its SNR into images->signal_to_noise where asked, and its
// candidates (maxima of the band-pass within `reach` rows, ridges, at or above the threshold)
// into column_best_ / column_count_.
template <class Lane>
LASERLINE_ROW_KERNEL void Frontend::row_candidates(const RollPass<Lane>& pass,
                                                   const StripRows<Lane>& strip, int r,
                                                   const StageImages* images) {
  const int begin = strip.begin, count = strip.count, c0 = strip.c0, c1 = strip.c1;
  const Lane* row = strip.band(r);
  // The noise window of row r, rows [r - nh, r + nh], less its guard band.
  const NoiseWindow noise{strip.band_rows + (r - pass.nh - strip.band_base),
                          strip.band_rows + (r + pass.gh + 1 - strip.band_base), pass.nh - pass.gh,
                          r - pass.nh >= 0 && r + pass.nh < pass.rows};
  auto noise_at = [&](int u) LASERLINE_ROW_LAMBDA {
    return noise_level(strip.band_ring, noise, u, begin);
  };
  if (images != nullptr && !images->signal_to_noise.empty()) {
    float* dst = images->signal_to_noise.data() + r * pass.image_stride;
    for (int u = c0; u < c1; ++u)
      dst[u] = static_cast<float>(row[u - begin]) * pass.unit / noise_at(u);
  }
  const bool searched = r >= pass.edge && r < pass.rows - pass.edge;
  if (!searched || strip.row_most(r) < pass.lane_threshold) return;
  // Candidates: maxima of the band-pass within `reach` rows at or above the threshold.
  const std::size_t* rows_at = strip.band_rows + (r - strip.band_base);
  std::uint64_t* bits = strip.peak_bits;
  kernels::peak_bits(strip.band_ring, rows_at, reach_, pass.lane_threshold, count, bits);
  const Lane* up = strip.band(r - 1);
  const Lane* down = strip.band(r + 1);
  const int source_row = static_cast<int>(rows_.source_row(r) + 0.5f);

  // The peaks that would be kept first, then the noise of all their windows at once, then the
  // SNR test and the ridge test (the dearer, for fewer peaks); a column has one peak per row:
  // its slot stays as found. From set bit to set bit over the strip's own columns [first, end) (a
  // branch per pixel would mispredict).
  const int first = c0 - begin, end = c1 - begin;
  int peaks = 0;
  for (int w = first / 64; w * 64 < end; ++w) {
    std::uint64_t word = bits[w];
    if (first > w * 64) word &= ~std::uint64_t{0} << (first - w * 64);
    if (end < w * 64 + 64) word &= (std::uint64_t{1} << (end - w * 64)) - 1;
    for (; word != 0; word &= word - 1) {
      const int i = w * 64 + std::countr_zero(word);
      const Lane lane = row[i];
      const int u = begin + i;
      const float value = static_cast<float>(lane) * pass.unit;
      // Keep the strongest few per column (bounded work and output). Strongest by band-pass
      // amplitude: the laser adds light, while a faint texture edge in a quiet neighbourhood can
      // have the higher SNR. But a short clipped run before any: where the laser crosses a bright
      // patch, clipping leaves it little amplitude, less than the texture's ridges around it.
      // (Checked first: they are the cheapest tests.)
      const bool clipped = in_clipped_core(u, source_row);
      const float rank = clipped ? value + kClippedCoreRank : value;
      Peak* best = column_best_.data() + static_cast<std::size_t>(u) * pass.per_column;
      const int n = column_count_[u];
      int slot = n;
      if (n == pass.per_column) {
        slot = 0;
        for (int j = 1; j < n; ++j)
          if (best[j].rank < best[slot].rank) slot = j;
        if (best[slot].rank >= rank) continue;
      }
      strip.peak_column[peaks] = i;
      strip.peak_slot[peaks] = slot;
      strip.peak_clipped[peaks] = clipped ? 1 : 0;
      strip.peak_rank[peaks] = rank;
      strip.window_first[peaks] = i - pass.nw;
      ++peaks;
    }
  }
  kernels::window_sums(strip.band_ring, noise.above, noise.rows, strip.window_first, peaks,
                       2 * pass.nw + 1, strip.window_sum_above);
  kernels::window_sums(strip.band_ring, noise.below, noise.rows, strip.window_first, peaks,
                       2 * pass.nw + 1, strip.window_sum_below);
  for (int k = 0; k < peaks; ++k) {
    const int i = strip.peak_column[k];
    const int u = begin + i;
    const Lane lane = row[i];
    const float value = static_cast<float>(lane) * pass.unit;
    // (At the image's sides the window repeats the edge column: noise_level() sums it so.)
    const float noise_level_at =
        u >= pass.nw && u + pass.nw < width_
            ? std::max(static_cast<float>(noise_sum(strip.window_sum_above[k],
                                                    strip.window_sum_below[k], noise.inside)) *
                           pass.unit * noise_norm_,
                       1.0f)
            : noise_at(u);
    const float snr = value / noise_level_at;
    // (A short clipped run is taken whatever its SNR: texture ridges beside the laser's crossing
    // of a bright patch raise the noise measured around it far above the light clipping left.)
    const bool near_line =
        std::abs(rows_.source_row(r) - previous_line_[static_cast<std::size_t>(u)]) <=
        pass.near_line_px;  // (false where there was none: NaN)
    const float snr_needed = near_line ? pass.near_line_threshold : pass.threshold;
    if (!(snr >= snr_needed) && strip.peak_clipped[k] == 0) continue;
    // A ridge, not an edge: the band-pass an eighth of the peak below zero on both sides (a
    // line gives a half to three quarters, a line lying on a texture edge less on the edge's
    // bright side; an edge nothing on its bright side).
    const int enough = -static_cast<int>(lane) / 8;  // (rounded toward zero)
    const int lowest_up =
        glowing_ && !pass.near_down ? 0 : lowest_beside(pass, strip, r, i, -1, enough);
    const int lowest_down =
        glowing_ && pass.near_down ? 0 : lowest_beside(pass, strip, r, i, +1, enough);
    const int needed =
        glowing_ ? (pass.near_down ? lowest_up : lowest_down) : std::max(lowest_up, lowest_down);
    // (A clipped core much wider than the model is flat: the band-pass sees its two flanks as
    // edges, its peak on the run or a pixel beside it. The run is found and centred by the
    // refinement.)
    if (8 * needed > -static_cast<int>(lane) && !touches_clipped_run(u, source_row)) continue;
    const int n = column_count_[u];
    if (n < pass.per_column) column_count_[u] = static_cast<std::uint8_t>(n + 1);
    // Sub-row position of the band-pass peak, mapped back to an original row: the guess the
    // refinement starts from.
    const auto above = static_cast<float>(up[i]), below = static_cast<float>(down[i]);
    const auto centre = static_cast<float>(lane);
    const float curvature = above - 2.0f * centre + below;
    const float offset =
        curvature < 0.0f ? std::clamp(0.5f * (above - below) / curvature, -0.5f, 0.5f) : 0.0f;
    Peak* best = column_best_.data() + static_cast<std::size_t>(u) * pass.per_column;
    best[strip.peak_slot[k]] = Peak{static_cast<float>(r) + offset, snr, value, strip.peak_rank[k]};
  }
}

// Rows go in blocks: the block's normalised rows across the part's columns (long runs through the
// frame), then strip by strip the band-pass, noise and candidates of the block's rows (the
// strip's rings stay in the first-level cache for the whole block). Within a region (bounds)
// only its strips, and the rows from those its first row's noise window reaches. A part does its
// own strips and writes only their sums and their columns' candidates.
template <class Lane>
LASERLINE_ROW_KERNEL void Frontend::roll_with(const StageImages* images, const PassBounds& bounds,
                                              BandRings<Lane>& rings, Part& part) {
  using Sum = std::make_unsigned_t<Lane>;
  if (part.first_strip == part.end_strip) return;
  RollPass<Lane> pass = roll_pass<Lane>();
  const int rows = pass.rows;
  const auto ring = static_cast<std::size_t>(ring_stride_);
  const auto sums = rings.inner.begin() + static_cast<std::ptrdiff_t>(part.first_strip * ring);
  const auto sums_end = rings.inner.begin() + static_cast<std::ptrdiff_t>(part.end_strip * ring);
  std::fill(sums, sums_end, Sum{0});
  std::fill(rings.outer.begin() + (sums - rings.inner.begin()),
            rings.outer.begin() + (sums_end - rings.inner.begin()), Sum{0});

  pass.start = std::max(bounds.row_begin - pass.look, 0);
  int next_normalised = std::max(pass.start - pass.ho - 1, 0);
  int next_band = pass.start;
  for (int r_begin = pass.start; r_begin < bounds.row_end; r_begin += kRowBlock) {
    const int r_end = std::min(r_begin + kRowBlock, bounds.row_end);
    const int band_end = std::min(r_end + pass.look, rows);  // band-pass rows [next_band, band_end)
    normalise_until(part, band_end - 1 + pass.ho, rows, pass.normalised_one, next_normalised,
                    images);
    const int band_base = r_begin - pass.look;
    const int normalised_base = next_band - pass.ho - 1;
    place_block_rows(part, rows, band_base, r_end + pass.look, normalised_base, band_end + pass.ho);
    for (int s = part.first_strip; s < part.end_strip; ++s) {
      StripRows<Lane> strip;
      strip.c0 = std::max(s * kStripColumns, bounds.column_begin);
      strip.c1 = std::min({(s + 1) * kStripColumns, width_, bounds.column_end});
      strip.begin = s * kStripColumns - noise_pad_;
      strip.count = ring_stride_;
      const std::size_t state = static_cast<std::size_t>(s) * ring;
      strip.most = band_most_.data() + static_cast<std::size_t>(s) * (band_ring_rows_ + 1);
      strip.inner = rings.inner.data() + state;
      strip.outer = rings.outer.data() + state;
      strip.band_ring = rings.band.data() + static_cast<std::size_t>(s) * band_strip_size_;
      strip.band_rows = part.band_rows.data();
      strip.band_slots = part.band_slots.data();
      strip.band_base = band_base;
      strip.normalised_rows = part.normalised_rows.data();
      strip.normalised_base = normalised_base;
      strip.peak_bits = part.peak_bits.data();
      strip.peak_column = part.peak_column.data();
      strip.peak_slot = part.peak_slot.data();
      strip.peak_clipped = part.peak_clipped.data();
      strip.peak_rank = part.peak_rank.data();
      strip.window_first = part.window_first.data();
      strip.window_sum_above = part.window_sum_above.data();
      strip.window_sum_below = part.window_sum_below.data();
      band_pass_rows(pass, strip, next_band, band_end, images);
      for (int r = std::max(r_begin, bounds.row_begin); r < r_end; ++r)
        row_candidates(pass, strip, r, images);
    }
    next_band = band_end;
  }
}

void Frontend::roll(const StageImages* images) {
  // The stage images are of the whole frame.
  const PassBounds bounds = images != nullptr ? whole_bounds() : bounds_;
  place_parts(bounds);
  std::fill(column_count_.begin(), column_count_.end(), 0);  // (the columns no part searches)
  auto part = [&](int p) {
    if (narrow_band_) {
      roll_narrow(images, bounds, p);
    } else {
      roll_wide(images, bounds, p);
    }
    const Part& own = parts_[static_cast<std::size_t>(p)];
    line_candidates(std::min(own.first_strip * kStripColumns, width_),
                    std::min(own.end_strip * kStripColumns, width_));
  };
  run_parts(part);
}

void Frontend::roll_narrow(const StageImages* images, const PassBounds& bounds, int part) {
  roll_with(images, bounds, narrow_, parts_[static_cast<std::size_t>(part)]);
}

void Frontend::roll_wide(const StageImages* images, const PassBounds& bounds, int part) {
  roll_with(images, bounds, wide_, parts_[static_cast<std::size_t>(part)]);
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

}  // namespace laserline::pipeline
