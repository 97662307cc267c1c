// Kernels of the row normalisation (paper III-A/B): the current frame's rows interpolated, minus
// the background seen through the warp. Compiled once per target (foreach_target.h); the scalar
// reference at the end.
#include <algorithm>
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
// with block j's weights.
HWY_INLINE void DifferencePixels(const WarpRow& row, int u, const std::uint8_t* p, int j,
                                 int count) {
  const D16 d;
  const int n = static_cast<int>(hn::Lanes(d));
  const auto weight_a = hn::Set(d, static_cast<std::uint16_t>(kFixedOne - row.fb));
  const auto weight_b = hn::Set(d, row.fb);
  const auto w00 = hn::Set(d, static_cast<std::uint16_t>(row.w00[j]));
  const auto w01 = hn::Set(d, static_cast<std::uint16_t>(row.w01[j]));
  const auto w10 = hn::Set(d, static_cast<std::uint16_t>(row.w10[j]));
  const auto w11 = hn::Set(d, static_cast<std::uint16_t>(row.w11[j]));
  const std::uint8_t* q = p + row.stride;
  int k = 0;
  for (; k + n <= count; k += n) {
    const int i = u + k;
    const auto current =
        hn::Add(hn::Mul(widened(row.a + i), weight_a), hn::Mul(widened(row.b + i), weight_b));
    const auto warped =
        hn::Add(hn::Add(hn::Mul(widened(p + k), w00), hn::Mul(widened(p + k + 1), w01)),
                hn::Add(hn::Mul(widened(q + k), w10), hn::Mul(widened(q + k + 1), w11)));
    // The laser only adds light: clipped at 0.
    hn::StoreU(rounded(hn::SaturatedSub(current, warped), row.shift), d, row.out + i);
  }
  if (k < count) reference::difference_pixels(row, u + k, p + k, j, count - k);
}

void DifferenceRow(const WarpRow& row) {
  constexpr int kWarp = WarpRow::kWarpBlock;
  for (int j = 0; j < row.blocks; ++j) {
    if (row.whole[j]) DifferencePixels(row, j * kWarp, row.background + row.offset[j], j, kWarp);
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
    const bool rows_inside = iy >= 0 && iy < row.last_row;
    const int f = rows_inside ? std::clamp(-ix, 0, count) : count;
    const int e = rows_inside ? std::clamp(row.last_column - ix, f, count) : count;
    std::fill(row.out + u0, row.out + u0 + f, std::uint16_t{0});
    std::fill(row.out + u0 + e, row.out + u0 + count, std::uint16_t{0});
    if (f < e) {
      DifferencePixels(row, u0 + f,
                       row.background + static_cast<std::ptrdiff_t>(iy) * row.stride + ix + f, j,
                       e - f);
    }
  }
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
    const bool rows_inside = iy >= 0 && iy < row.last_row;
    const int f = rows_inside ? std::clamp(-ix, 0, count) : count;
    const int e = rows_inside ? std::clamp(row.last_column - ix, f, count) : count;
    std::fill(row.out + u0, row.out + u0 + f, std::uint16_t{0});
    std::fill(row.out + u0 + e, row.out + u0 + count, std::uint16_t{0});
    if (f < e) {
      difference_pixels(row, u0 + f,
                        row.background + static_cast<std::ptrdiff_t>(iy) * row.stride + ix + f, j,
                        e - f);
    }
  }
}

}  // namespace reference
}  // namespace laserline::pipeline::kernels
#endif  // HWY_ONCE
