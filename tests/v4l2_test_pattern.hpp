#pragma once

#include <linux/videodev2.h>

#include <cstdint>

namespace laserline::test {

// The luma of pixel (x, y) in frame `sequence` of the V4L2 stand-in device: every frame differs,
// so a test can tell which frame it got and that all of it arrived.
inline std::uint8_t pattern_value(std::uint32_t x, std::uint32_t y, std::uint32_t sequence) {
  return static_cast<std::uint8_t>((x + 2 * y + 3 * sequence) & 0xff);
}

// Writes frame `sequence` in `fourcc` (GREY, Y16 little-endian with the luma in the top byte,
// or YUYV with neutral chroma), rows packed.
inline void fill_pattern(std::uint32_t fourcc, std::uint32_t width, std::uint32_t height,
                         std::uint32_t sequence, std::uint8_t* out) {
  for (std::uint32_t y = 0; y < height; ++y) {
    for (std::uint32_t x = 0; x < width; ++x) {
      const std::uint8_t v = pattern_value(x, y, sequence);
      if (fourcc == V4L2_PIX_FMT_GREY) {
        *out++ = v;
      } else if (fourcc == V4L2_PIX_FMT_Y16) {
        *out++ = static_cast<std::uint8_t>(x);  // low byte: noise the top byte must not see
        *out++ = v;
      } else {  // YUYV: Y0 U Y1 V
        *out++ = v;
        *out++ = 128;
      }
    }
  }
}

}  // namespace laserline::test
