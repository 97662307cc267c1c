// Kernels over whole images: the per-column maxima of the maxvalue detector, and the transpose of
// a frame into the search image (a laser beside the camera). Compiled once per target
// (foreach_target.h); the scalar references at the end.
#include <algorithm>
#include <array>
#include <cstdint>

#include "pipeline/kernels/kernels.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/kernels/image_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace laserline::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

#if HWY_TARGET == HWY_SCALAR
// (One lane: no pairs of bytes to widen.)
void ColumnMaxima(const std::uint8_t* image, std::ptrdiff_t stride, int begin, int end, int height,
                  std::uint8_t* max, std::uint16_t* first, std::uint16_t* last,
                  std::uint32_t* sum) {
  reference::column_maxima(image, stride, begin, end, height, max, first, last, sum);
}
#else
// A strip of one vector of columns goes down all the rows with its state in registers: the
// largest value (bytes), where it is first and last reached and the sum (16-bit lanes, the bytes
// widened by interleaving with zeros, so in the interleave's order of columns; the sums flushed
// every 256 rows, before they can overflow).
void ColumnMaxima(const std::uint8_t* image, std::ptrdiff_t stride, int begin, int end, int height,
                  std::uint8_t* max, std::uint16_t* first, std::uint16_t* last,
                  std::uint32_t* sum) {
  const hn::ScalableTag<std::uint8_t> d8;
  const hn::Repartition<std::uint16_t, decltype(d8)> d16;
  const int n = static_cast<int>(hn::Lanes(d8));
  const std::size_t half = hn::Lanes(d16);
  constexpr std::size_t kMost = HWY_MAX_BYTES;  // bytes of the widest vector
  const auto zero = hn::Zero(d8);
  // The strip's column of each 16-bit lane.
  const auto iota = hn::Iota(d8, 0);
  alignas(64) std::array<std::uint16_t, kMost> column{};
  hn::Store(hn::BitCast(d16, hn::InterleaveLower(d8, iota, zero)), d16, column.data());
  hn::Store(hn::BitCast(d16, hn::InterleaveUpper(d8, iota, zero)), d16, column.data() + half);
  alignas(64) std::array<std::uint16_t, kMost> values{};
  auto spread = [&](std::uint16_t* to, int u, auto low, auto high) HWY_ATTR {
    hn::Store(low, d16, values.data());
    hn::Store(high, d16, values.data() + half);
    for (std::size_t j = 0; j < 2 * half; ++j)
      to[u + column[j]] = values[j];
  };
  int u = begin;
  for (; u + n <= end; u += n) {
    auto most = hn::Zero(d8);
    auto first_low = hn::Zero(d16), first_high = first_low, last_low = first_low,
         last_high = first_low;
    for (int j = 0; j < n; ++j)
      sum[u + j] = 0;
    for (int v0 = 0; v0 < height; v0 += 256) {
      auto sum_low = hn::Zero(d16), sum_high = sum_low;
      for (int v = v0; v < std::min(v0 + 256, height); ++v) {
        const auto x = hn::LoadU(d8, image + v * stride + u);
        const auto row = hn::Set(d16, static_cast<std::uint16_t>(v));
        const auto larger = hn::Max(most, x);
        // Not greater: the largest so far stays; at least as large: x is the largest.
        const auto stays = hn::VecFromMask(d8, hn::Eq(larger, most));
        const auto reaches = hn::VecFromMask(d8, hn::Eq(larger, x));
        most = larger;
        first_low =
            hn::IfThenElse(hn::MaskFromVec(hn::BitCast(d16, hn::InterleaveLower(d8, stays, stays))),
                           first_low, row);
        first_high =
            hn::IfThenElse(hn::MaskFromVec(hn::BitCast(d16, hn::InterleaveUpper(d8, stays, stays))),
                           first_high, row);
        last_low = hn::IfThenElse(
            hn::MaskFromVec(hn::BitCast(d16, hn::InterleaveLower(d8, reaches, reaches))), row,
            last_low);
        last_high = hn::IfThenElse(
            hn::MaskFromVec(hn::BitCast(d16, hn::InterleaveUpper(d8, reaches, reaches))), row,
            last_high);
        sum_low = hn::Add(sum_low, hn::BitCast(d16, hn::InterleaveLower(d8, x, zero)));
        sum_high = hn::Add(sum_high, hn::BitCast(d16, hn::InterleaveUpper(d8, x, zero)));
      }
      hn::Store(sum_low, d16, values.data());
      hn::Store(sum_high, d16, values.data() + half);
      for (std::size_t j = 0; j < 2 * half; ++j)
        sum[u + column[j]] += values[j];
    }
    hn::StoreU(most, d8, max + u);
    spread(first, u, first_low, first_high);
    spread(last, u, last_low, last_high);
  }
  if (u < end) reference::column_maxima(image, stride, u, end, height, max, first, last, sum);
}
#endif

// A 16 x 16 block through four rounds of interleaves (bytes, 16-, 32-, 64-bit lanes): each round
// doubles the run of one source column held together in a register.
void Transpose16(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                 std::ptrdiff_t dst_stride) {
#if HWY_TARGET == HWY_SCALAR
  reference::transpose16(src, src_stride, dst, dst_stride);
#else
  const hn::Full128<std::uint8_t> d8;
  const hn::Full128<std::uint16_t> d16;
  const hn::Full128<std::uint32_t> d32;
  const hn::Full128<std::uint64_t> d64;
  using V = hn::Vec<decltype(d8)>;
  V r[16], t[16];
  for (int i = 0; i < 16; ++i)
    r[i] = hn::LoadU(d8, src + i * src_stride);
  for (int k = 0; k < 8; ++k) {  // rows 2k, 2k+1 paired: columns 0-7, then 8-15
    t[k] = hn::InterleaveLower(d8, r[2 * k], r[2 * k + 1]);
    t[k + 8] = hn::InterleaveUpper(d8, r[2 * k], r[2 * k + 1]);
  }
  auto lower = [](auto d, V a, V b) HWY_ATTR {
    return hn::BitCast(hn::Full128<std::uint8_t>(),
                       hn::InterleaveLower(d, hn::BitCast(d, a), hn::BitCast(d, b)));
  };
  auto upper = [](auto d, V a, V b) HWY_ATTR {
    return hn::BitCast(hn::Full128<std::uint8_t>(),
                       hn::InterleaveUpper(d, hn::BitCast(d, a), hn::BitCast(d, b)));
  };
  for (int half = 0; half < 16; half += 8) {  // columns 0-7, then 8-15
    for (int k = 0; k < 4; ++k) {             // rows 4k .. 4k+3: columns +0-3, then +4-7
      r[half + k] = lower(d16, t[half + 2 * k], t[half + 2 * k + 1]);
      r[half + k + 4] = upper(d16, t[half + 2 * k], t[half + 2 * k + 1]);
    }
  }
  for (int quad = 0; quad < 16; quad += 4) {  // four columns: rows 0-3, 4-7, 8-11, 12-15 in r
    const V low01 = lower(d32, r[quad], r[quad + 1]);       // columns 0, 1: rows 0-7
    const V high01 = upper(d32, r[quad], r[quad + 1]);      // columns 2, 3: rows 0-7
    const V low23 = lower(d32, r[quad + 2], r[quad + 3]);   // rows 8-15
    const V high23 = upper(d32, r[quad + 2], r[quad + 3]);  // rows 8-15
    t[quad] = lower(d64, low01, low23);
    t[quad + 1] = upper(d64, low01, low23);
    t[quad + 2] = lower(d64, high01, high23);
    t[quad + 3] = upper(d64, high01, high23);
  }
  for (int i = 0; i < 16; ++i)
    hn::StoreU(t[i], d8, dst + i * dst_stride);
#endif
}

}  // namespace HWY_NAMESPACE
}  // namespace laserline::pipeline::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace laserline::pipeline::kernels {

HWY_EXPORT(ColumnMaxima);
HWY_EXPORT(Transpose16);

void column_maxima(const std::uint8_t* image, std::ptrdiff_t stride, int begin, int end, int height,
                   std::uint8_t* max, std::uint16_t* first, std::uint16_t* last,
                   std::uint32_t* sum) {
  HWY_DYNAMIC_DISPATCH(ColumnMaxima)(image, stride, begin, end, height, max, first, last, sum);
}

void transpose16(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                 std::ptrdiff_t dst_stride) {
  HWY_DYNAMIC_DISPATCH(Transpose16)(src, src_stride, dst, dst_stride);
}

namespace reference {

void column_maxima(const std::uint8_t* image, std::ptrdiff_t stride, int begin, int end, int height,
                   std::uint8_t* max, std::uint16_t* first, std::uint16_t* last,
                   std::uint32_t* sum) {
  std::fill(max + begin, max + end, std::uint8_t{0});
  std::fill(first + begin, first + end, std::uint16_t{0});
  std::fill(last + begin, last + end, std::uint16_t{0});
  std::fill(sum + begin, sum + end, 0u);
  for (int v = 0; v < height; ++v) {
    const std::uint8_t* p = image + v * stride;
    const auto row = static_cast<std::uint16_t>(v);
    for (int u = begin; u < end; ++u) {
      const std::uint8_t x = p[u];
      sum[u] += x;
      first[u] = x > max[u] ? row : first[u];
      last[u] = x >= max[u] ? row : last[u];
      max[u] = std::max(max[u], x);
    }
  }
}

void transpose16(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                 std::ptrdiff_t dst_stride) {
  for (int y = 0; y < 16; ++y) {
    for (int x = 0; x < 16; ++x)
      dst[x * dst_stride + y] = src[y * src_stride + x];
  }
}

}  // namespace reference
}  // namespace laserline::pipeline::kernels
#endif  // HWY_ONCE
