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
  const hn::ScalableTag<Sum> d;
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
  // At most 64 lanes: a vector's mask bits fall within one word.
  const hn::CappedTag<Lane, 64> d;
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

// |x| of each lane widened (to 32 bits for 16-bit lanes: exact for a window of at most 1000 rows
// of 32768; to 64 for 32-bit lanes), summed over the rows per vector of columns, then reduced.
template <class Lane, class Wide>
std::uint64_t WindowSum(const Lane* ring, const std::size_t* above, const std::size_t* below,
                        int rows, int first, int count) {
  const hn::ScalableTag<Wide> d;
  const hn::Rebind<Lane, decltype(d)> dn;
  const int n = static_cast<int>(hn::Lanes(d));
  const Lane* columns = ring + first;
  auto magnitude = [&](const Lane* x)
                       HWY_ATTR { return hn::Abs(hn::PromoteTo(d, hn::LoadU(dn, x))); };
  std::uint64_t sum = 0;
  int c = 0;
  for (; c + n <= count; c += n) {
    auto up = hn::Zero(d), down = hn::Zero(d);
    for (int j = 0; j < rows; ++j) {
      up = hn::Add(up, magnitude(columns + above[j] + c));
      down = hn::Add(down, magnitude(columns + below[j] + c));
    }
    sum += static_cast<std::uint64_t>(hn::GetLane(hn::SumOfLanes(d, hn::Add(up, down))));
  }
  if (c < count) sum += reference::window_sum(ring, above, below, rows, first + c, count - c);
  return sum;
}

std::uint64_t WindowSum16(const std::int16_t* ring, const std::size_t* above,
                          const std::size_t* below, int rows, int first, int count) {
  return WindowSum<std::int16_t, std::int32_t>(ring, above, below, rows, first, count);
}

std::uint64_t WindowSum32(const std::int32_t* ring, const std::size_t* above,
                          const std::size_t* below, int rows, int first, int count) {
  return WindowSum<std::int32_t, std::int64_t>(ring, above, below, rows, first, count);
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

std::uint64_t window_sum(const std::int16_t* ring, const std::size_t* above,
                         const std::size_t* below, int rows, int first, int count) {
  return HWY_DYNAMIC_DISPATCH(WindowSum16)(ring, above, below, rows, first, count);
}

std::uint64_t window_sum(const std::int32_t* ring, const std::size_t* above,
                         const std::size_t* below, int rows, int first, int count) {
  return HWY_DYNAMIC_DISPATCH(WindowSum32)(ring, above, below, rows, first, count);
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
std::uint64_t window_sum_of(const Lane* ring, const std::size_t* above, const std::size_t* below,
                            int rows, int first, int count) {
  std::uint64_t sum = 0;
  for (const std::size_t* offsets : {above, below}) {
    for (int j = 0; j < rows; ++j) {
      const Lane* row = ring + offsets[j] + first;
      for (int i = 0; i < count; ++i)
        sum += detail::magnitude(row[i]);
    }
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

std::uint64_t window_sum(const std::int16_t* ring, const std::size_t* above,
                         const std::size_t* below, int rows, int first, int count) {
  return window_sum_of(ring, above, below, rows, first, count);
}

std::uint64_t window_sum(const std::int32_t* ring, const std::size_t* above,
                         const std::size_t* below, int rows, int first, int count) {
  return window_sum_of(ring, above, below, rows, first, count);
}

}  // namespace reference
}  // namespace laserline::pipeline::kernels
#endif  // HWY_ONCE
