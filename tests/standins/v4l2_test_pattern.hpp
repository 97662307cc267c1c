#pragma once

#include <linux/videodev2.h>

#include <cstdint>

namespace laserline::test {

// The luma of pixel (x, y) in frame `sequence` of the V4L2 stand-in device: every frame differs,
// so a test can tell which frame it got and that all of it arrived. It is also the red of the
// colour pattern.
inline std::uint8_t pattern_value(std::uint32_t x, std::uint32_t y, std::uint32_t sequence) {
  return static_cast<std::uint8_t>((x + 2 * y + 3 * sequence) & 0xff);
}

struct PatternColour {
  std::uint8_t red, green, blue;
};

// The colour of pixel (x, y) in frame `sequence`: three ramps of different slopes, so that every
// colour, and every weighted sum of them, differs from pixel to pixel and from frame to frame.
inline PatternColour pattern_colour(std::uint32_t x, std::uint32_t y, std::uint32_t sequence) {
  return {pattern_value(x, y, sequence),
          static_cast<std::uint8_t>((2 * x + y + 5 * sequence + 85) & 0xff),
          static_cast<std::uint8_t>((3 * x + 3 * y + 7 * sequence + 170) & 0xff)};
}

// Bytes per pixel of a packed row.
inline std::uint32_t pattern_bytes_per_pixel(std::uint32_t fourcc) {
  switch (fourcc) {
    case V4L2_PIX_FMT_GREY:
    case V4L2_PIX_FMT_SRGGB8:
    case V4L2_PIX_FMT_SGRBG8:
    case V4L2_PIX_FMT_SGBRG8:
    case V4L2_PIX_FMT_SBGGR8:
      return 1;
    case V4L2_PIX_FMT_RGB24:
    case V4L2_PIX_FMT_BGR24:
      return 3;
    default:
      return 2;
  }
}

// The colours of a mosaic's top-left 2x2 cell, row by row; null for other formats.
inline const char* pattern_mosaic(std::uint32_t fourcc) {
  switch (fourcc) {
    case V4L2_PIX_FMT_SRGGB8:
    case V4L2_PIX_FMT_SRGGB12:
    case V4L2_PIX_FMT_SRGGB16:
      return "RGGB";
    case V4L2_PIX_FMT_SGRBG8:
    case V4L2_PIX_FMT_SGRBG12:
    case V4L2_PIX_FMT_SGRBG16:
      return "GRBG";
    case V4L2_PIX_FMT_SGBRG8:
    case V4L2_PIX_FMT_SGBRG12:
    case V4L2_PIX_FMT_SGBRG16:
      return "GBRG";
    case V4L2_PIX_FMT_SBGGR8:
    case V4L2_PIX_FMT_SBGGR12:
    case V4L2_PIX_FMT_SBGGR16:
      return "BGGR";
    default:
      return nullptr;
  }
}

// Writes a width x height window of frame `sequence` in `fourcc`, whose top-left pixel is (x0, y0)
// of the frame (x0 and y0 even: the whole frame from 0, 0 as the device sends it; a test takes
// small windows to find which frame it got), each row followed by `padding` bytes of 0xEE:
//   GREY        pattern_value()
//   Y16         little-endian, pattern_value() in the top byte, x in the bottom byte (noise the
//               top byte must not see)
//   YUYV        luma pattern_value(), chroma Cb and Cr the green and blue of pattern_colour() at
//               the pair's first pixel
//   RGB24/BGR24 pattern_colour()
//   Bayer       the mosaic site's colour of pattern_colour(); 12 and 16 bits little-endian with
//               the colour in the top 8 of the sample's bits and x below it
inline void fill_pattern(std::uint32_t fourcc, std::uint32_t width, std::uint32_t height,
                         std::uint32_t sequence, std::uint8_t* out, std::uint32_t padding = 0,
                         std::uint32_t x0 = 0, std::uint32_t y0 = 0) {
  const char* mosaic = pattern_mosaic(fourcc);
  const bool twelve = fourcc == V4L2_PIX_FMT_SRGGB12 || fourcc == V4L2_PIX_FMT_SGRBG12 ||
                      fourcc == V4L2_PIX_FMT_SGBRG12 || fourcc == V4L2_PIX_FMT_SBGGR12;
  for (std::uint32_t y = y0; y < y0 + height; ++y) {
    for (std::uint32_t x = x0; x < x0 + width; ++x) {
      const std::uint8_t v = pattern_value(x, y, sequence);
      const PatternColour c = pattern_colour(x, y, sequence);
      if (fourcc == V4L2_PIX_FMT_GREY) {
        *out++ = v;
      } else if (fourcc == V4L2_PIX_FMT_Y16) {
        *out++ = static_cast<std::uint8_t>(x);  // low byte: noise the top byte must not see
        *out++ = v;
      } else if (fourcc == V4L2_PIX_FMT_YUYV) {  // Y0 Cb Y1 Cr
        const PatternColour pair = pattern_colour(x & ~1u, y, sequence);
        *out++ = v;
        *out++ = x % 2 == 0 ? pair.green : pair.blue;
      } else if (fourcc == V4L2_PIX_FMT_RGB24) {
        *out++ = c.red;
        *out++ = c.green;
        *out++ = c.blue;
      } else if (fourcc == V4L2_PIX_FMT_BGR24) {
        *out++ = c.blue;
        *out++ = c.green;
        *out++ = c.red;
      } else {
        const char site = mosaic[2 * (y % 2) + (x % 2)];
        const std::uint8_t s = site == 'R' ? c.red : site == 'G' ? c.green : c.blue;
        if (pattern_bytes_per_pixel(fourcc) == 1) {
          *out++ = s;
        } else {
          const auto word =
              static_cast<std::uint16_t>(twelve ? (s << 4) | (x & 0xf) : (s << 8) | (x & 0xff));
          *out++ = static_cast<std::uint8_t>(word & 0xff);
          *out++ = static_cast<std::uint8_t>(word >> 8);
        }
      }
    }
    for (std::uint32_t i = 0; i < padding; ++i)
      *out++ = 0xEE;
  }
}

}  // namespace laserline::test
