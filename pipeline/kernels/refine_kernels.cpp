// The sub-pixel refinement of many columns at once (paper III-F), a column per lane: the same
// arithmetic as the scalar reference at the end, in the same order, so the same results.
// Compiled once per target (foreach_target.h).
#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <limits>

#include "pipeline/kernels/kernels.hpp"
#include "pipeline/subpixel.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/kernels/refine_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace laserline::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// At most 16 columns at a time.
using DF = hn::CappedTag<float, 16>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;
using VI = hn::Vec<DI>;
using MI = hn::Mask<DI>;
constexpr std::size_t kMaxLanes = 16;

// Four bytes from each of base + offset (lanes not `wanted`: 0), by one load per lane: gathers
// are slower than that on the CPUs measured. The lanes not wanted read from base itself.
HWY_INLINE VI FourBytesAt(const std::uint8_t* base, VI offset, MI wanted) {
  const DI di;
  alignas(64) std::array<std::int32_t, kMaxLanes> at{};
  hn::Store(hn::IfThenElseZero(wanted, offset), di, at.data());
  alignas(64) std::array<std::int32_t, kMaxLanes> value{};
  for (std::size_t j = 0; j < hn::Lanes(di); ++j)
    std::memcpy(&value[j], base + at[j], sizeof value[j]);
  return hn::IfThenElseZero(wanted, hn::Load(di, value.data()));
}

// The columns of one vector: their samples as the reference takes them.
class Lanes {
 public:
  Lanes(const RefineColumns& c, int first)
      : column_(hn::LoadU(DI(), c.u + first)),
        centre_(hn::LoadU(DI(), c.centre + first)),
        x0_(hn::LoadU(DF(), c.x0 + first)),
        y0_(hn::LoadU(DF(), c.y0 + first)),
        dx_(hn::LoadU(DF(), c.dx + first)),
        dy_(hn::LoadU(DF(), c.dy + first)),
        current_stride_(hn::Set(DI(), static_cast<std::int32_t>(c.current_stride))),
        background_stride_(hn::Set(DI(), static_cast<std::int32_t>(c.background_stride))),
        current_(c.current),
        top_row_(c.background),
        bottom_row_(c.background + c.background_stride) {}

  // The current frame at `rows` of the columns (lanes not `wanted`: 0).
  HWY_INLINE VI Current(VI rows, MI wanted) const {
    const DI di;
    const VI offset = hn::Add(hn::Mul(rows, current_stride_), column_);
    return hn::And(FourBytesAt(current_, offset, wanted), hn::Set(di, 0xff));
  }

  // The background-free samples at `rows` (lanes not `wanted`: 0).
  HWY_INLINE VF Sample(VI rows, MI wanted) const {
    const DF df;
    const DI di;
    const VI low_byte = hn::Set(di, 0xff);
    const VF k = hn::ConvertTo(df, hn::Sub(rows, centre_));
    const VF x = hn::Add(x0_, hn::Mul(dx_, k));
    const VF y = hn::Add(y0_, hn::Mul(dy_, k));
    const VI ix = hn::ConvertTo(di, x), iy = hn::ConvertTo(di, y);  // (truncated)
    const VF fx = hn::Sub(x, hn::ConvertTo(df, ix));
    const VF fy = hn::Sub(y, hn::ConvertTo(df, iy));
    const VI offset = hn::Add(hn::Mul(iy, background_stride_), ix);
    const VI top = FourBytesAt(top_row_, offset, wanted);
    const VI bottom = FourBytesAt(bottom_row_, offset, wanted);
    const VF p00 = hn::ConvertTo(df, hn::And(top, low_byte));
    const VF p01 = hn::ConvertTo(df, hn::And(hn::ShiftRight<8>(top), low_byte));
    const VF p10 = hn::ConvertTo(df, hn::And(bottom, low_byte));
    const VF p11 = hn::ConvertTo(df, hn::And(hn::ShiftRight<8>(bottom), low_byte));
    const VF upper = hn::Add(p00, hn::Mul(fx, hn::Sub(p01, p00)));
    const VF lower = hn::Add(p10, hn::Mul(fx, hn::Sub(p11, p10)));
    const VF warped = hn::Add(upper, hn::Mul(fy, hn::Sub(lower, upper)));
    const VF value = hn::ConvertTo(df, Current(rows, wanted));
    return hn::Max(hn::Sub(value, warped), hn::Zero(df));
  }

 private:
  VI column_, centre_;
  VF x0_, y0_, dx_, dy_;
  VI current_stride_, background_stride_;
  const std::uint8_t* current_;
  const std::uint8_t* top_row_;
  const std::uint8_t* bottom_row_;
};

// Columns [first, first + lanes) into rows.
HWY_INLINE void RefineVector(const RefineColumns& c, int first, float* result) {
  const DF df;
  const DI di;
  const Lanes lanes(c, first);
  const MI all = hn::FirstN(di, hn::Lanes(di));
  const VI lo = hn::LoadU(di, c.lo + first), count = hn::LoadU(di, c.count + first);
  const VI last_row = hn::Set(di, c.last_row);
  // The search window: the first largest sample of each lane.
  VF most = hn::Set(df, -1.0f);
  VI best = lo;
  const int longest = hn::GetLane(hn::MaxOfLanes(di, count));
  for (int k = 0; k < longest; ++k) {
    const VI step = hn::Set(di, k);
    const MI wanted = hn::Gt(count, step);
    const VI rows = hn::Add(lo, step);
    const VF value = lanes.Sample(rows, wanted);
    const MI larger = hn::And(hn::RebindMask(di, hn::Gt(value, most)), wanted);
    most = hn::IfThenElse(hn::RebindMask(df, larger), value, most);
    best = hn::IfThenElse(larger, rows, best);
  }

  // A clipped core: left to the caller (NaN).
  const VI below_saturation = hn::Set(di, c.saturation - 1);
  const MI clipped = hn::Gt(lanes.Current(best, all), below_saturation);

  // Else the Gaussian 3-point fit on the baseline-free samples, where the baseline's samples lie
  // inside the frame.
  const VI edge = hn::LoadU(di, c.edge + first), spacing = hn::LoadU(di, c.spacing + first);
  const MI off_frame = hn::Or(hn::Gt(edge, best), hn::Gt(hn::Add(best, edge), last_row));
  const MI fitted = hn::Not(hn::Or(clipped, off_frame));
  const VF before = lanes.Sample(hn::Sub(best, edge), fitted);
  const VF after = lanes.Sample(hn::Add(best, edge), fitted);
  const VF slope = hn::Div(hn::Sub(after, before), hn::ConvertTo(df, hn::Add(edge, edge)));
  const VF baseline = hn::Mul(hn::Set(df, 0.5f), hn::Add(before, after));
  const VF rise = hn::Mul(slope, hn::ConvertTo(df, spacing));
  alignas(64) std::array<float, kMaxLanes> a{}, b{}, cc{}, rows{}, spacings{}, results{};
  hn::Store(hn::Sub(lanes.Sample(hn::Sub(best, spacing), fitted), hn::Sub(baseline, rise)), df,
            a.data());
  hn::Store(hn::Sub(most, baseline), df, b.data());
  hn::Store(hn::Sub(lanes.Sample(hn::Add(best, spacing), fitted), hn::Add(baseline, rise)), df,
            cc.data());
  hn::Store(hn::ConvertTo(df, best), df, rows.data());
  hn::Store(hn::ConvertTo(df, spacing), df, spacings.data());
  hn::Store(
      hn::IfThenElse(hn::RebindMask(df, clipped),
                     hn::Set(df, std::numeric_limits<float>::quiet_NaN()), hn::ConvertTo(df, best)),
      df, results.data());
  alignas(64) std::array<std::int32_t, kMaxLanes> fit{};
  hn::Store(hn::VecFromMask(di, fitted), di, fit.data());
  for (std::size_t j = 0; j < hn::Lanes(df); ++j) {
    result[j] =
        fit[j] != 0 ? rows[j] + spacings[j] * gaussian_offset(a[j], b[j], cc[j]) : results[j];
  }
}

void RefineColumnsOf(const RefineColumns& columns, int n, float* rows) {
  const int lanes = static_cast<int>(hn::Lanes(DF()));
  int j = 0;
  for (; j + lanes <= n; j += lanes)
    RefineVector(columns, j, rows + j);
  // (The rest one by one: a vector of them would need its lanes filled.)
  if (j < n) {
    RefineColumns rest = columns;
    for (auto* field : {&rest.u, &rest.centre, &rest.lo, &rest.count, &rest.spacing, &rest.edge})
      *field += j;
    for (auto* field : {&rest.x0, &rest.y0, &rest.dx, &rest.dy})
      *field += j;
    reference::refine_columns(rest, n - j, rows + j);
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace laserline::pipeline::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace laserline::pipeline::kernels {

HWY_EXPORT(RefineColumnsOf);

void refine_columns(const RefineColumns& columns, int n, float* rows) {
  HWY_DYNAMIC_DISPATCH(RefineColumnsOf)(columns, n, rows);
}

namespace reference {

namespace {

// Column j of `c`: its pixels and background-free samples.
struct Column {
  const RefineColumns& c;
  std::size_t j;

  float current(int v) const {
    return c.current[static_cast<std::ptrdiff_t>(v) * c.current_stride + c.u[j]];
  }
  float sample(int v) const {
    const auto k = static_cast<float>(v - c.centre[j]);
    const float x = c.x0[j] + c.dx[j] * k, y = c.y0[j] + c.dy[j] * k;
    const int ix = static_cast<int>(x), iy = static_cast<int>(y);
    const float fx = x - static_cast<float>(ix), fy = y - static_cast<float>(iy);
    const std::uint8_t* p =
        c.background + static_cast<std::ptrdiff_t>(iy) * c.background_stride + ix;
    const auto p00 = static_cast<float>(p[0]), p01 = static_cast<float>(p[1]);
    const auto p10 = static_cast<float>(p[c.background_stride]);
    const auto p11 = static_cast<float>(p[c.background_stride + 1]);
    const float upper = p00 + fx * (p01 - p00);
    const float lower = p10 + fx * (p11 - p10);
    const float difference = current(v) - (upper + fy * (lower - upper));
    return difference > 0.0f ? difference : 0.0f;
  }
};

float refine_column(const Column& at) {
  const RefineColumns& c = at.c;
  const std::size_t j = at.j;
  const int last = c.last_row;
  float most = -1.0f;
  int best = c.lo[j];
  for (int k = 0; k < c.count[j]; ++k) {
    const float value = at.sample(c.lo[j] + k);
    if (value > most) {
      most = value;
      best = c.lo[j] + k;
    }
  }
  if (at.current(best) >= static_cast<float>(c.saturation)) {
    return std::numeric_limits<float>::quiet_NaN();
  }
  const int edge = c.edge[j], spacing = c.spacing[j];
  if (best - edge < 0 || best + edge > last) return static_cast<float>(best);
  const float before = at.sample(best - edge), after = at.sample(best + edge);
  const float slope = (after - before) / static_cast<float>(2 * edge);
  const float level = 0.5f * (before + after);
  const float rise = slope * static_cast<float>(spacing);
  const float a = at.sample(best - spacing) - (level - rise);
  const float b = most - level;
  const float cc = at.sample(best + spacing) - (level + rise);
  return static_cast<float>(best) + static_cast<float>(spacing) * gaussian_offset(a, b, cc);
}

}  // namespace

void refine_columns(const RefineColumns& columns, int n, float* rows) {
  for (int j = 0; j < n; ++j)
    rows[j] = refine_column(Column{columns, static_cast<std::size_t>(j)});
}

}  // namespace reference
}  // namespace laserline::pipeline::kernels
#endif  // HWY_ONCE
