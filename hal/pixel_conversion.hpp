#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "hal/laser_channel.hpp"

namespace laserline::hal {

// How the samples of a camera's buffer are arranged.
enum class PixelLayout : std::uint8_t {
  kMono,  // one sample per pixel
  kRgb,   // three samples per pixel: red, green, blue
  kBgr,   // blue, green, red
  kYuyv,  // 4:2:2 YCbCr: Y0 Cb Y1 Cr for each pair of pixels (V4L2 YUYV)
  // A colour filter mosaic, named by its top-left 2x2 cell read row by row (BayerRG8 = RGGB).
  kBayerRggb,
  kBayerGrbg,
  kBayerGbrg,
  kBayerBggr,
};

// The YCbCr encoding of YUYV: its luma weights and whether codes span 16..235/240 or 0..255.
enum class YuvMatrix : std::uint8_t { kBt601, kBt709 };
enum class YuvRange : std::uint8_t { kLimited, kFull };

// A camera buffer's pixel format.
struct SourceFormat {
  PixelLayout layout = PixelLayout::kMono;
  // Significant bits per sample. 8: one byte per sample. 9..16: two bytes per sample,
  // little-endian, right-aligned (Mono12 and V4L2 SRGGB12: 12; Mono16 and V4L2 Y16: 16), of which
  // the top 8 reach the frame. RGB, BGR and YUYV: 8 only.
  int bits = 8;
  YuvMatrix yuv_matrix = YuvMatrix::kBt601;  // kYuyv only
  YuvRange yuv_range = YuvRange::kLimited;   // kYuyv only

  int bytes_per_pixel() const;  // in a packed row
};

// Empty when `format` frames of width x height can be converted; otherwise why not, one line.
std::string conversion_problem(const SourceFormat& format, int width, int height);

// A camera backend's table of the pixel formats it takes (entries with a `name` and a `source`
// SourceFormat): their names, and why `name` cannot give width x height frames (empty if it can).
template <typename Entry, std::size_t N>
std::vector<std::string> pixel_format_names(const Entry (&table)[N]) {
  std::vector<std::string> names;
  for (const Entry& entry : table)
    names.emplace_back(entry.name);
  return names;
}
template <typename Entry, std::size_t N>
std::string pixel_format_problem(const Entry (&table)[N], const std::string& name, int width,
                                 int height) {
  for (const Entry& entry : table) {
    if (name == entry.name) return conversion_problem(entry.source, width, height);
  }
  return "not a format this backend takes";
}

// Turns a camera buffer into the mono8 frame the pipeline takes: the laser's channel of colour
// frames, mono frames as they are (whatever the channel). Colour frames give
//   clip(round(red_weight * R + green_weight * G + blue_weight * B), 0, 255),
// rounding halves up, where R, G, B are in 8-bit units (16-bit samples scaled down by
// 2^(bits - 8)) and not clipped themselves. Per layout:
//   mono     the sample (16-bit: its top 8 significant bits, cut, not rounded, and clipped to 255)
//   RGB/BGR  the pixel's own three samples
//   YUYV     R, G, B of the pixel's luma and its pair's chroma (not interpolated), by the
//            encoding's matrix and range
//   Bayer    no full demosaic: the pixel's own sample for its own colour and, for each other
//            colour, the mean of its neighbours of that colour among the 8 around it (those in
//            the frame). A single colour (red, green, blue) is thus that colour's sites kept and
//            the other pixels filled bilinearly from the nearest sites of that colour only; a
//            weighted sum costs the same (one pass, four products per pixel).
// Clipped colours: a pixel whose value of a positively weighted colour is at the top of the
// sample range (255; 16-bit samples: the top code of their bits, 4095 for 12 bit, or above)
// gives 255, whatever the other colours say. The detectors take a run of 255 for a clipped laser
// core and centre it from its flanks; without the rule, red - (green + blue) / 2 on a red line
// that clips the red channel gives a flat top of 255 - (G + B) / 2 that follows the texture
// under it. A colour's value is the one above: RGB/BGR the pixel's own sample; Bayer the own
// sample for the own colour, else the mean of the neighbours of that colour, at the top when
// every one of them is (a pixel between clipped red sites is clipped in red too, so a clipped
// line gives 255 all along a mosaic, not every other pixel). Unchanged by the rule: mono frames
// (a clipped sample is 255 already), single colours and sums whose positive weights are all 1 or
// more (the sum reaches 255 by itself), and YUYV, whose R, G, B come from luma and chroma that a
// pair of pixels shares and do not say whether the sensor clipped a colour. Sums with a positive
// weight below 1 do change: grey gives 255 where any colour is clipped.
// Thread context: constructed on the setup thread; convert() from any one thread at a time. It
// allocates nothing, takes no lock and throws nothing: cameras call it in grab().
class PixelConverter {
 public:
  PixelConverter() = default;  // 0x0 mono8
  // Throws std::invalid_argument with conversion_problem() when that is not empty.
  PixelConverter(const SourceFormat& format, int width, int height, const LaserChannel& channel);

  const SourceFormat& format() const { return format_; }
  int width() const { return width_; }
  int height() const { return height_; }
  // Bytes of one packed source row (a buffer's rows may be longer: src_stride).
  std::size_t row_bytes() const;

  // `src`: height rows of src_stride bytes each; `dst`: height rows of dst_stride bytes, width of
  // them written.
  void convert(const std::uint8_t* src, std::size_t src_stride, std::uint8_t* dst,
               std::size_t dst_stride) const noexcept;

  // Per-pixel coefficients of a Bayer pixel: of its own sample, of the sum of its left and right
  // neighbours, of its upper and lower, and of its four diagonal neighbours.
  struct Taps {
    float own = 0, horizontal = 0, vertical = 0, diagonal = 0;
  };
  // The same in quarters, for 8-bit mosaics whose inner taps are whole quarters.
  struct QuarterTaps {
    std::uint16_t own = 0, horizontal = 0, vertical = 0, diagonal = 0;
  };
  // A Bayer pixel is clipped (gives 255) when its own sample, or the least of its horizontal,
  // vertical, horizontal and vertical, or diagonal neighbours, is at least `top` under its mask:
  // 0xffff where that is a positively weighted colour, else 0.
  struct ClipLevels {
    std::uint16_t top = 0xffff;
    std::uint16_t own = 0, horizontal = 0, vertical = 0, both = 0, diagonal = 0;
  };

 private:
  SourceFormat format_;
  int width_ = 0;
  int height_ = 0;
  // Mono: the right shift of 16-bit samples. RGB/BGR: weights of a pixel's samples in the order
  // they lie in memory (scaled to output units). YUYV: weights of Y, Cb, Cr and a constant.
  int shift_ = 0;
  float weights_[4] = {0, 0, 0, 0};
  // Bayer: by [row: 0 first, 1 inner, 2 last][column: likewise][y % 2][x % 2]. Pixels on the
  // frame's edges read the missing neighbours from the other side (same colour) with taps scaled
  // so that only the neighbours in the frame count.
  Taps taps_[3][3][2][2] = {};
  // Inner pixels' taps in quarters ([y % 2][x % 2]) when they all are (quarters_exact_): a single
  // colour's are (1, 1/2, 1/4), computed exactly in 16-bit integers.
  QuarterTaps quarters_[2][2] = {};
  bool quarters_exact_ = true;
  int pick_ = -1;  // RGB/BGR of a single colour: its sample's place in a pixel
  // Whether the clipping rule can change a pixel (see above), and its levels: RGB/BGR per sample
  // in memory order, Bayer by [y % 2][x % 2] (a pixel's neighbours have the same colours on the
  // frame's edges, read from the other side).
  bool clips_ = false;
  std::uint8_t sample_clip_[3] = {0, 0, 0};  // masks, as in ClipLevels
  ClipLevels clip_[2][2] = {};
};

}  // namespace laserline::hal
