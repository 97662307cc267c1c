#include "hal/pixel_conversion.hpp"

#include <bit>
#include <cstring>
#include <stdexcept>

// The frame kernels are compiled for the baseline and for AVX2, and the loader picks the one the
// CPU runs (GCC function multi-versioning), as in pipeline/frontend.cpp. Not under
// ThreadSanitizer: the loader runs the version resolvers before its runtime is up.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_THREAD__)
#define LASERLINE_PIXEL_KERNEL __attribute__((target_clones("avx2", "default")))
#else
#define LASERLINE_PIXEL_KERNEL
#endif
// Row loops and helpers are inlined into the frame kernel, so that each version has its own.
#define LASERLINE_PIXEL_ROW __attribute__((always_inline)) inline

namespace laserline::hal {

namespace {

// `tap` in whole quarters, 0..64, into `quarters`; false when it is not that.
bool whole_quarters(float tap, std::uint16_t& quarters) {
  const float q = tap * 4.0f;
  if (!(q >= 0.0f && q <= 64.0f) || q != static_cast<float>(static_cast<int>(q))) return false;
  quarters = static_cast<std::uint16_t>(q);
  return true;
}

static_assert(std::endian::native == std::endian::little,
              "16-bit samples are read as native little-endian words");

enum Colour : int { kRed = 0, kGreen = 1, kBlue = 2 };

bool is_bayer(PixelLayout layout) {
  return layout == PixelLayout::kBayerRggb || layout == PixelLayout::kBayerGrbg ||
         layout == PixelLayout::kBayerGbrg || layout == PixelLayout::kBayerBggr;
}

// The colour of the mosaic's site at (x % 2, y % 2).
Colour bayer_colour(PixelLayout layout, int x_parity, int y_parity) {
  static constexpr Colour kCells[4][4] = {
      {kRed, kGreen, kGreen, kBlue},  // RGGB
      {kGreen, kRed, kBlue, kGreen},  // GRBG
      {kGreen, kBlue, kRed, kGreen},  // GBRG
      {kBlue, kGreen, kGreen, kRed},  // BGGR
  };
  const int pattern = static_cast<int>(layout) - static_cast<int>(PixelLayout::kBayerRggb);
  return kCells[pattern][2 * y_parity + x_parity];
}

// Rounds half up and clips to 0..255 (the value is finite).
LASERLINE_PIXEL_ROW std::uint8_t to_byte(float value) {
  float v = value + 0.5f;
  v = v < 0.0f ? 0.0f : v;
  v = v > 255.0f ? 255.0f : v;
  return static_cast<std::uint8_t>(static_cast<int>(v));
}

// Sample x of a row of 1- or 2-byte samples (2: a little-endian word, read without assuming the
// row's type).
template <int kBytes>
LASERLINE_PIXEL_ROW int sample(const std::uint8_t* row, int x) {
  if constexpr (kBytes == 1) {
    return row[x];
  } else {
    std::uint16_t word;
    std::memcpy(&word, row + 2 * x, 2);
    return word;
  }
}

template <int kBytes>
LASERLINE_PIXEL_ROW float bayer_pixel(const std::uint8_t* up, const std::uint8_t* mid,
                                      const std::uint8_t* down, int x, int left, int right,
                                      const PixelConverter::Taps& t) {
  const int own = sample<kBytes>(mid, x);
  const int horizontal = sample<kBytes>(mid, left) + sample<kBytes>(mid, right);
  const int vertical = sample<kBytes>(up, x) + sample<kBytes>(down, x);
  const int diagonal = sample<kBytes>(up, left) + sample<kBytes>(up, right) +
                       sample<kBytes>(down, left) + sample<kBytes>(down, right);
  return t.own * static_cast<float>(own) + t.horizontal * static_cast<float>(horizontal) +
         t.vertical * static_cast<float>(vertical) + t.diagonal * static_cast<float>(diagonal);
}

// Pixels 1 .. 2 * pairs of a row away from the frame's left and right edges, two at a time so
// that the taps alternate without a branch (GCC vectorises the pair as one group).
template <int kBytes>
LASERLINE_PIXEL_ROW void bayer_pairs(const std::uint8_t* __restrict up,
                                     const std::uint8_t* __restrict mid,
                                     const std::uint8_t* __restrict down, int pairs,
                                     PixelConverter::Taps odd, PixelConverter::Taps even,
                                     std::uint8_t* __restrict out) {
  for (int i = 0; i < pairs; ++i) {
    const int x = 2 * i + 1;
    out[x] = to_byte(bayer_pixel<kBytes>(up, mid, down, x, x - 1, x + 1, odd));
    out[x + 1] = to_byte(bayer_pixel<kBytes>(up, mid, down, x + 1, x, x + 2, even));
  }
}

// The same in 16-bit integers where the taps are whole quarters (a single colour, inside the
// frame): exact, and measured 2.7 times as fast as the float version at 2048x1536 (twice the
// lanes, no conversions).
LASERLINE_PIXEL_ROW std::uint8_t quarter_pixel(const std::uint8_t* up, const std::uint8_t* mid,
                                               const std::uint8_t* down, int x,
                                               const PixelConverter::QuarterTaps& t) {
  const auto horizontal = static_cast<std::uint16_t>(mid[x - 1] + mid[x + 1]);
  const auto vertical = static_cast<std::uint16_t>(up[x] + down[x]);
  const auto diagonal =
      static_cast<std::uint16_t>(up[x - 1] + up[x + 1] + down[x - 1] + down[x + 1]);
  const auto sum = static_cast<std::uint16_t>(t.own * mid[x] + t.horizontal * horizontal +
                                              t.vertical * vertical + t.diagonal * diagonal + 2);
  const auto value = static_cast<std::uint16_t>(sum >> 2);
  return static_cast<std::uint8_t>(value < 255 ? value : 255);
}

LASERLINE_PIXEL_ROW void quarter_pairs(const std::uint8_t* __restrict up,
                                       const std::uint8_t* __restrict mid,
                                       const std::uint8_t* __restrict down, int pairs,
                                       PixelConverter::QuarterTaps odd,
                                       PixelConverter::QuarterTaps even,
                                       std::uint8_t* __restrict out) {
  for (int i = 0; i < pairs; ++i) {
    const int x = 2 * i + 1;
    out[x] = quarter_pixel(up, mid, down, x, odd);
    out[x + 1] = quarter_pixel(up, mid, down, x + 1, even);
  }
}

using BayerTaps = PixelConverter::Taps[3][3][2][2];
using InnerQuarterTaps = PixelConverter::QuarterTaps[2][2];

// `quarters`: the inner taps in quarters, or null where they are not whole quarters.
template <int kBytes>
LASERLINE_PIXEL_ROW void bayer_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                     int height, const BayerTaps& taps,
                                     const InnerQuarterTaps* quarters, std::uint8_t* dst,
                                     std::size_t dst_stride) {
  const int pairs = (width - 2) / 2;
  const int last = width - 1;
  for (int y = 0; y < height; ++y) {
    // Missing rows and columns are read from the other side, which has the same colours.
    const int kind = y == 0 ? 0 : y == height - 1 ? 2 : 1;
    const std::uint8_t* up = src + static_cast<std::size_t>(y == 0 ? 1 : y - 1) * src_stride;
    const std::uint8_t* mid = src + static_cast<std::size_t>(y) * src_stride;
    const std::uint8_t* down =
        src + static_cast<std::size_t>(y == height - 1 ? height - 2 : y + 1) * src_stride;
    const auto& t = taps[kind];
    const int p = y & 1;
    std::uint8_t* out = dst + static_cast<std::size_t>(y) * dst_stride;
    out[0] = to_byte(bayer_pixel<kBytes>(up, mid, down, 0, 1, 1, t[0][p][0]));
    if (kind == 1 && quarters != nullptr) {
      quarter_pairs(up, mid, down, pairs, (*quarters)[p][1], (*quarters)[p][0], out);
    } else {
      bayer_pairs<kBytes>(up, mid, down, pairs, t[1][p][1], t[1][p][0], out);
    }
    for (int x = 2 * pairs + 1; x < last; ++x)  // one pixel when the width is odd
      out[x] = to_byte(bayer_pixel<kBytes>(up, mid, down, x, x - 1, x + 1, t[1][p][x & 1]));
    out[last] =
        to_byte(bayer_pixel<kBytes>(up, mid, down, last, last - 1, last - 1, t[2][p][last & 1]));
  }
}

LASERLINE_PIXEL_KERNEL void bayer8_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                         int height, const BayerTaps& taps,
                                         const InnerQuarterTaps* quarters, std::uint8_t* dst,
                                         std::size_t dst_stride) {
  bayer_frame<1>(src, src_stride, width, height, taps, quarters, dst, dst_stride);
}

LASERLINE_PIXEL_KERNEL void bayer16_frame(const std::uint8_t* src, std::size_t src_stride,
                                          int width, int height, const BayerTaps& taps,
                                          std::uint8_t* dst, std::size_t dst_stride) {
  bayer_frame<2>(src, src_stride, width, height, taps, nullptr, dst, dst_stride);
}

LASERLINE_PIXEL_ROW void triple_row(const std::uint8_t* __restrict in, int width, float w0,
                                    float w1, float w2, std::uint8_t* __restrict out) {
  for (int x = 0; x < width; ++x) {
    out[x] = to_byte(w0 * static_cast<float>(in[3 * x]) + w1 * static_cast<float>(in[3 * x + 1]) +
                     w2 * static_cast<float>(in[3 * x + 2]));
  }
}

LASERLINE_PIXEL_ROW void pick_row(const std::uint8_t* __restrict in, int width,
                                  std::uint8_t* __restrict out) {
  for (int x = 0; x < width; ++x)
    out[x] = in[3 * x];
}

// RGB or BGR, one colour: the sample at `offset` of each pixel.
LASERLINE_PIXEL_KERNEL void pick_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                       int height, int offset, std::uint8_t* dst,
                                       std::size_t dst_stride) {
  for (int y = 0; y < height; ++y) {
    pick_row(src + static_cast<std::size_t>(y) * src_stride + offset, width,
             dst + static_cast<std::size_t>(y) * dst_stride);
  }
}

// RGB or BGR: w = the weights of a pixel's three samples in memory order.
LASERLINE_PIXEL_KERNEL void triple_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                         int height, const float* w, std::uint8_t* dst,
                                         std::size_t dst_stride) {
  for (int y = 0; y < height; ++y) {
    triple_row(src + static_cast<std::size_t>(y) * src_stride, width, w[0], w[1], w[2],
               dst + static_cast<std::size_t>(y) * dst_stride);
  }
}

LASERLINE_PIXEL_ROW void yuyv_row(const std::uint8_t* __restrict in, int pairs, float wy, float wu,
                                  float wv, float constant, std::uint8_t* __restrict out) {
  for (int i = 0; i < pairs; ++i) {
    const float chroma =
        wu * static_cast<float>(in[4 * i + 1]) + wv * static_cast<float>(in[4 * i + 3]) + constant;
    out[2 * i] = to_byte(wy * static_cast<float>(in[4 * i]) + chroma);
    out[2 * i + 1] = to_byte(wy * static_cast<float>(in[4 * i + 2]) + chroma);
  }
}

// w = the weights of Y, Cb, Cr and a constant.
LASERLINE_PIXEL_KERNEL void yuyv_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                       int height, const float* w, std::uint8_t* dst,
                                       std::size_t dst_stride) {
  for (int y = 0; y < height; ++y) {
    yuyv_row(src + static_cast<std::size_t>(y) * src_stride, width / 2, w[0], w[1], w[2], w[3],
             dst + static_cast<std::size_t>(y) * dst_stride);
  }
}

LASERLINE_PIXEL_ROW void mono16_row(const std::uint8_t* __restrict in, int width, int shift,
                                    std::uint8_t* __restrict out) {
  for (int x = 0; x < width; ++x) {
    const int v = sample<2>(in, x) >> shift;
    out[x] = static_cast<std::uint8_t>(v < 255 ? v : 255);
  }
}

LASERLINE_PIXEL_KERNEL void mono16_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                         int height, int shift, std::uint8_t* dst,
                                         std::size_t dst_stride) {
  for (int y = 0; y < height; ++y) {
    mono16_row(src + static_cast<std::size_t>(y) * src_stride, width, shift,
               dst + static_cast<std::size_t>(y) * dst_stride);
  }
}

}  // namespace

int SourceFormat::bytes_per_pixel() const {
  switch (layout) {
    case PixelLayout::kRgb:
    case PixelLayout::kBgr:
      return 3;
    case PixelLayout::kYuyv:
      return 2;
    default:
      return bits > 8 ? 2 : 1;
  }
}

std::string conversion_problem(const SourceFormat& format, int width, int height) {
  const std::string size = std::to_string(width) + "x" + std::to_string(height);
  if (width < 1 || height < 1) return "no pixels in a " + size + " frame";
  const bool mono_or_bayer = format.layout == PixelLayout::kMono || is_bayer(format.layout);
  if (format.bits != 8 && !(mono_or_bayer && format.bits > 8 && format.bits <= 16)) {
    return std::to_string(format.bits) + "-bit samples are not supported in this layout";
  }
  if (is_bayer(format.layout) && (width < 2 || height < 2)) {
    return "a Bayer mosaic needs at least 2x2 pixels, got " + size;
  }
  if (format.layout == PixelLayout::kYuyv && width % 2 != 0) {
    return "YUYV needs an even width (pixels come in pairs), got " + size;
  }
  return "";
}

PixelConverter::PixelConverter(const SourceFormat& format, int width, int height,
                               const LaserChannel& channel)
    : format_(format), width_(width), height_(height) {
  if (const std::string problem = conversion_problem(format, width, height); !problem.empty()) {
    throw std::invalid_argument(problem);
  }
  // 16-bit samples are scaled to 8-bit units inside the weights (a power of two: exact).
  shift_ = format.bits - 8;
  const float scale = 1.0f / static_cast<float>(1 << shift_);
  const float w[3] = {channel.red * scale, channel.green * scale, channel.blue * scale};
  switch (format.layout) {
    case PixelLayout::kMono:
      break;
    case PixelLayout::kRgb:
      weights_[0] = w[kRed];
      weights_[1] = w[kGreen];
      weights_[2] = w[kBlue];
      break;
    case PixelLayout::kBgr:
      weights_[0] = w[kBlue];
      weights_[1] = w[kGreen];
      weights_[2] = w[kRed];
      break;
    case PixelLayout::kYuyv: {
      // Normalised luma Y' = (Y - y0) / ys and chroma Pb = (Cb - 128) / cs, Pr likewise; then
      // R' = Y' + 2 (1 - Kr) Pr, B' = Y' + 2 (1 - Kb) Pb, G' = (Y' - Kr R' - Kb B') / Kg, and
      // the output is 255 (wr R' + wg G' + wb B'), linear in Y, Cb, Cr.
      const bool bt709 = format.yuv_matrix == YuvMatrix::kBt709;
      const double kr = bt709 ? 0.2126 : 0.299;
      const double kb = bt709 ? 0.0722 : 0.114;
      const double kg = 1.0 - kr - kb;
      const bool full = format.yuv_range == YuvRange::kFull;
      const double y0 = full ? 0.0 : 16.0;
      const double ys = full ? 255.0 : 219.0;
      const double cs = full ? 255.0 : 224.0;
      const double r = channel.red, g = channel.green, b = channel.blue;
      const double per_y = 255.0 * (r + g + b) / ys;
      const double per_pb = 255.0 * (2.0 * (1.0 - kb) * (b - g * kb / kg)) / cs;
      const double per_pr = 255.0 * (2.0 * (1.0 - kr) * (r - g * kr / kg)) / cs;
      weights_[0] = static_cast<float>(per_y);
      weights_[1] = static_cast<float>(per_pb);
      weights_[2] = static_cast<float>(per_pr);
      weights_[3] = static_cast<float>(-per_y * y0 - (per_pb + per_pr) * 128.0);
      break;
    }
    default: {
      // Which neighbours each pixel has depends on its row and column kind (first, inner, last);
      // those on a missing side are read from the other side (same colour), so each category's
      // taps are scaled by (neighbours there in the frame / its slots) and divided by the number
      // of neighbours of that colour in the frame.
      for (int row_kind = 0; row_kind < 3; ++row_kind) {
        for (int column_kind = 0; column_kind < 3; ++column_kind) {
          for (int py = 0; py < 2; ++py) {
            for (int px = 0; px < 2; ++px) {
              const Colour own = bayer_colour(format.layout, px, py);
              struct Category {
                Colour colour = kRed;
                int slots = 0;
                int inside = 0;
              } categories[3];                // horizontal, vertical, diagonal
              int neighbours[3] = {0, 0, 0};  // of each colour, in the frame
              for (int dy = -1; dy <= 1; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                  if (dx == 0 && dy == 0) continue;
                  const bool inside = !(dy < 0 && row_kind == 0) && !(dy > 0 && row_kind == 2) &&
                                      !(dx < 0 && column_kind == 0) &&
                                      !(dx > 0 && column_kind == 2);
                  const Colour colour =
                      bayer_colour(format.layout, (px + dx + 2) & 1, (py + dy + 2) & 1);
                  Category& c = categories[dy == 0 ? 0 : dx == 0 ? 1 : 2];
                  c.colour = colour;
                  ++c.slots;
                  c.inside += inside ? 1 : 0;
                  if (inside && colour != own) ++neighbours[colour];
                }
              }
              float category_taps[3];
              for (int k = 0; k < 3; ++k) {
                const Category& c = categories[k];
                category_taps[k] = c.colour == own || neighbours[c.colour] == 0
                                       ? 0.0f
                                       : w[c.colour] * static_cast<float>(c.inside) /
                                             static_cast<float>(neighbours[c.colour] * c.slots);
              }
              taps_[row_kind][column_kind][py][px] =
                  Taps{w[own], category_taps[0], category_taps[1], category_taps[2]};
              if (row_kind == 1 && column_kind == 1) {
                const Taps& t = taps_[1][1][py][px];
                QuarterTaps& q = quarters_[py][px];
                quarters_exact_ =
                    quarters_exact_ && format.bits == 8 && whole_quarters(t.own, q.own) &&
                    whole_quarters(t.horizontal, q.horizontal) &&
                    whole_quarters(t.vertical, q.vertical) &&
                    whole_quarters(t.diagonal, q.diagonal) &&
                    // the largest sum fits in 16 bits
                    255 * (q.own + 2 * q.horizontal + 2 * q.vertical + 4 * q.diagonal) + 2 <= 65535;
              }
            }
          }
        }
      }
      break;
    }
  }
  if (format.layout == PixelLayout::kRgb || format.layout == PixelLayout::kBgr) {
    for (int i = 0; i < 3; ++i) {
      const bool others_zero = weights_[(i + 1) % 3] == 0.0f && weights_[(i + 2) % 3] == 0.0f;
      if (weights_[i] == 1.0f && others_zero) pick_ = i;
    }
  }
}

std::size_t PixelConverter::row_bytes() const {
  return static_cast<std::size_t>(width_) * static_cast<std::size_t>(format_.bytes_per_pixel());
}

void PixelConverter::convert(const std::uint8_t* src, std::size_t src_stride, std::uint8_t* dst,
                             std::size_t dst_stride) const noexcept {
  switch (format_.layout) {
    case PixelLayout::kMono:
      if (format_.bits > 8) {
        mono16_frame(src, src_stride, width_, height_, shift_, dst, dst_stride);
      } else {
        for (int y = 0; y < height_; ++y) {
          std::memcpy(dst + static_cast<std::size_t>(y) * dst_stride,
                      src + static_cast<std::size_t>(y) * src_stride,
                      static_cast<std::size_t>(width_));
        }
      }
      break;
    case PixelLayout::kRgb:
    case PixelLayout::kBgr:
      if (pick_ >= 0) {
        pick_frame(src, src_stride, width_, height_, pick_, dst, dst_stride);
      } else {
        triple_frame(src, src_stride, width_, height_, weights_, dst, dst_stride);
      }
      break;
    case PixelLayout::kYuyv:
      yuyv_frame(src, src_stride, width_, height_, weights_, dst, dst_stride);
      break;
    default:
      if (format_.bits > 8) {
        bayer16_frame(src, src_stride, width_, height_, taps_, dst, dst_stride);
      } else {
        bayer8_frame(src, src_stride, width_, height_, taps_,
                     quarters_exact_ ? &quarters_ : nullptr, dst, dst_stride);
      }
      break;
  }
}

}  // namespace laserline::hal
