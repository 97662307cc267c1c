#pragma once
// What hal::PixelConverter must produce, written the straightforward way, pixel by pixel in
// double (tests only): the colours of each pixel by the textbook definition of its layout, then
// the laser channel's weighted sum, or 255 where a positively weighted colour is clipped (at the
// top of the sample range; RGB, BGR and Bayer, not YUYV). Shared by the kernels' unit test and the
// camera backends' end-to-end tests, which apply it to the frames their stand-in cameras send.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "hal/laser_channel.hpp"
#include "hal/pixel_conversion.hpp"

namespace laserline::test {

// Sample i of a row: a byte, or a little-endian 16-bit word.
inline int reference_sample(const std::uint8_t* row, int i, int bits) {
  if (bits <= 8) return row[i];
  return row[2 * i] | (row[2 * i + 1] << 8);
}

// "RGGB" etc.: the colours of the mosaic's top-left 2x2 cell, row by row.
inline const char* reference_mosaic(hal::PixelLayout layout) {
  switch (layout) {
    case hal::PixelLayout::kBayerRggb:
      return "RGGB";
    case hal::PixelLayout::kBayerGrbg:
      return "GRBG";
    case hal::PixelLayout::kBayerGbrg:
      return "GBRG";
    case hal::PixelLayout::kBayerBggr:
      return "BGGR";
    default:
      return nullptr;
  }
}

// A pixel's exact output value before rounding and clipping. `thirds`: it takes a mean over three
// neighbours (a mosaic's edge), or a YUV matrix, which float arithmetic cannot hold exactly.
// `clipped`: a positively weighted colour is at the top of the sample range, so `value` is 255
// and `weighted` the sum it replaces (otherwise the two are equal).
struct ReferenceValue {
  double value = 0;
  bool thirds = false;
  bool clipped = false;
  double weighted = 0;
};

// Every pixel's, row-major.
inline std::vector<ReferenceValue> reference_values(const std::uint8_t* src, std::size_t stride,
                                                    int width, int height,
                                                    const hal::SourceFormat& format,
                                                    const hal::LaserChannel& channel) {
  std::vector<ReferenceValue> out(static_cast<std::size_t>(width) *
                                  static_cast<std::size_t>(height));
  const double unit = std::ldexp(1.0, format.bits - 8);            // one 8-bit step in sample units
  const int top = format.bits > 8 ? (1 << format.bits) - 1 : 255;  // the sample range's top
  const double weights[3] = {channel.red, channel.green, channel.blue};
  auto row = [&](int y) { return src + static_cast<std::size_t>(y) * stride; };
  const char* mosaic = reference_mosaic(format.layout);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      double rgb[3] = {0, 0, 0};
      // Per colour: at the top of the sample range (a sample at or above it; a mean when every
      // sample in it is).
      bool top_of_range[3] = {false, false, false};
      double value = 0;
      bool thirds = format.layout == hal::PixelLayout::kYuyv;
      if (format.layout == hal::PixelLayout::kMono) {
        // The top 8 significant bits, cut.
        value = std::floor(reference_sample(row(y), x, format.bits) / unit);
      } else if (format.layout == hal::PixelLayout::kRgb ||
                 format.layout == hal::PixelLayout::kBgr) {
        const bool bgr = format.layout == hal::PixelLayout::kBgr;
        rgb[0] = row(y)[3 * x + (bgr ? 2 : 0)];
        rgb[1] = row(y)[3 * x + 1];
        rgb[2] = row(y)[3 * x + (bgr ? 0 : 2)];
        for (int c = 0; c < 3; ++c)
          top_of_range[c] = rgb[c] >= top;
      } else if (format.layout == hal::PixelLayout::kYuyv) {
        // Pixel x: its own luma, its pair's chroma. Y' in 0..1, Pb and Pr in -0.5..0.5.
        const bool full = format.yuv_range == hal::YuvRange::kFull;
        const bool bt709 = format.yuv_matrix == hal::YuvMatrix::kBt709;
        const double kr = bt709 ? 0.2126 : 0.299, kb = bt709 ? 0.0722 : 0.114;
        const double luma = full ? row(y)[2 * x] / 255.0 : (row(y)[2 * x] - 16.0) / 219.0;
        const int pair = 4 * (x / 2);
        const double chroma_scale = full ? 255.0 : 224.0;
        const double pb = (row(y)[pair + 1] - 128.0) / chroma_scale;
        const double pr = (row(y)[pair + 3] - 128.0) / chroma_scale;
        const double r = luma + 2.0 * (1.0 - kr) * pr;
        const double b = luma + 2.0 * (1.0 - kb) * pb;
        const double g = (luma - kr * r - kb * b) / (1.0 - kr - kb);
        rgb[0] = 255.0 * r;
        rgb[1] = 255.0 * g;
        rgb[2] = 255.0 * b;
      } else {
        auto colour = [&](int cx, int cy) {
          const char c = mosaic[2 * (cy % 2) + (cx % 2)];
          return c == 'R' ? 0 : c == 'G' ? 1 : 2;
        };
        const int own = colour(x, y);
        double sum[3] = {0, 0, 0};
        int count[3] = {0, 0, 0};
        int at_top[3] = {0, 0, 0};
        for (int ny = y - 1; ny <= y + 1; ++ny) {
          for (int nx = x - 1; nx <= x + 1; ++nx) {
            if (nx < 0 || ny < 0 || nx >= width || ny >= height || (nx == x && ny == y)) continue;
            const int s = reference_sample(row(ny), nx, format.bits);
            sum[colour(nx, ny)] += s;
            ++count[colour(nx, ny)];
            at_top[colour(nx, ny)] += s >= top ? 1 : 0;
          }
        }
        for (int c = 0; c < 3; ++c) {
          const int own_sample = reference_sample(row(y), x, format.bits);
          rgb[c] = (c == own ? own_sample : sum[c] / count[c]) / unit;
          thirds = thirds || (c != own && count[c] == 3);
          top_of_range[c] = c == own ? own_sample >= top : at_top[c] == count[c];
        }
      }
      if (format.layout != hal::PixelLayout::kMono) {
        value = weights[0] * rgb[0] + weights[1] * rgb[1] + weights[2] * rgb[2];
      }
      bool clipped = false;
      for (int c = 0; c < 3; ++c)
        clipped = clipped || (weights[c] > 0 && top_of_range[c]);
      out[static_cast<std::size_t>(y) * static_cast<std::size_t>(width) +
          static_cast<std::size_t>(x)] = {clipped ? 255.0 : value, thirds && !clipped, clipped,
                                          value};
    }
  }
  return out;
}

// True when every weight is a multiple of 1/16 with a small numerator (red, 1.5*red - 0.25*green,
// red - (green + blue) / 2): the kernels' float sums of such weights times integer samples and
// halves or quarters of them are exact, so their halves must round up.
inline bool dyadic_weights(const hal::LaserChannel& channel) {
  for (const double w : {channel.red, channel.green, channel.blue}) {
    if (w * 16 != std::round(w * 16) || std::abs(w) > 4) return false;
  }
  return true;
}

// "" when every pixel of `got` (width x height, packed) is its reference value rounded half up
// and clipped to 0..255; otherwise the first pixel that is not. Only values the kernels cannot
// compute exactly in float (weights that are not dyadic_weights(), means over three, YUV) may be
// off by one, and only within 1e-3 of a rounding tie.
inline std::string compare_with_reference(const std::vector<std::uint8_t>& got,
                                          const std::vector<ReferenceValue>& reference, int width,
                                          const hal::LaserChannel& channel) {
  const bool dyadic = dyadic_weights(channel);
  for (std::size_t i = 0; i < reference.size(); ++i) {
    const double v = reference[i].value;
    const double expected = std::min(255.0, std::max(0.0, std::floor(v + 0.5)));
    const bool near_tie = std::abs(v - std::floor(v) - 0.5) < 1e-3;
    const bool exact = dyadic && !reference[i].thirds;
    const double off = std::abs(got[i] - expected);
    if (off == 0 || (off == 1 && near_tie && !exact)) continue;
    return "pixel (" + std::to_string(static_cast<int>(i) % width) + ", " +
           std::to_string(static_cast<int>(i) / width) + "): got " + std::to_string(got[i]) +
           ", expected " + std::to_string(static_cast<int>(expected)) + " (" + std::to_string(v) +
           ")";
  }
  return "";
}

}  // namespace laserline::test
