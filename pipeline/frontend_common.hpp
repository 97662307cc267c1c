// What the front end's files (frontend.cpp: sizes, row normalisation, line choice;
// frontend_roll.cpp: the pass down the rows; frontend_refine.cpp: the sub-pixel refinement)
// share: the fixed-point scale and small inline helpers. Private to them.
#pragma once

#include <cstdint>

#include "pipeline/frontend.hpp"
#include "pipeline/image_view.hpp"
#include "pipeline/kernels/kernels.hpp"

// The stages of the pass down the rows are inlined into it (one loop nest the compiler sees
// whole); the vector kernels they call are in pipeline/kernels/.
#define LASERLINE_ROW_KERNEL __attribute__((always_inline)) inline
#define LASERLINE_ROW_LAMBDA __attribute__((always_inline))

namespace laserline::pipeline::frontend_detail {

constexpr double kSigmaPerFwhm = 1.0 / 2.3548200450309493;  // a Gaussian's sigma per FWHM
// Interpolation is done in fixed point, 1/128 grey level (see the row kernels).
using kernels::kFixedBits;
using kernels::kFixedOne;
// Row kernels run over blocks of this many pixels with a constant trip count: what GCC needs to
// vectorise them. Float rows are padded to a multiple of it.
constexpr int kBlock = 16;

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

}  // namespace laserline::pipeline::frontend_detail
