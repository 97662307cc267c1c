// What the front end's two files (frontend.cpp: the pass down the rows; frontend_refine.cpp: the
// sub-pixel refinement) share: how their kernels are compiled, the fixed-point scale, and small
// inline helpers. Private to them.
#pragma once

#include <cstdint>

#include "pipeline/frontend.hpp"
#include "pipeline/image_view.hpp"

// The dense kernels are compiled twice on x86-64, for the baseline and for AVX2, and the loader
// picks the one the CPU runs (GCC function multi-versioning): twice the lanes per instruction where
// the machine has them, and the same binary still runs everywhere.
// Not under ThreadSanitizer: the loader runs the version resolvers before its runtime is up.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_THREAD__)
#define LASERLINE_DENSE_KERNEL __attribute__((target_clones("avx2", "default")))
#else
#define LASERLINE_DENSE_KERNEL
#endif
// Row kernels and the helpers of a dense kernel are inlined into it, so that they are compiled
// for the target of each of its versions.
#define LASERLINE_ROW_KERNEL __attribute__((always_inline)) inline
#define LASERLINE_ROW_LAMBDA __attribute__((always_inline))
// Where auto-vectorisation falls short, a kernel is written in AVX2 intrinsics, in functions
// compiled for AVX2 and chosen at run time (the CPU is asked once, in the constructor).
#if LASERLINE_AVX2_KERNELS
#include <immintrin.h>
#endif

namespace laserline::pipeline::frontend_detail {

constexpr double kSigmaPerFwhm = 1.0 / 2.3548200450309493;  // a Gaussian's sigma per FWHM
// Interpolation is done in fixed point, 1/128 grey level (see the row kernels).
constexpr int kFixedOne = 128;
constexpr int kFixedBits = 7;
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
