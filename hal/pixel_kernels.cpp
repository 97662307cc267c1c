// The frame kernels (pixel_kernels.hpp). Each format's row helpers are here, in the file of the
// frame kernel compiled per target (target_clones) that inlines them.
#include "hal/pixel_kernels.hpp"

#include <bit>
#include <cstring>
#include <type_traits>

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

namespace laserline::hal::pixel_kernels {

static_assert(std::endian::native == std::endian::little,
              "16-bit samples are read as native little-endian words");

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

// Least and greatest by value (std::min and max return a reference, which here is the address of
// one of two samples: a load GCC does not vectorise).
template <typename T>
LASERLINE_PIXEL_ROW T lo(T a, T b) {
  return a < b ? a : b;
}
template <typename T>
LASERLINE_PIXEL_ROW T hi(T a, T b) {
  return a > b ? a : b;
}

// The clipping rule on a Bayer pixel: whether a positively weighted colour is at the top of the
// sample range. A mean is at the top when its least sample is (samples above the top code count
// as at it). Branch-free, in the samples' own width.
template <int kBytes>
LASERLINE_PIXEL_ROW bool bayer_clipped(const std::uint8_t* up, const std::uint8_t* mid,
                                       const std::uint8_t* down, int x, int left, int right,
                                       const PixelConverter::ClipLevels& c) {
  using S = std::conditional_t<kBytes == 1, std::uint8_t, std::uint16_t>;
  const auto at = [](const std::uint8_t* row, int i) {
    return static_cast<S>(sample<kBytes>(row, i));
  };
  const S own = static_cast<S>(c.own), h = static_cast<S>(c.horizontal);
  const S v = static_cast<S>(c.vertical), both = static_cast<S>(c.both);
  const S d = static_cast<S>(c.diagonal), top = static_cast<S>(c.top);
  const S horizontal = lo(at(mid, left), at(mid, right));
  const S vertical = lo(at(up, x), at(down, x));
  const S diagonal = lo(lo(at(up, left), at(up, right)), lo(at(down, left), at(down, right)));
  const S score = hi(hi(hi<S>(at(mid, x) & own, horizontal & h),
                        hi<S>(vertical & v, lo(horizontal, vertical) & both)),
                     static_cast<S>(diagonal & d));
  return score >= top;
}

// One Bayer pixel. kClip: with the clipping rule, a select rather than a branch (8-bit mosaics
// take the rule in a pass of their own instead, clip_lanes).
template <int kBytes, bool kClip>
LASERLINE_PIXEL_ROW std::uint8_t bayer_pixel(const std::uint8_t* up, const std::uint8_t* mid,
                                             const std::uint8_t* down, int x, int left, int right,
                                             const PixelConverter::Taps& t,
                                             const PixelConverter::ClipLevels& c) {
  const int own = sample<kBytes>(mid, x);
  const int h0 = sample<kBytes>(mid, left), h1 = sample<kBytes>(mid, right);
  const int v0 = sample<kBytes>(up, x), v1 = sample<kBytes>(down, x);
  const int d0 = sample<kBytes>(up, left), d1 = sample<kBytes>(up, right);
  const int d2 = sample<kBytes>(down, left), d3 = sample<kBytes>(down, right);
  const float value = t.own * static_cast<float>(own) + t.horizontal * static_cast<float>(h0 + h1) +
                      t.vertical * static_cast<float>(v0 + v1) +
                      t.diagonal * static_cast<float>(d0 + d1 + d2 + d3);
  if constexpr (kClip) {
    return bayer_clipped<kBytes>(up, mid, down, x, left, right, c) ? std::uint8_t{255}
                                                                   : to_byte(value);
  } else {
    return to_byte(value);
  }
}

// Pixels 1 .. 2 * pairs of a row away from the frame's left and right edges, two at a time so
// that the taps alternate without a branch (GCC vectorises the pair as one group).
template <int kBytes, bool kClip>
LASERLINE_PIXEL_ROW void bayer_pairs(const std::uint8_t* __restrict up,
                                     const std::uint8_t* __restrict mid,
                                     const std::uint8_t* __restrict down, int pairs,
                                     PixelConverter::Taps odd, PixelConverter::Taps even,
                                     PixelConverter::ClipLevels odd_clip,
                                     PixelConverter::ClipLevels even_clip,
                                     std::uint8_t* __restrict out) {
  for (int i = 0; i < pairs; ++i) {
    const int x = 2 * i + 1;
    out[x] = bayer_pixel<kBytes, kClip>(up, mid, down, x, x - 1, x + 1, odd, odd_clip);
    out[x + 1] = bayer_pixel<kBytes, kClip>(up, mid, down, x + 1, x, x + 2, even, even_clip);
  }
}

// The clipping rule over an 8-bit row's pixels 1, 2, ... after bayer_pairs wrote them, 32 at a
// time in GCC's vector extensions. Written as pairs (odd and even pixels' masks alternate),
// GCC's vectoriser interleaves and de-interleaves every sample, and the rule inside bayer_pairs
// runs it out of registers: at 2048x1536 each cost about twice this pass (0.6-0.9 ms against
// 0.3-0.4 ms; 16-bit mosaics, in half the lanes, take the rule better inside bayer_pairs).
// Lane i is pixel 1 + i + a multiple of 32: odd when i is even.
struct ClipLanes {
  static constexpr int kLanes = 32;
  typedef std::uint8_t Vector __attribute__((vector_size(kLanes)));
  typedef std::int8_t Mask __attribute__((vector_size(kLanes)));  // a compare's lanes: 0 or -1
  Vector own, horizontal, vertical, both, diagonal;

  ClipLanes(const PixelConverter::ClipLevels& odd, const PixelConverter::ClipLevels& even) {
    for (int i = 0; i < kLanes; ++i) {
      const PixelConverter::ClipLevels& c = i % 2 == 0 ? odd : even;
      own[i] = static_cast<std::uint8_t>(c.own);
      horizontal[i] = static_cast<std::uint8_t>(c.horizontal);
      vertical[i] = static_cast<std::uint8_t>(c.vertical);
      both[i] = static_cast<std::uint8_t>(c.both);
      diagonal[i] = static_cast<std::uint8_t>(c.diagonal);
    }
  }
};

// In place, by reference: a function that takes or returns a 32-byte vector by value is an ABI
// question in the baseline version (GCC's -Wpsabi), though all of these are inlined.
template <typename Vector>
LASERLINE_PIXEL_ROW void load_lanes(Vector& v, const std::uint8_t* at) {
  std::memcpy(&v, at, sizeof v);
}
template <typename Vector>
LASERLINE_PIXEL_ROW void lower_to(Vector& a, const Vector& b) {
  a = a < b ? a : b;
}
template <typename Vector>
LASERLINE_PIXEL_ROW void raise_to(Vector& a, const Vector& b) {
  a = a > b ? a : b;
}

// Pixels 1 .. up to `end` (exclusive) in whole vectors; returns the first pixel not done.
LASERLINE_PIXEL_ROW int clip_lanes(const std::uint8_t* __restrict up,
                                   const std::uint8_t* __restrict mid,
                                   const std::uint8_t* __restrict down, int end, const ClipLanes& m,
                                   std::uint8_t* __restrict out) {
  using Vector = ClipLanes::Vector;
  const Vector top = Vector{} + 255;
  int x = 1;
  for (; x + ClipLanes::kLanes <= end; x += ClipLanes::kLanes) {
    Vector own, horizontal, vertical, diagonal, other;
    load_lanes(own, mid + x);
    load_lanes(horizontal, mid + x - 1);
    load_lanes(other, mid + x + 1);
    lower_to(horizontal, other);
    load_lanes(vertical, up + x);
    load_lanes(other, down + x);
    lower_to(vertical, other);
    load_lanes(diagonal, up + x - 1);
    load_lanes(other, up + x + 1);
    lower_to(diagonal, other);
    load_lanes(other, down + x - 1);
    lower_to(diagonal, other);
    load_lanes(other, down + x + 1);
    lower_to(diagonal, other);
    // The greatest of the sample and the least of each neighbours under their masks.
    Vector score = own & m.own;
    raise_to(score, Vector(horizontal & m.horizontal));
    raise_to(score, Vector(vertical & m.vertical));
    raise_to(score, Vector(diagonal & m.diagonal));
    lower_to(horizontal, vertical);
    raise_to(score, Vector(horizontal & m.both));
    ClipLanes::Mask pixels;
    load_lanes(pixels, out + x);
    pixels |= score == top;
    std::memcpy(out + x, &pixels, sizeof pixels);
  }
  return x;
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

// `quarters`: the inner taps in quarters, or null where they are not whole quarters (never with
// kClip: the quarters are taken only where the rule changes nothing).
template <int kBytes, bool kClip>
LASERLINE_PIXEL_ROW void bayer_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                     int height, const BayerTaps& taps,
                                     const InnerQuarterTaps* quarters, const BayerClipLevels& clip,
                                     std::uint8_t* dst, std::size_t dst_stride) {
  const int pairs = (width - 2) / 2;
  const int last = width - 1;
  const ClipLanes lanes[2] = {{clip[0][1], clip[0][0]}, {clip[1][1], clip[1][0]}};
  for (int y = 0; y < height; ++y) {
    // Missing rows and columns are read from the other side, which has the same colours.
    const int kind = y == 0 ? 0 : y == height - 1 ? 2 : 1;
    const std::uint8_t* up = src + static_cast<std::size_t>(y == 0 ? 1 : y - 1) * src_stride;
    const std::uint8_t* mid = src + static_cast<std::size_t>(y) * src_stride;
    const std::uint8_t* down =
        src + static_cast<std::size_t>(y == height - 1 ? height - 2 : y + 1) * src_stride;
    const auto& t = taps[kind];
    const int p = y & 1;
    const auto& c = clip[p];
    std::uint8_t* out = dst + static_cast<std::size_t>(y) * dst_stride;
    out[0] = bayer_pixel<kBytes, kClip>(up, mid, down, 0, 1, 1, t[0][p][0], c[0]);
    if (kind == 1 && quarters != nullptr) {
      quarter_pairs(up, mid, down, pairs, (*quarters)[p][1], (*quarters)[p][0], out);
    } else {
      constexpr bool kApart = kClip && kBytes == 1;  // the rule in clip_lanes
      bayer_pairs<kBytes, kClip && !kApart>(up, mid, down, pairs, t[1][p][1], t[1][p][0], c[1],
                                            c[0], out);
      if constexpr (kApart) {
        const int end = 2 * pairs + 1;
        for (int x = clip_lanes(up, mid, down, end, lanes[p], out); x < end; ++x) {
          out[x] = bayer_clipped<1>(up, mid, down, x, x - 1, x + 1, c[x & 1]) ? 255 : out[x];
        }
      }
    }
    for (int x = 2 * pairs + 1; x < last; ++x)  // one pixel when the width is odd
      out[x] = bayer_pixel<kBytes, kClip>(up, mid, down, x, x - 1, x + 1, t[1][p][x & 1], c[x & 1]);
    out[last] = bayer_pixel<kBytes, kClip>(up, mid, down, last, last - 1, last - 1,
                                           t[2][p][last & 1], c[last & 1]);
  }
}

// `clip`: the clipping rule's levels, or null where it changes nothing.
LASERLINE_PIXEL_KERNEL void bayer8_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                         int height, const BayerTaps& taps,
                                         const InnerQuarterTaps* quarters,
                                         const BayerClipLevels* clip, std::uint8_t* dst,
                                         std::size_t dst_stride) {
  if (clip != nullptr) {
    bayer_frame<1, true>(src, src_stride, width, height, taps, nullptr, *clip, dst, dst_stride);
  } else {
    bayer_frame<1, false>(src, src_stride, width, height, taps, quarters, BayerClipLevels{}, dst,
                          dst_stride);
  }
}

LASERLINE_PIXEL_KERNEL void bayer16_frame(const std::uint8_t* src, std::size_t src_stride,
                                          int width, int height, const BayerTaps& taps,
                                          const BayerClipLevels* clip, std::uint8_t* dst,
                                          std::size_t dst_stride) {
  if (clip != nullptr) {
    bayer_frame<2, true>(src, src_stride, width, height, taps, nullptr, *clip, dst, dst_stride);
  } else {
    bayer_frame<2, false>(src, src_stride, width, height, taps, nullptr, BayerClipLevels{}, dst,
                          dst_stride);
  }
}

// kClip: 255 where a sample under its mask (0xff: a positively weighted colour, else 0) is 255
// (the clipping rule), in bytes.
template <bool kClip>
LASERLINE_PIXEL_ROW void triple_row(const std::uint8_t* __restrict in, int width, const float* w,
                                    const std::uint8_t* clip, std::uint8_t* __restrict out) {
  const float w0 = w[0], w1 = w[1], w2 = w[2];
  const std::uint8_t m0 = clip[0], m1 = clip[1], m2 = clip[2];
  for (int x = 0; x < width; ++x) {
    const std::uint8_t s0 = in[3 * x], s1 = in[3 * x + 1], s2 = in[3 * x + 2];
    const std::uint8_t value = to_byte(w0 * static_cast<float>(s0) + w1 * static_cast<float>(s1) +
                                       w2 * static_cast<float>(s2));
    if constexpr (kClip) {
      const std::uint8_t score =
          hi(hi<std::uint8_t>(s0 & m0, s1 & m1), static_cast<std::uint8_t>(s2 & m2));
      out[x] = score == 255 ? std::uint8_t{255} : value;
    } else {
      out[x] = value;
    }
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

// RGB or BGR: w = the weights of a pixel's three samples in memory order; `clip` their clipping
// levels, or null where the rule changes nothing.
LASERLINE_PIXEL_KERNEL void triple_frame(const std::uint8_t* src, std::size_t src_stride, int width,
                                         int height, const float* w, const std::uint8_t* clip,
                                         std::uint8_t* dst, std::size_t dst_stride) {
  for (int y = 0; y < height; ++y) {
    const std::uint8_t* in = src + static_cast<std::size_t>(y) * src_stride;
    std::uint8_t* out = dst + static_cast<std::size_t>(y) * dst_stride;
    if (clip != nullptr) {
      triple_row<true>(in, width, w, clip, out);
    } else {
      static constexpr std::uint8_t kNoClip[3] = {0, 0, 0};
      triple_row<false>(in, width, w, kNoClip, out);
    }
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

}  // namespace laserline::hal::pixel_kernels
