#pragma once

// The frame kernels of PixelConverter::convert() (pixel_conversion.hpp), apart from the choice of
// kernel and its coefficients: each converts a whole frame into mono8 with its row loops inlined,
// compiled for the baseline and for AVX2 where GCC's function multi-versioning is available.
// None allocates, locks or throws.

#include <cstddef>
#include <cstdint>

#include "hal/pixel_conversion.hpp"

namespace laserline::hal::pixel_kernels {

using BayerTaps = PixelConverter::Taps[3][3][2][2];
using InnerQuarterTaps = PixelConverter::QuarterTaps[2][2];
using BayerClipLevels = PixelConverter::ClipLevels[2][2];

// `clip`: the clipping rule's levels, or null where it changes nothing.
void bayer8_frame(const std::uint8_t* src, std::size_t src_stride, int width, int height,
                  const BayerTaps& taps, const InnerQuarterTaps* quarters,
                  const BayerClipLevels* clip, std::uint8_t* dst, std::size_t dst_stride);
void bayer16_frame(const std::uint8_t* src, std::size_t src_stride, int width, int height,
                   const BayerTaps& taps, const BayerClipLevels* clip, std::uint8_t* dst,
                   std::size_t dst_stride);
// RGB or BGR, one colour: the sample at `offset` of each pixel.
void pick_frame(const std::uint8_t* src, std::size_t src_stride, int width, int height, int offset,
                std::uint8_t* dst, std::size_t dst_stride);
// RGB or BGR: w = the weights of a pixel's three samples in memory order; `clip` their clipping
// levels, or null where the rule changes nothing.
void triple_frame(const std::uint8_t* src, std::size_t src_stride, int width, int height,
                  const float* w, const std::uint8_t* clip, std::uint8_t* dst,
                  std::size_t dst_stride);
// w = the weights of Y, Cb, Cr and a constant.
void yuyv_frame(const std::uint8_t* src, std::size_t src_stride, int width, int height,
                const float* w, std::uint8_t* dst, std::size_t dst_stride);
void mono16_frame(const std::uint8_t* src, std::size_t src_stride, int width, int height, int shift,
                  std::uint8_t* dst, std::size_t dst_stride);

}  // namespace laserline::hal::pixel_kernels
