// Kernels of the pass down the normalised rows (paper III-C to III-E): a band-pass row from
// running box sums, the candidates' peak test as bits, the noise window's sum. Compiled once per
// target (foreach_target.h); the scalar reference at the end.
#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>

#include "pipeline/kernels/kernels.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/kernels/band_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#ifndef LASERLINE_BAND_KERNELS_SCALAR
#define LASERLINE_BAND_KERNELS_SCALAR
namespace laserline::pipeline::kernels::detail {

// Column i of peak_bits(): at or above the threshold, strictly above the rows above, at least the
// rows below.
template <class Lane>
inline bool is_peak(const Lane* ring, const std::size_t* slot, int reach, Lane threshold, int i) {
  const Lane centre = ring[slot[0] + i];
  bool peak = centre >= threshold;
  for (int k = 1; k <= reach; ++k)
    peak = peak & (centre > ring[slot[-k] + i]) & (centre >= ring[slot[k] + i]);
  return peak;
}

template <class Lane>
inline std::uint64_t magnitude(Lane x) {
  return static_cast<std::uint64_t>(x < 0 ? -static_cast<std::int64_t>(x) : x);
}

}  // namespace laserline::pipeline::kernels::detail
#endif

HWY_BEFORE_NAMESPACE();
namespace laserline::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

template <class Sum, class Lane>
int BandPass(Sum* inner, const std::uint16_t* inner_in, const std::uint16_t* inner_out, Sum* outer,
             const std::uint16_t* outer_in, const std::uint16_t* outer_out, Sum a, Sum b, int count,
             Lane* out) {
  // At most 256 bits: the strips' rows are a multiple of 16 columns, so no scalar tail.
  const hn::CappedTag<Sum, 32 / sizeof(Sum)> d;
  const hn::RebindToSigned<decltype(d)> ds;
  const hn::Rebind<std::uint16_t, decltype(d)> d16;
  const int n = static_cast<int>(hn::Lanes(d));
  auto load = [&](const std::uint16_t* x) HWY_ATTR {
    if constexpr (sizeof(Sum) == 2) {
      return hn::LoadU(d, x);
    } else {
      return hn::PromoteTo(d, hn::LoadU(d16, x));
    }
  };
  const auto va = hn::Set(d, a), vb = hn::Set(d, b);
  auto most = hn::Set(ds, std::numeric_limits<Lane>::min());
  int u = 0;
  for (; u + n <= count; u += n) {
    // (Modulo 2^bits: the sums wrap, the band-pass fits.)
    const auto i =
        hn::Sub(hn::Add(hn::LoadU(d, inner + u), load(inner_in + u)), load(inner_out + u));
    const auto o =
        hn::Sub(hn::Add(hn::LoadU(d, outer + u), load(outer_in + u)), load(outer_out + u));
    hn::StoreU(i, d, inner + u);
    hn::StoreU(o, d, outer + u);
    const auto band = hn::BitCast(ds, hn::Sub(hn::Mul(va, i), hn::Mul(vb, o)));
    hn::StoreU(band, ds, out + u);
    most = hn::Max(most, band);
  }
  const int largest = static_cast<int>(hn::GetLane(hn::MaxOfLanes(ds, most)));
  if (u == count) return largest;
  return std::max(largest,
                  reference::band_pass_row(inner + u, inner_in + u, inner_out + u, outer + u,
                                           outer_in + u, outer_out + u, a, b, count - u, out + u));
}

int BandPass16(std::uint16_t* inner, const std::uint16_t* inner_in, const std::uint16_t* inner_out,
               std::uint16_t* outer, const std::uint16_t* outer_in, const std::uint16_t* outer_out,
               std::uint16_t a, std::uint16_t b, int count, std::int16_t* out) {
  return BandPass(inner, inner_in, inner_out, outer, outer_in, outer_out, a, b, count, out);
}

int BandPass32(std::uint32_t* inner, const std::uint16_t* inner_in, const std::uint16_t* inner_out,
               std::uint32_t* outer, const std::uint16_t* outer_in, const std::uint16_t* outer_out,
               std::uint32_t a, std::uint32_t b, int count, std::int32_t* out) {
  return BandPass(inner, inner_in, inner_out, outer, outer_in, outer_out, a, b, count, out);
}

template <class Lane>
void PeakBits(const Lane* ring, const std::size_t* slot, int reach, Lane threshold, int count,
              std::uint64_t* bits) {
  // At most 256 bits: the strips' rows are a multiple of 16 columns, so no scalar tail (and a
  // vector's mask bits fall within one word).
  const hn::CappedTag<Lane, 32 / sizeof(Lane)> d;
  const int n = static_cast<int>(hn::Lanes(d));
  for (int w = 0; w * 64 < count; ++w)
    bits[w] = 0;
  const auto level = hn::Set(d, threshold);
  int u = 0;
  for (; u + n <= count; u += n) {
    const auto centre = hn::LoadU(d, ring + slot[0] + u);
    auto peak = hn::Not(hn::Lt(centre, level));
    for (int k = 1; k <= reach; ++k) {
      const auto above = hn::LoadU(d, ring + slot[-k] + u);
      const auto below = hn::LoadU(d, ring + slot[k] + u);
      peak = hn::AndNot(hn::Lt(centre, below), hn::And(peak, hn::Gt(centre, above)));
    }
    std::uint8_t mask[8] = {};
    hn::StoreMaskBits(d, peak, mask);
    std::uint64_t word = 0;
    std::memcpy(&word, mask, sizeof word);
    static_assert(std::endian::native == std::endian::little);
    if (n < 64) word &= (std::uint64_t{1} << n) - 1;
    bits[u / 64] |= word << (u % 64);
  }
  for (; u < count; ++u) {
    if (detail::is_peak(ring, slot, reach, threshold, u))
      bits[u / 64] |= std::uint64_t{1} << (u % 64);
  }
}

void PeakBits16(const std::int16_t* ring, const std::size_t* slot, int reach,
                std::int16_t threshold, int count, std::uint64_t* bits) {
  PeakBits(ring, slot, reach, threshold, count, bits);
}

void PeakBits32(const std::int32_t* ring, const std::size_t* slot, int reach,
                std::int32_t threshold, int count, std::uint64_t* bits) {
  PeakBits(ring, slot, reach, threshold, count, bits);
}

#if HWY_TARGET == HWY_SCALAR
template <class Lane, class Wide>
std::uint64_t WindowSum(const Lane* ring, const std::size_t* offsets, int rows, int first,
                        int count) {
  return reference::window_sum(ring, offsets, rows, first, count);
}
#else
// |x| of a vector of columns (those past `count` masked to 0), taken as unsigned (exact for the
// most negative value too), its pairs of lanes summed into lanes twice as wide; summed over the
// rows, then reduced. (16-bit lanes: a window of up to 2 x 1000 rows of 2 x 32768 fits 32 bits.)
template <class Lane, class Wide>
std::uint64_t WindowSum(const Lane* ring, const std::size_t* offsets, int rows, int first,
                        int count) {
  const hn::CappedTag<Lane, 64 / sizeof(Lane)> d;  // at most 512 bits: kWindowLanes or fewer
  const hn::RebindToUnsigned<decltype(d)> du;
  const hn::Repartition<Wide, decltype(d)> dw;
  const int n = static_cast<int>(hn::Lanes(d));
  const Lane* columns = ring + first;
  const auto low_half = hn::Set(dw, static_cast<Wide>((Wide{1} << (8 * sizeof(Lane))) - 1));
  std::uint64_t sum = 0;
  for (int c = 0; c < count; c += n) {
    const auto wanted = hn::FirstN(d, static_cast<std::size_t>(count - c));
    auto pairs = [&](const Lane* x) HWY_ATTR {
      const auto magnitude =
          hn::BitCast(dw, hn::BitCast(du, hn::Abs(hn::IfThenElseZero(wanted, hn::LoadU(d, x)))));
      return hn::Add(hn::And(magnitude, low_half), hn::ShiftRight<8 * sizeof(Lane)>(magnitude));
    };
    auto total = hn::Zero(dw);
    for (int j = 0; j < rows; ++j)
      total = hn::Add(total, pairs(columns + offsets[j] + c));
    sum += static_cast<std::uint64_t>(hn::GetLane(hn::SumOfLanes(dw, total)));
  }
  return sum;
}
#endif

std::uint64_t WindowSum16(const std::int16_t* ring, const std::size_t* offsets, int rows, int first,
                          int count) {
#if HWY_TARGET == HWY_SCALAR
  return WindowSum<std::int16_t, std::uint32_t>(ring, offsets, rows, first, count);
#else
  // |x| (x > -32768: the band-pass's range) summed in pairs into 32-bit lanes, weighted 1 for
  // the window's columns and 0 past them: a multiply-add of pairs where the CPU has one (AVX2's,
  // NEON's). Exact: 1000 rows of 2 x 32767 fit, and so does the whole window's sum.
  const hn::CappedTag<std::int16_t, 32> d;
  const hn::Repartition<std::int32_t, decltype(d)> d32;
  const int n = static_cast<int>(hn::Lanes(d));
  const std::int16_t* columns = ring + first;
  std::uint64_t sum = 0;
  for (int c = 0; c < count; c += n) {
    const auto ones =
        hn::IfThenElseZero(hn::FirstN(d, static_cast<std::size_t>(count - c)), hn::Set(d, 1));
    auto total = hn::Zero(d32), total_other = total;  // (the multiply-add's two halves)
    for (int j = 0; j < rows; ++j) {
      total = hn::ReorderWidenMulAccumulate(d32, hn::Abs(hn::LoadU(d, columns + offsets[j] + c)),
                                            ones, total, total_other);
    }
    sum +=
        static_cast<std::uint32_t>(hn::GetLane(hn::SumOfLanes(d32, hn::Add(total, total_other))));
  }
  return sum;
#endif
}

std::uint64_t WindowSum32(const std::int32_t* ring, const std::size_t* offsets, int rows, int first,
                          int count) {
  return WindowSum<std::int32_t, std::uint64_t>(ring, offsets, rows, first, count);
}

// Windows whose columns lie within one vector of the first's (a line crossing the strip, a
// texture edge along the row) share its columns: their sums down the rows, once for all of them.
// (From this many windows on that costs less than a window at a time.)
constexpr int kSharedWindows = 3;

void WindowSums16(const std::int16_t* ring, const std::size_t* offsets, int rows,
                  const std::int32_t* firsts, int n, int count, std::uint64_t* sums) {
#if HWY_TARGET != HWY_SCALAR
  const hn::CappedTag<std::int16_t, 32> d;
  const hn::RebindToUnsigned<decltype(d)> du;
  const hn::Repartition<std::int32_t, decltype(d)> d32;
  const hn::Repartition<std::uint32_t, decltype(d)> dw;
  const int lanes = static_cast<int>(hn::Lanes(d));
  if (count <= lanes) {
    // One vector per row and window (WindowSum16's loop once): its mask, the rows' places and
    // the dispatch paid once for all the windows.
    const auto ones =
        hn::IfThenElseZero(hn::FirstN(d, static_cast<std::size_t>(count)), hn::Set(d, 1));
    const auto low_half = hn::Set(dw, 0xFFFFu);
    const int reach = lanes - count;  // the farthest window start that one vector covers
    for (int k = 0; k < n;) {
      const int start = firsts[k];
      int shared = k + 1;
      while (shared < n && firsts[shared] >= start && firsts[shared] <= start + reach)
        ++shared;
      const std::int16_t* columns = ring + start;
      if (shared - k >= kSharedWindows) {
        // Per column the sum of |x| down the rows, even and odd columns in 32-bit lanes (|x| as
        // unsigned: exact for -2^15 too); then sums of `count` columns as differences of running
        // sums along the row. (At most 1000 rows of 2^15 and 32 columns: fits 32 bits.)
        auto even = hn::Zero(dw), odd = even;
        auto add = [&](const std::int16_t* x) HWY_ATTR {
          const auto magnitude = hn::BitCast(dw, hn::BitCast(du, hn::Abs(hn::LoadU(d, x))));
          even = hn::Add(even, hn::And(magnitude, low_half));
          odd = hn::Add(odd, hn::ShiftRight<16>(magnitude));
        };
        for (int j = 0; j < rows; ++j)
          add(columns + offsets[j]);
        std::uint32_t even_sums[16], odd_sums[16], running[33];
        hn::StoreU(even, dw, even_sums);
        hn::StoreU(odd, dw, odd_sums);
        running[0] = 0;
        for (int c = 0; c < lanes; ++c)
          running[c + 1] = running[c] + ((c & 1) != 0 ? odd_sums[c / 2] : even_sums[c / 2]);
        for (; k < shared; ++k)
          sums[k] = running[firsts[k] - start + count] - running[firsts[k] - start];
        continue;
      }
      auto total = hn::Zero(d32), total_other = total;
      for (int j = 0; j < rows; ++j) {
        total = hn::ReorderWidenMulAccumulate(d32, hn::Abs(hn::LoadU(d, columns + offsets[j])),
                                              ones, total, total_other);
      }
      sums[k] =
          static_cast<std::uint32_t>(hn::GetLane(hn::SumOfLanes(d32, hn::Add(total, total_other))));
      ++k;
    }
    return;
  }
#endif
  for (int k = 0; k < n; ++k)
    sums[k] = WindowSum16(ring, offsets, rows, firsts[k], count);
}

void WindowSums32(const std::int32_t* ring, const std::size_t* offsets, int rows,
                  const std::int32_t* firsts, int n, int count, std::uint64_t* sums) {
  for (int k = 0; k < n; ++k)
    sums[k] = WindowSum32(ring, offsets, rows, firsts[k], count);
}

}  // namespace HWY_NAMESPACE
}  // namespace laserline::pipeline::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace laserline::pipeline::kernels {

HWY_EXPORT(BandPass16);
HWY_EXPORT(BandPass32);
HWY_EXPORT(PeakBits16);
HWY_EXPORT(PeakBits32);
HWY_EXPORT(WindowSum16);
HWY_EXPORT(WindowSum32);
HWY_EXPORT(WindowSums16);
HWY_EXPORT(WindowSums32);

int band_pass_row(std::uint16_t* inner, const std::uint16_t* inner_in,
                  const std::uint16_t* inner_out, std::uint16_t* outer,
                  const std::uint16_t* outer_in, const std::uint16_t* outer_out, std::uint16_t a,
                  std::uint16_t b, int count, std::int16_t* out) {
  return HWY_DYNAMIC_DISPATCH(BandPass16)(inner, inner_in, inner_out, outer, outer_in, outer_out, a,
                                          b, count, out);
}

int band_pass_row(std::uint32_t* inner, const std::uint16_t* inner_in,
                  const std::uint16_t* inner_out, std::uint32_t* outer,
                  const std::uint16_t* outer_in, const std::uint16_t* outer_out, std::uint32_t a,
                  std::uint32_t b, int count, std::int32_t* out) {
  return HWY_DYNAMIC_DISPATCH(BandPass32)(inner, inner_in, inner_out, outer, outer_in, outer_out, a,
                                          b, count, out);
}

void peak_bits(const std::int16_t* ring, const std::size_t* slot, int reach, std::int16_t threshold,
               int count, std::uint64_t* bits) {
  HWY_DYNAMIC_DISPATCH(PeakBits16)(ring, slot, reach, threshold, count, bits);
}

void peak_bits(const std::int32_t* ring, const std::size_t* slot, int reach, std::int32_t threshold,
               int count, std::uint64_t* bits) {
  HWY_DYNAMIC_DISPATCH(PeakBits32)(ring, slot, reach, threshold, count, bits);
}

std::uint64_t window_sum(const std::int16_t* ring, const std::size_t* offsets, int rows, int first,
                         int count) {
  return HWY_DYNAMIC_DISPATCH(WindowSum16)(ring, offsets, rows, first, count);
}

std::uint64_t window_sum(const std::int32_t* ring, const std::size_t* offsets, int rows, int first,
                         int count) {
  return HWY_DYNAMIC_DISPATCH(WindowSum32)(ring, offsets, rows, first, count);
}

void window_sums(const std::int16_t* ring, const std::size_t* offsets, int rows,
                 const std::int32_t* firsts, int n, int count, std::uint64_t* sums) {
  HWY_DYNAMIC_DISPATCH(WindowSums16)(ring, offsets, rows, firsts, n, count, sums);
}

void window_sums(const std::int32_t* ring, const std::size_t* offsets, int rows,
                 const std::int32_t* firsts, int n, int count, std::uint64_t* sums) {
  HWY_DYNAMIC_DISPATCH(WindowSums32)(ring, offsets, rows, firsts, n, count, sums);
}

namespace reference {

namespace {

template <class Sum, class Lane>
int band_pass(Sum* inner, const std::uint16_t* inner_in, const std::uint16_t* inner_out, Sum* outer,
              const std::uint16_t* outer_in, const std::uint16_t* outer_out, Sum a, Sum b,
              int count, Lane* out) {
  Lane largest = std::numeric_limits<Lane>::min();
  for (int u = 0; u < count; ++u) {
    const auto i = static_cast<Sum>(inner[u] + inner_in[u] - inner_out[u]);
    const auto o = static_cast<Sum>(outer[u] + outer_in[u] - outer_out[u]);
    inner[u] = i;
    outer[u] = o;
    const auto band = static_cast<Lane>(static_cast<Sum>(a * i - b * o));
    out[u] = band;
    largest = std::max(largest, band);
  }
  return largest;
}

template <class Lane>
void peak_bits_of(const Lane* ring, const std::size_t* slot, int reach, Lane threshold, int count,
                  std::uint64_t* bits) {
  for (int w = 0; w * 64 < count; ++w)
    bits[w] = 0;
  for (int u = 0; u < count; ++u) {
    if (detail::is_peak(ring, slot, reach, threshold, u))
      bits[u / 64] |= std::uint64_t{1} << (u % 64);
  }
}

template <class Lane>
std::uint64_t window_sum_of(const Lane* ring, const std::size_t* offsets, int rows, int first,
                            int count) {
  std::uint64_t sum = 0;
  for (int j = 0; j < rows; ++j) {
    const Lane* row = ring + offsets[j] + first;
    for (int i = 0; i < count; ++i)
      sum += detail::magnitude(row[i]);
  }
  return sum;
}

}  // namespace

int band_pass_row(std::uint16_t* inner, const std::uint16_t* inner_in,
                  const std::uint16_t* inner_out, std::uint16_t* outer,
                  const std::uint16_t* outer_in, const std::uint16_t* outer_out, std::uint16_t a,
                  std::uint16_t b, int count, std::int16_t* out) {
  return band_pass(inner, inner_in, inner_out, outer, outer_in, outer_out, a, b, count, out);
}

int band_pass_row(std::uint32_t* inner, const std::uint16_t* inner_in,
                  const std::uint16_t* inner_out, std::uint32_t* outer,
                  const std::uint16_t* outer_in, const std::uint16_t* outer_out, std::uint32_t a,
                  std::uint32_t b, int count, std::int32_t* out) {
  return band_pass(inner, inner_in, inner_out, outer, outer_in, outer_out, a, b, count, out);
}

void peak_bits(const std::int16_t* ring, const std::size_t* slot, int reach, std::int16_t threshold,
               int count, std::uint64_t* bits) {
  peak_bits_of(ring, slot, reach, threshold, count, bits);
}

void peak_bits(const std::int32_t* ring, const std::size_t* slot, int reach, std::int32_t threshold,
               int count, std::uint64_t* bits) {
  peak_bits_of(ring, slot, reach, threshold, count, bits);
}

std::uint64_t window_sum(const std::int16_t* ring, const std::size_t* offsets, int rows, int first,
                         int count) {
  return window_sum_of(ring, offsets, rows, first, count);
}

std::uint64_t window_sum(const std::int32_t* ring, const std::size_t* offsets, int rows, int first,
                         int count) {
  return window_sum_of(ring, offsets, rows, first, count);
}

void window_sums(const std::int16_t* ring, const std::size_t* offsets, int rows,
                 const std::int32_t* firsts, int n, int count, std::uint64_t* sums) {
  for (int k = 0; k < n; ++k)
    sums[k] = window_sum_of(ring, offsets, rows, firsts[k], count);
}

void window_sums(const std::int32_t* ring, const std::size_t* offsets, int rows,
                 const std::int32_t* firsts, int n, int count, std::uint64_t* sums) {
  for (int k = 0; k < n; ++k)
    sums[k] = window_sum_of(ring, offsets, rows, firsts[k], count);
}

}  // namespace reference
}  // namespace laserline::pipeline::kernels
#endif  // HWY_ONCE
