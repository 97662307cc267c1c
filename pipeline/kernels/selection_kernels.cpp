// The line selection's comparison of one line's candidates with the candidates of a line before it
// (pipeline/line_selection.cpp), a candidate per lane: the same arithmetic as the scalar reference
// at the end, in the same order, so the same choices. Compiled once per target (foreach_target.h).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "pipeline/kernels/kernels.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/kernels/selection_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace laserline::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// At most kSelectionLanes candidates at a time (a line rarely has more).
using DF = hn::CappedTag<float, kSelectionLanes>;
using DI = hn::RebindToSigned<DF>;

void BestPriorsOf(const PriorLine& line, int n, float* best, std::int32_t* from,
                  const float* position) {
  const DF df;
  const DI di;
  const auto lanes = static_cast<int>(hn::Lanes(df));
  const auto zero = hn::Zero(df);
  const auto allowed = hn::Set(df, line.allowed);
  const auto jump_cost = hn::Set(df, line.jump_cost);
  for (int i = 0; i < n; i += lanes) {
    const auto at = hn::LoadU(df, position + i);
    auto here = hn::Set(df, -std::numeric_limits<float>::infinity());
    auto prior_at = hn::Zero(di);
    for (int j = 0; j < line.count; ++j) {
      const auto beyond = hn::Sub(hn::Abs(hn::Sub(at, hn::Set(df, line.position[j]))), allowed);
      const auto value =
          hn::Sub(hn::Set(df, line.score[j]),
                  hn::Mul(jump_cost, hn::IfThenElseZero(hn::Gt(beyond, zero), beyond)));
      const auto better = hn::Gt(value, here);
      here = hn::IfThenElse(better, value, here);
      prior_at = hn::IfThenElse(hn::RebindMask(di, better), hn::Set(di, j), prior_at);
    }
    const auto total = hn::Sub(here, hn::Set(df, line.skipped));
    const auto was = hn::LoadU(df, best + i);
    const auto better = hn::Gt(total, was);
    hn::StoreU(hn::IfThenElse(better, total, was), df, best + i);
    const auto from_here = hn::Add(prior_at, hn::Set(di, line.first));
    hn::StoreU(hn::IfThenElse(hn::RebindMask(di, better), from_here, hn::LoadU(di, from + i)), di,
               from + i);
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace laserline::pipeline::kernels
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace laserline::pipeline::kernels {

HWY_EXPORT(BestPriorsOf);

void best_priors(const PriorLine& line, int n, float* best, std::int32_t* from,
                 const float* position) {
  HWY_DYNAMIC_DISPATCH(BestPriorsOf)(line, n, best, from, position);
}

namespace reference {

void best_priors(const PriorLine& line, int n, float* best, std::int32_t* from,
                 const float* position) {
  for (int i = 0; i < n; ++i) {
    // The best prior, then the first prior that gives it.
    auto value = [&](int j) {
      const float jump = std::abs(position[i] - line.position[j]);
      return line.score[j] - line.jump_cost * std::max(0.0f, jump - line.allowed);
    };
    float here = -std::numeric_limits<float>::infinity();
    for (int j = 0; j < line.count; ++j)
      here = std::max(here, value(j));
    if (here - line.skipped > best[i]) {
      best[i] = here - line.skipped;
      for (int j = 0; j < line.count; ++j) {
        if (value(j) == here) {
          from[i] = line.first + j;
          break;
        }
      }
    }
  }
}

}  // namespace reference
}  // namespace laserline::pipeline::kernels
#endif  // HWY_ONCE
