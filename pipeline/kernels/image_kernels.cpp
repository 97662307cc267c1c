// Kernels over whole images: the per-column maxima of the maxvalue detector, the transpose of
// a frame into the search image (a laser beside the camera), the halving of the motion
// estimate's image pyramid and its corner scores, and the copy of rows kept for later frames.
// Compiled once per target (foreach_target.h); the scalar references at the end.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "pipeline/kernels/kernels.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/kernels/image_kernels.cpp"
#include <hwy/cache_control.h>
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
// A strip of kVectors vectors of columns goes down all the rows with its state in registers, in
// chunks of 256 rows so that everything per row stays in byte lanes without a shuffle: within a
// chunk the largest value, the rows (from the chunk's start) where it is first and last reached,
// and the sums of the even and of the odd columns (the bytes read as little-endian 16-bit lanes,
// masked and shifted: 256 x 255 fits). After each chunk, its result merged into the strip's: a
// larger largest takes the chunk's first and last row, an equal one its last row only. Two
// vectors read whole cache lines of 64 bytes per row on AVX2.
template <int kVectors>
void ColumnMaximaStrip(const std::uint8_t* image, std::ptrdiff_t stride, int u, int height,
                       std::uint8_t* max, std::uint16_t* first, std::uint16_t* last,
                       std::uint32_t* sum) {
  const hn::ScalableTag<std::uint8_t> d8;
  const hn::Repartition<std::uint16_t, decltype(d8)> d16;
  using V8 = hn::Vec<decltype(d8)>;
  using V16 = hn::Vec<decltype(d16)>;
  const std::size_t n = hn::Lanes(d8);
  const std::size_t half = hn::Lanes(d16);
  constexpr int kChunk = 256;
  constexpr int kAhead = 16;  // rows read ahead
  const V16 low_byte = hn::Set(d16, 0x00FF);
  const V8 one = hn::Set(d8, 1);
  const auto split = [&](V8 bytes, V16& even_lanes, V16& odd_lanes) HWY_ATTR {
    const V16 pairs = hn::BitCast(d16, bytes);
    even_lanes = hn::And(pairs, low_byte);
    odd_lanes = hn::ShiftRight<8>(pairs);
  };
  V8 most[kVectors];
  V16 first_even[kVectors], first_odd[kVectors], last_even[kVectors], last_odd[kVectors];
  for (int k = 0; k < kVectors; ++k) {
    most[k] = hn::Zero(d8);
    first_even[k] = first_odd[k] = last_even[k] = last_odd[k] = hn::Zero(d16);
  }
  for (std::size_t j = 0; j < kVectors * n; ++j)
    sum[u + j] = 0;
  alignas(64) std::array<std::uint16_t, HWY_MAX_BYTES / 2> even{}, odd{};
  for (int v0 = 0; v0 < height; v0 += kChunk) {
    V8 chunk_most[kVectors], chunk_first[kVectors], chunk_last[kVectors];
    V16 sum_even[kVectors], sum_odd[kVectors];
    for (int k = 0; k < kVectors; ++k) {
      chunk_most[k] = chunk_first[k] = chunk_last[k] = hn::Zero(d8);
      sum_even[k] = sum_odd[k] = hn::Zero(d16);
    }
    V8 row = hn::Zero(d8);  // from the chunk's start
    const std::uint8_t* p = image + v0 * stride + u;
    for (int v = v0; v < std::min(v0 + kChunk, height); ++v, p += stride) {
      // Rows a strip apart defeat the hardware's prefetcher.
      if (v + kAhead < height) {
        hwy::Prefetch(p + kAhead * stride);
        if (kVectors * n > 64) hwy::Prefetch(p + kAhead * stride + 64);
      }
      for (int k = 0; k < kVectors; ++k) {
        const V8 x = hn::LoadU(d8, p + k * n);
        const V8 larger = hn::Max(chunk_most[k], x);
        // Not greater: the largest so far stays; at least as large: x is the largest.
        chunk_first[k] = hn::IfThenElse(hn::Eq(larger, chunk_most[k]), chunk_first[k], row);
        chunk_last[k] = hn::IfThenElse(hn::Eq(larger, x), row, chunk_last[k]);
        chunk_most[k] = larger;
        const V16 pairs = hn::BitCast(d16, x);
        sum_even[k] = hn::Add(sum_even[k], hn::And(pairs, low_byte));
        sum_odd[k] = hn::Add(sum_odd[k], hn::ShiftRight<8>(pairs));
      }
      row = hn::Add(row, one);
    }
    const V16 start = hn::Set(d16, static_cast<std::uint16_t>(v0));
    for (int k = 0; k < kVectors; ++k) {
      V16 chunk_most_even, chunk_most_odd, most_even, most_odd, chunk_first_even, chunk_first_odd,
          chunk_last_even, chunk_last_odd;
      split(chunk_most[k], chunk_most_even, chunk_most_odd);
      split(most[k], most_even, most_odd);
      split(chunk_first[k], chunk_first_even, chunk_first_odd);
      split(chunk_last[k], chunk_last_even, chunk_last_odd);
      first_even[k] = hn::IfThenElse(hn::Gt(chunk_most_even, most_even),
                                     hn::Add(start, chunk_first_even), first_even[k]);
      first_odd[k] = hn::IfThenElse(hn::Gt(chunk_most_odd, most_odd),
                                    hn::Add(start, chunk_first_odd), first_odd[k]);
      // (Highway 1.0 has no Ge of unsigned lanes.)
      last_even[k] = hn::IfThenElse(hn::Eq(hn::Max(chunk_most_even, most_even), chunk_most_even),
                                    hn::Add(start, chunk_last_even), last_even[k]);
      last_odd[k] = hn::IfThenElse(hn::Eq(hn::Max(chunk_most_odd, most_odd), chunk_most_odd),
                                   hn::Add(start, chunk_last_odd), last_odd[k]);
      most[k] = hn::Max(most[k], chunk_most[k]);
      hn::Store(sum_even[k], d16, even.data());
      hn::Store(sum_odd[k], d16, odd.data());
      const int columns = u + static_cast<int>(k * n);
      for (std::size_t j = 0; j < half; ++j) {
        sum[columns + 2 * j] += even[j];
        sum[columns + 2 * j + 1] += odd[j];
      }
    }
  }
  // Columns 2j from the even lanes, 2j + 1 from the odd ones.
  const auto spread = [&](std::uint16_t* to, int columns, V16 even_lanes, V16 odd_lanes) HWY_ATTR {
    hn::Store(even_lanes, d16, even.data());
    hn::Store(odd_lanes, d16, odd.data());
    for (std::size_t j = 0; j < half; ++j) {
      to[columns + 2 * j] = even[j];
      to[columns + 2 * j + 1] = odd[j];
    }
  };
  for (int k = 0; k < kVectors; ++k) {
    const int columns = u + static_cast<int>(k * n);
    hn::StoreU(most[k], d8, max + columns);
    spread(first, columns, first_even[k], first_odd[k]);
    spread(last, columns, last_even[k], last_odd[k]);
  }
}

void ColumnMaxima(const std::uint8_t* image, std::ptrdiff_t stride, int begin, int end, int height,
                  std::uint8_t* max, std::uint16_t* first, std::uint16_t* last,
                  std::uint32_t* sum) {
  const int n = static_cast<int>(hn::Lanes(hn::ScalableTag<std::uint8_t>()));
  int u = begin;
  for (; u + 2 * n <= end; u += 2 * n)
    ColumnMaximaStrip<2>(image, stride, u, height, max, first, last, sum);
  for (; u + n <= end; u += n)
    ColumnMaximaStrip<1>(image, stride, u, height, max, first, last, sum);
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

// Pairs of pixels as 16-bit lanes (which byte is which does not matter: they are summed), so that
// the sums of four fit, then narrowed back to bytes.
void DownsampleRow(const std::uint8_t* a, const std::uint8_t* b, int count, std::uint8_t* out) {
#if HWY_TARGET == HWY_SCALAR
  reference::downsample_row(a, b, count, out);
#else
  const hn::ScalableTag<std::uint16_t> d;
  const hn::RebindToSigned<decltype(d)> di;
  const hn::Rebind<std::uint8_t, decltype(di)> d8;
  const hn::Repartition<std::uint8_t, decltype(d)> bytes;
  const auto n = static_cast<int>(hn::Lanes(d));
  const auto low = hn::Set(d, 0xFF);
  const auto two = hn::Set(d, 2);
  int u = 0;
  for (; u + n <= count; u += n) {
    const auto pa = hn::BitCast(d, hn::LoadU(bytes, a + 2 * u));
    const auto pb = hn::BitCast(d, hn::LoadU(bytes, b + 2 * u));
    const auto sum = hn::Add(hn::Add(hn::And(pa, low), hn::ShiftRight<8>(pa)),
                             hn::Add(hn::Add(hn::And(pb, low), hn::ShiftRight<8>(pb)), two));
    hn::StoreU(hn::DemoteTo(d8, hn::BitCast(di, hn::ShiftRight<2>(sum))), d8, out + u);
  }
  if (u < count) reference::downsample_row(a + 2 * u, b + 2 * u, count - u, out + u);
#endif
}

// Whole vectors streamed past the cache to aligned destinations, the unaligned ends copied; the
// stores fenced at the end, so that a thread that synchronises with this one after the call sees
// them.
void CopyRowsPastCache(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                       std::ptrdiff_t dst_stride, int width, int rows) {
#if HWY_TARGET == HWY_SCALAR
  reference::copy_rows_past_cache(src, src_stride, dst, dst_stride, width, rows);
#else
  const hn::ScalableTag<std::uint8_t> d;
  const auto n = static_cast<std::ptrdiff_t>(hn::Lanes(d));
  for (int v = 0; v < rows; ++v) {
    const std::uint8_t* from = src + v * src_stride;
    std::uint8_t* to = dst + v * dst_stride;
    const auto misaligned = static_cast<std::ptrdiff_t>(reinterpret_cast<std::uintptr_t>(to) %
                                                        static_cast<std::uintptr_t>(n));
    std::ptrdiff_t u = std::min<std::ptrdiff_t>((n - misaligned) % n, width);
    std::memcpy(to, from, static_cast<std::size_t>(u));
    for (; u + n <= width; u += n)
      hn::Stream(hn::LoadU(d, from + u), d, to + u);
    std::memcpy(to + u, from + u, static_cast<std::size_t>(width - u));
  }
  hwy::FlushStream();
#endif
}

void SlideStructureRow(const std::uint8_t* up, const std::uint8_t* mid, const std::uint8_t* down,
                       std::int32_t* xx, std::int32_t* xy, std::int32_t* yy, std::int32_t* sum_xx,
                       std::int32_t* sum_xy, std::int32_t* sum_yy, int first, int last) {
#if HWY_TARGET == HWY_SCALAR
  reference::slide_structure_row(up, mid, down, xx, xy, yy, sum_xx, sum_xy, sum_yy, first, last);
#else
  const hn::ScalableTag<std::int32_t> d;
  const hn::Rebind<std::uint8_t, decltype(d)> d8;
  const auto n = static_cast<int>(hn::Lanes(d));
  const auto wide = [&](const std::uint8_t* p)
                        HWY_ATTR { return hn::PromoteTo(d, hn::LoadU(d8, p)); };
  const auto replace = [&](std::int32_t* products, std::int32_t* sums, int u,
                           hn::Vec<decltype(d)> p) HWY_ATTR {
    hn::StoreU(hn::Add(hn::LoadU(d, sums + u), hn::Sub(p, hn::LoadU(d, products + u))), d,
               sums + u);
    hn::StoreU(p, d, products + u);
  };
  int u = first;
  for (; u + n <= last; u += n) {
    const auto gx = hn::Sub(wide(mid + u + 1), wide(mid + u - 1));
    const auto gy = hn::Sub(wide(down + u), wide(up + u));
    replace(xx, sum_xx, u, hn::Mul(gx, gx));
    replace(xy, sum_xy, u, hn::Mul(gx, gy));
    replace(yy, sum_yy, u, hn::Mul(gy, gy));
  }
  reference::slide_structure_row(up, mid, down, xx, xy, yy, sum_xx, sum_xy, sum_yy, u, last);
#endif
}

void CornerScores(const std::int32_t* sum_xx, const std::int32_t* sum_xy,
                  const std::int32_t* sum_yy, int first, int last, float* score) {
  const hn::ScalableTag<float> df;
  const hn::RebindToSigned<decltype(df)> di;
  const auto n = static_cast<int>(hn::Lanes(df));
  const auto half = hn::Set(df, 0.5f);
  const auto three = [&](const std::int32_t* sums, int u) HWY_ATTR {
    return hn::Add(hn::Add(hn::LoadU(di, sums + u - 1), hn::LoadU(di, sums + u)),
                   hn::LoadU(di, sums + u + 1));
  };
  int u = first;
  for (; u + n <= last; u += n) {
    const auto a = three(sum_xx, u), b = three(sum_xy, u), c = three(sum_yy, u);
    const auto half_difference = hn::Mul(half, hn::ConvertTo(df, hn::Sub(a, c)));
    const auto bf = hn::ConvertTo(df, b);
    const auto root = hn::Sqrt(hn::Add(hn::Mul(half_difference, half_difference), hn::Mul(bf, bf)));
    hn::StoreU(hn::Sub(hn::Mul(half, hn::ConvertTo(df, hn::Add(a, c))), root), df, score + u);
  }
  reference::corner_scores(sum_xx, sum_xy, sum_yy, u, last, score);
}

}  // namespace HWY_NAMESPACE
}  // namespace laserline::pipeline::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace laserline::pipeline::kernels {

HWY_EXPORT(ColumnMaxima);
HWY_EXPORT(Transpose16);
HWY_EXPORT(DownsampleRow);
HWY_EXPORT(CopyRowsPastCache);
HWY_EXPORT(CornerScores);
HWY_EXPORT(SlideStructureRow);

void slide_structure_row(const std::uint8_t* up, const std::uint8_t* mid, const std::uint8_t* down,
                         std::int32_t* xx, std::int32_t* xy, std::int32_t* yy, std::int32_t* sum_xx,
                         std::int32_t* sum_xy, std::int32_t* sum_yy, int first, int last) {
  HWY_DYNAMIC_DISPATCH(SlideStructureRow)
  (up, mid, down, xx, xy, yy, sum_xx, sum_xy, sum_yy, first, last);
}

void corner_scores(const std::int32_t* sum_xx, const std::int32_t* sum_xy,
                   const std::int32_t* sum_yy, int first, int last, float* score) {
  HWY_DYNAMIC_DISPATCH(CornerScores)(sum_xx, sum_xy, sum_yy, first, last, score);
}

void copy_rows_past_cache(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                          std::ptrdiff_t dst_stride, int width, int rows) {
  HWY_DYNAMIC_DISPATCH(CopyRowsPastCache)(src, src_stride, dst, dst_stride, width, rows);
}

void downsample_row(const std::uint8_t* a, const std::uint8_t* b, int count, std::uint8_t* out) {
  HWY_DYNAMIC_DISPATCH(DownsampleRow)(a, b, count, out);
}

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

void downsample_row(const std::uint8_t* a, const std::uint8_t* b, int count, std::uint8_t* out) {
  for (int u = 0; u < count; ++u) {
    const unsigned sum = 2u + a[2 * u] + a[2 * u + 1] + b[2 * u] + b[2 * u + 1];
    out[u] = static_cast<std::uint8_t>(sum >> 2);
  }
}

void copy_rows_past_cache(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                          std::ptrdiff_t dst_stride, int width, int rows) {
  for (int v = 0; v < rows; ++v)
    std::memcpy(dst + v * dst_stride, src + v * src_stride, static_cast<std::size_t>(width));
}

void slide_structure_row(const std::uint8_t* up, const std::uint8_t* mid, const std::uint8_t* down,
                         std::int32_t* xx, std::int32_t* xy, std::int32_t* yy, std::int32_t* sum_xx,
                         std::int32_t* sum_xy, std::int32_t* sum_yy, int first, int last) {
  for (int u = first; u < last; ++u) {
    const std::int32_t gx = mid[u + 1] - mid[u - 1];
    const std::int32_t gy = down[u] - up[u];
    const std::int32_t pxx = gx * gx, pxy = gx * gy, pyy = gy * gy;
    sum_xx[u] += pxx - xx[u];
    sum_xy[u] += pxy - xy[u];
    sum_yy[u] += pyy - yy[u];
    xx[u] = pxx;
    xy[u] = pxy;
    yy[u] = pyy;
  }
}

void corner_scores(const std::int32_t* sum_xx, const std::int32_t* sum_xy,
                   const std::int32_t* sum_yy, int first, int last, float* score) {
  for (int u = first; u < last; ++u) {
    const std::int32_t a = sum_xx[u - 1] + sum_xx[u] + sum_xx[u + 1];
    const std::int32_t c = sum_yy[u - 1] + sum_yy[u] + sum_yy[u + 1];
    const std::int32_t b = sum_xy[u - 1] + sum_xy[u] + sum_xy[u + 1];
    const float half_difference = 0.5f * static_cast<float>(a - c);
    const float bf = static_cast<float>(b);
    score[u] =
        0.5f * static_cast<float>(a + c) - std::sqrt(half_difference * half_difference + bf * bf);
  }
}

}  // namespace reference
}  // namespace laserline::pipeline::kernels
#endif  // HWY_ONCE
