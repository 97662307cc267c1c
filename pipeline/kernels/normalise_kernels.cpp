// Kernels of the row normalisation (paper III-A/B): the current frame's rows interpolated, minus
// the background seen through the warp. Compiled once per target (foreach_target.h); the scalar
// reference at the end.
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "pipeline/kernels/kernels.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/kernels/normalise_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace laserline::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// 16-bit lanes, at most a warp block's worth.
using D16 = hn::CappedTag<std::uint16_t, WarpRow::kWarpBlock>;
using D8 = hn::Rebind<std::uint8_t, D16>;

HWY_INLINE hn::Vec<D16> widened(const std::uint8_t* x) {
  return hn::PromoteTo(D16(), hn::LoadU(D8(), x));
}

HWY_INLINE hn::Vec<D16> rounded(hn::Vec<D16> value, int shift) {
  const D16 d;
  return hn::ShiftRightSame(
      hn::Add(value, hn::Set(d, static_cast<std::uint16_t>((1 << shift) >> 1))), shift);
}

void InterpolateRow(const std::uint8_t* a, const std::uint8_t* b, std::uint16_t fb, int shift,
                    int count, std::uint16_t* out) {
  const D16 d;
  const int n = static_cast<int>(hn::Lanes(d));
  const auto weight_a = hn::Set(d, static_cast<std::uint16_t>(kFixedOne - fb));
  const auto weight_b = hn::Set(d, fb);
  int u = 0;
  for (; u + n <= count; u += n) {
    const auto current =
        hn::Add(hn::Mul(widened(a + u), weight_a), hn::Mul(widened(b + u), weight_b));
    hn::StoreU(rounded(current, shift), d, out + u);
  }
  reference::interpolate_row(a + u, b + u, fb, shift, count - u, out + u);
}

// Pixels [u, u + count) of the row against background rows p (under pixel u) and p + stride,
// with block j's weights: vectors of d; where the count is not a multiple of their lanes, the
// last overlaps the one before (the same pixels written twice, alike); fewer pixels than a vector,
// the scalar reference.
template <class D>
HWY_INLINE void DifferencePixels(D d, const WarpRow& row, int u, const std::uint8_t* p, int j,
                                 int count) {
  const int n = static_cast<int>(hn::Lanes(d));
  if (count < n) {
    reference::difference_pixels(row, u, p, j, count);
    return;
  }
  const hn::Rebind<std::uint8_t, D> d8;
  auto wide = [&](const std::uint8_t* x) HWY_ATTR { return hn::PromoteTo(d, hn::LoadU(d8, x)); };
  const auto weight_a = hn::Set(d, static_cast<std::uint16_t>(kFixedOne - row.fb));
  const auto weight_b = hn::Set(d, row.fb);
  const auto w00 = hn::Set(d, static_cast<std::uint16_t>(row.w00[j]));
  const auto w01 = hn::Set(d, static_cast<std::uint16_t>(row.w01[j]));
  const auto w10 = hn::Set(d, static_cast<std::uint16_t>(row.w10[j]));
  const auto w11 = hn::Set(d, static_cast<std::uint16_t>(row.w11[j]));
  const auto half = hn::Set(d, static_cast<std::uint16_t>((1 << row.shift) >> 1));
  const std::uint8_t* q = p + row.stride;
  for (int k = 0;; k += n) {
    k = std::min(k, count - n);
    const int i = u + k;
    const auto current =
        hn::Add(hn::Mul(wide(row.a + i), weight_a), hn::Mul(wide(row.b + i), weight_b));
    const auto warped = hn::Add(hn::Add(hn::Mul(wide(p + k), w00), hn::Mul(wide(p + k + 1), w01)),
                                hn::Add(hn::Mul(wide(q + k), w10), hn::Mul(wide(q + k + 1), w11)));
    // The laser only adds light: clipped at 0.
    hn::StoreU(hn::ShiftRightSame(hn::Add(hn::SaturatedSub(current, warped), half), row.shift), d,
               row.out + i);
    if (k == count - n) break;
  }
}

void DifferenceRow(const WarpRow& row) {
  constexpr int kWarp = WarpRow::kWarpBlock;
  for (int j = 0; j < row.blocks; ++j) {
    if (row.whole[j]) {
      DifferencePixels(D16(), row, j * kWarp, row.background + row.offset[j], j, kWarp);
    }
  }
  // The blocks partly or wholly outside the background: pixels [f, e) have their four neighbours
  // inside it; elsewhere there is nothing to compare with, so no signal. (Few or none: the scan
  // stops after the last.)
  for (int j = 0, partial = row.partial; partial > 0; ++j) {
    if (row.whole[j]) continue;
    --partial;
    const int u0 = j * kWarp;
    const int count = std::min(kWarp, row.width - u0);
    const int ix = row.left[j], iy = row.top[j];
    const auto [f, e, last_column] = reference::partial_block(row, ix, iy, count);
    std::fill(row.out + u0, row.out + u0 + f, std::uint16_t{0});
    std::fill(row.out + u0 + e, row.out + u0 + count, std::uint16_t{0});
    const std::uint8_t* p = row.background + static_cast<std::ptrdiff_t>(iy) * row.stride + ix;
    if (f < e) {
      // (Narrower vectors: the part of a block inside is often short.)
      DifferencePixels(hn::CappedTag<std::uint16_t, 8>(), row, u0 + f, p + f, j, e - f);
    }
    if (last_column) reference::difference_last_column(row, u0 + e, p + e, j);
  }
}

int WarpBlocksOf(const WarpLine& line, int first, int end, const WarpBlocks& out) {
  constexpr int kWarp = WarpRow::kWarpBlock;
  const hn::ScalableTag<float> df;
  const hn::RebindToSigned<decltype(df)> di;
  const hn::RebindToUnsigned<decltype(df)> du;
  const int n = static_cast<int>(hn::Lanes(df));
  const auto far = hn::Set(df, line.far), near = hn::Set(df, -line.far);
  const auto one = hn::Set(df, 1.0f), half = hn::Set(df, 0.5f);
  const auto fixed_one = hn::Set(di, kFixedOne);
  int partial = 0;
  int j = first;
  for (; j + n <= end; j += n) {
    const auto u0 = hn::Mul(hn::Add(hn::Iota(di, 0), hn::Set(di, j)), hn::Set(di, kWarp));
    const auto count = hn::Min(hn::Set(di, kWarp), hn::Sub(hn::Set(di, line.width), u0));
    const auto start = hn::ConvertTo(df, u0);
    const auto centre =
        hn::Add(start, hn::Mul(half, hn::ConvertTo(df, hn::Sub(count, hn::Set(di, 1)))));
    const auto inv =
        hn::Div(one, hn::Add(hn::Set(df, line.wn0), hn::Mul(hn::Set(df, line.wnu), centre)));
    const auto y =
        hn::Mul(hn::Add(hn::Set(df, line.yn0), hn::Mul(hn::Set(df, line.ynu), centre)), inv);
    const auto x = hn::Sub(
        hn::Mul(hn::Add(hn::Set(df, line.xn0), hn::Mul(hn::Set(df, line.xnu), centre)), inv),
        hn::Sub(centre, start));
    // (A NaN compares false: to -far.)
    const auto xs = hn::IfThenElse(hn::Gt(x, near), hn::IfThenElse(hn::Lt(x, far), x, far), near);
    const auto ys = hn::IfThenElse(hn::Gt(y, near), hn::IfThenElse(hn::Lt(y, far), y, far), near);
    const auto fx = hn::Floor(xs), fy = hn::Floor(ys);
    const auto ix = hn::ConvertTo(di, fx), iy = hn::ConvertTo(di, fy);
    hn::StoreU(ix, di, out.left + j);
    hn::StoreU(iy, di, out.top + j);
    const auto offset =
        hn::Add(hn::Mul(hn::BitCast(du, iy), hn::Set(du, static_cast<std::uint32_t>(line.stride))),
                hn::BitCast(du, ix));
    hn::StoreU(hn::BitCast(di, offset), di, out.offset + j);
    const auto whole_mask = hn::And(
        hn::And(hn::Eq(count, hn::Set(di, kWarp)), hn::Not(hn::Lt(ix, hn::Zero(di)))),
        hn::And(
            hn::Not(hn::Gt(hn::Add(ix, hn::Set(di, kWarp)), hn::Set(di, line.last_column))),
            hn::And(hn::Not(hn::Lt(iy, hn::Zero(di))), hn::Lt(iy, hn::Set(di, line.last_row)))));
    const auto whole = hn::IfThenElseZero(whole_mask, hn::Set(di, 1));
    hn::StoreU(whole, di, out.whole + j);
    partial += n - static_cast<int>(hn::CountTrue(di, whole_mask));
    const auto tx = hn::Sub(xs, fx), ty = hn::Sub(ys, fy);
    const auto top_share = hn::ConvertTo(
        di, hn::Add(hn::Mul(hn::Sub(one, ty), hn::Set(df, static_cast<float>(kFixedOne))), half));
    const auto bottom_share = hn::Sub(fixed_one, top_share);
    const auto top_left =
        hn::ConvertTo(di, hn::Add(hn::Mul(hn::Sub(one, tx), hn::ConvertTo(df, top_share)), half));
    const auto bottom_left = hn::ConvertTo(
        di, hn::Add(hn::Mul(hn::Sub(one, tx), hn::ConvertTo(df, bottom_share)), half));
    hn::StoreU(top_left, di, out.w00 + j);
    hn::StoreU(hn::Sub(top_share, top_left), di, out.w01 + j);
    hn::StoreU(bottom_left, di, out.w10 + j);
    hn::StoreU(hn::Sub(bottom_share, bottom_left), di, out.w11 + j);
  }
  return partial + reference::warp_blocks(line, j, end, out);
}

const char* TargetName() {
  return hwy::TargetName(HWY_TARGET);
}

}  // namespace HWY_NAMESPACE
}  // namespace laserline::pipeline::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace laserline::pipeline::kernels {

HWY_EXPORT(InterpolateRow);
HWY_EXPORT(DifferenceRow);
HWY_EXPORT(TargetName);
HWY_EXPORT(WarpBlocksOf);

int warp_blocks(const WarpLine& line, int first, int end, const WarpBlocks& out) {
  return HWY_DYNAMIC_DISPATCH(WarpBlocksOf)(line, first, end, out);
}

void interpolate_row(const std::uint8_t* a, const std::uint8_t* b, std::uint16_t fb, int shift,
                     int count, std::uint16_t* out) {
  HWY_DYNAMIC_DISPATCH(InterpolateRow)(a, b, fb, shift, count, out);
}

void difference_row(const WarpRow& row) {
  HWY_DYNAMIC_DISPATCH(DifferenceRow)(row);
}

const char* target_name() {
  return HWY_DYNAMIC_DISPATCH(TargetName)();
}

namespace reference {

namespace {
std::uint16_t rounded(unsigned value, int shift) {
  return static_cast<std::uint16_t>((value + ((1u << shift) >> 1)) >> shift);
}
}  // namespace

void interpolate_row(const std::uint8_t* a, const std::uint8_t* b, std::uint16_t fb, int shift,
                     int count, std::uint16_t* out) {
  const auto fa = static_cast<std::uint16_t>(kFixedOne - fb);
  for (int u = 0; u < count; ++u)
    out[u] = rounded(static_cast<std::uint16_t>(a[u] * fa + b[u] * fb), shift);
}

int warp_blocks(const WarpLine& line, int first, int end, const WarpBlocks& out) {
  constexpr int kWarp = WarpRow::kWarpBlock;
  int partial = 0;
  for (int j = first; j < end; ++j) {
    const int u0 = j * kWarp;
    const int count = std::min(kWarp, line.width - u0);
    const float centre = static_cast<float>(u0) + 0.5f * static_cast<float>(count - 1);
    const float inv = 1.0f / (line.wn0 + line.wnu * centre);
    const float y = (line.yn0 + line.ynu * centre) * inv;
    const float x = (line.xn0 + line.xnu * centre) * inv - (centre - static_cast<float>(u0));
    const float far = line.far;
    const float xs = x > -far ? (x < far ? x : far) : -far;
    const float ys = y > -far ? (y < far ? y : far) : -far;
    const float fx = std::floor(xs), fy = std::floor(ys);
    const auto ix = static_cast<std::int32_t>(fx), iy = static_cast<std::int32_t>(fy);
    out.left[j] = ix;
    out.top[j] = iy;
    // (Where whole, it fits: unsigned, so that elsewhere it may wrap.)
    out.offset[j] = static_cast<std::int32_t>(static_cast<std::uint32_t>(iy) *
                                                  static_cast<std::uint32_t>(line.stride) +
                                              static_cast<std::uint32_t>(ix));
    // Whole: all its pixels' four neighbours lie inside the background (nearly every block).
    out.whole[j] = (count == kWarp) & (ix >= 0) & (ix + kWarp <= line.last_column) & (iy >= 0) &
                   (iy < line.last_row);
    partial += 1 - out.whole[j];
    const float tx = xs - fx, ty = ys - fy;
    // The four sum to 128 (else the background is scaled) by construction: the rows' shares
    // rounded, then each row's share split between its two pixels.
    const auto top_share =
        static_cast<std::int32_t>((1.0f - ty) * static_cast<float>(kFixedOne) + 0.5f);
    const std::int32_t bottom_share = kFixedOne - top_share;
    const auto top_left =
        static_cast<std::int32_t>((1.0f - tx) * static_cast<float>(top_share) + 0.5f);
    const auto bottom_left =
        static_cast<std::int32_t>((1.0f - tx) * static_cast<float>(bottom_share) + 0.5f);
    out.w00[j] = top_left;
    out.w01[j] = top_share - top_left;
    out.w10[j] = bottom_left;
    out.w11[j] = bottom_share - bottom_left;
  }
  return partial;
}

void difference_pixels(const WarpRow& row, int u, const std::uint8_t* p, int block, int count) {
  const auto fa = static_cast<std::uint16_t>(kFixedOne - row.fb);
  const std::uint8_t* q = p + row.stride;
  const auto j = static_cast<std::size_t>(block);
  for (int k = 0; k < count; ++k) {
    const auto current = static_cast<std::uint16_t>(row.a[u + k] * fa + row.b[u + k] * row.fb);
    const auto warped = static_cast<std::uint16_t>(p[k] * row.w00[j] + p[k + 1] * row.w01[j] +
                                                   q[k] * row.w10[j] + q[k + 1] * row.w11[j]);
    row.out[u + k] = rounded(current > warped ? current - warped : 0u, row.shift);
  }
}

void difference_row(const WarpRow& row) {
  constexpr int kWarp = WarpRow::kWarpBlock;
  for (int j = 0; j < row.blocks; ++j) {
    const int u0 = j * kWarp;
    const int count = std::min(kWarp, row.width - u0);
    if (row.whole[j]) {
      difference_pixels(row, u0, row.background + row.offset[j], j, count);
      continue;
    }
    const int ix = row.left[j], iy = row.top[j];
    const auto [f, e, last_column] = partial_block(row, ix, iy, count);
    std::fill(row.out + u0, row.out + u0 + f, std::uint16_t{0});
    std::fill(row.out + u0 + e, row.out + u0 + count, std::uint16_t{0});
    const std::uint8_t* p = row.background + static_cast<std::ptrdiff_t>(iy) * row.stride + ix;
    if (f < e) difference_pixels(row, u0 + f, p + f, j, e - f);
    if (last_column) difference_last_column(row, u0 + e, p + e, j);
  }
}

PartialBlock partial_block(const WarpRow& row, int ix, int iy, int count) {
  if (iy < 0 || iy >= row.last_row) return {count, count, false};
  const int first = std::clamp(-ix, 0, count);
  const int end = std::clamp(row.last_column - ix, first, count);
  return {first, end, end < count && ix + end == row.last_column && ix + end >= 0};
}

void difference_last_column(const WarpRow& row, int u, const std::uint8_t* p, int block) {
  const auto fa = static_cast<std::uint16_t>(kFixedOne - row.fb);
  const auto j = static_cast<std::size_t>(block);
  const auto current = static_cast<std::uint16_t>(row.a[u] * fa + row.b[u] * row.fb);
  const auto warped = static_cast<std::uint16_t>(p[0] * (row.w00[j] + row.w01[j]) +
                                                 p[row.stride] * (row.w10[j] + row.w11[j]));
  row.out[u] = rounded(current > warped ? current - warped : 0u, row.shift);
}

}  // namespace reference
}  // namespace laserline::pipeline::kernels
#endif  // HWY_ONCE
