// Camera pixel formats into the detectors' mono8: mono 8/16-bit, RGB/BGR, YUYV and Bayer mosaics.
// Which kernel converts a format and with what coefficients; the frame kernels themselves are in
// pixel_kernels.cpp.
#include "hal/pixel_conversion.hpp"

#include <cstring>
#include <stdexcept>

#include "hal/pixel_kernels.hpp"

namespace laserline::hal {

namespace {

// `tap` in whole quarters, 0..64, into `quarters`; false when it is not that.
bool whole_quarters(float tap, std::uint16_t& quarters) {
  const float q = tap * 4.0f;
  if (!(q >= 0.0f && q <= 64.0f) || q != static_cast<float>(static_cast<int>(q))) return false;
  quarters = static_cast<std::uint16_t>(q);
  return true;
}

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
  // The clipping rule changes a pixel only where a clipped colour's weighted sum can stay below
  // 255: a positive weight below 1, or a positive and a negative weight. Elsewhere (single colours,
  // red + green) it is left out, which keeps the quarters' exact integer path.
  const float weights[3] = {channel.red, channel.green, channel.blue};
  bool positive = false, negative = false, below_one = false;
  for (const float weight : weights) {
    positive = positive || weight > 0.0f;
    negative = negative || weight < 0.0f;
    below_one = below_one || (weight > 0.0f && weight < 1.0f);
  }
  const bool colour = format.layout != PixelLayout::kMono && format.layout != PixelLayout::kYuyv;
  clips_ = colour && (below_one || (positive && negative));
  if (!clips_) return;
  quarters_exact_ = false;
  auto mask = [&](Colour c) { return static_cast<std::uint16_t>(weights[c] > 0.0f ? 0xffff : 0); };
  if (format.layout == PixelLayout::kRgb || format.layout == PixelLayout::kBgr) {
    const bool bgr = format.layout == PixelLayout::kBgr;
    const Colour order[3] = {bgr ? kBlue : kRed, kGreen, bgr ? kRed : kBlue};
    for (int i = 0; i < 3; ++i)
      sample_clip_[i] = static_cast<std::uint8_t>(mask(order[i]));
    return;
  }
  // Bayer: a green site's horizontal and vertical neighbours are red and blue, one each, its
  // diagonal ones green; a red or blue site's horizontal and vertical ones are all green, its
  // diagonal ones the other of red and blue.
  for (int py = 0; py < 2; ++py) {
    for (int px = 0; px < 2; ++px) {
      const Colour own = bayer_colour(format.layout, px, py);
      ClipLevels& c = clip_[py][px];
      c.top = static_cast<std::uint16_t>(format.bits > 8 ? (1 << format.bits) - 1 : 255);
      c.own = mask(own);
      if (own == kGreen) {
        c.horizontal = mask(bayer_colour(format.layout, px ^ 1, py));
        c.vertical = mask(bayer_colour(format.layout, px, py ^ 1));
      } else {
        c.both = mask(kGreen);
        c.diagonal = mask(bayer_colour(format.layout, px ^ 1, py ^ 1));
      }
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
        pixel_kernels::mono16_frame(src, src_stride, width_, height_, shift_, dst, dst_stride);
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
        pixel_kernels::pick_frame(src, src_stride, width_, height_, pick_, dst, dst_stride);
      } else {
        pixel_kernels::triple_frame(src, src_stride, width_, height_, weights_,
                                    clips_ ? sample_clip_ : nullptr, dst, dst_stride);
      }
      break;
    case PixelLayout::kYuyv:
      pixel_kernels::yuyv_frame(src, src_stride, width_, height_, weights_, dst, dst_stride);
      break;
    default:
      if (format_.bits > 8) {
        pixel_kernels::bayer16_frame(src, src_stride, width_, height_, taps_,
                                     clips_ ? &clip_ : nullptr, dst, dst_stride);
      } else {
        pixel_kernels::bayer8_frame(src, src_stride, width_, height_, taps_,
                                    quarters_exact_ ? &quarters_ : nullptr,
                                    clips_ ? &clip_ : nullptr, dst, dst_stride);
      }
      break;
  }
}

}  // namespace laserline::hal
