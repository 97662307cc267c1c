#include "pipeline/search_axes.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace laserline::pipeline {

const char* to_string(SearchAxis axis) {
  switch (axis) {
    case SearchAxis::kColumns:
      return "columns";
    case SearchAxis::kRows:
      return "rows";
    case SearchAxis::kOblique:
      return "oblique";
  }
  return "columns";
}

SearchAxes SearchAxes::columns(int width, int height) {
  SearchAxes axes;
  axes.lines = width;
  axes.length = height;
  return axes;
}

SearchAxes choose_search_axes(const ScannerGeometry& g) {
  const auto& [a, b, c, e] = g.laser_plane;
  (void)c;
  (void)e;
  // The gradient of 1/Z = -(a (u - cx) / fx + b (v - cy) / fy + c) / e over the pixels is
  // proportional to (a / fx, b / fy).
  const double gu = a / g.fx, gv = b / g.fy;
  const double norm = std::hypot(gu, gv);
  const double tolerance = std::tan(kAxisToleranceDeg * std::numbers::pi / 180.0);
  if (!(norm > 0) || std::abs(gu) <= tolerance * std::abs(gv)) {
    // No gradient at all (a sheet through the camera centre, or parallel to the image plane)
    // is refused by the detectors with their own reason; the columns are as good as any here.
    return SearchAxes::columns(g.width, g.height);
  }
  if (std::abs(gv) <= tolerance * std::abs(gu)) {
    SearchAxes axes;
    axes.axis = SearchAxis::kRows;
    axes.line_step = {0.0, 1.0};
    axes.along = {1.0, 0.0};
    axes.lines = g.height;
    axes.length = g.width;
    return axes;
  }
  SearchAxes axes;
  axes.axis = SearchAxis::kOblique;
  const double sign = gv < 0 ? -1.0 : 1.0;  // along points down the image, as for columns
  axes.along = {sign * gu / norm, sign * gv / norm};
  axes.line_step = {axes.along[1], -axes.along[0]};  // [line_step along] is a rotation
  // The search image holds the whole frame: the bounding box of its corners.
  double line_lo = 1e300, line_hi = -1e300, pos_lo = 1e300, pos_hi = -1e300;
  for (const double x : {0.0, static_cast<double>(g.width - 1)}) {
    for (const double y : {0.0, static_cast<double>(g.height - 1)}) {
      const auto [line, position] = axes.to_search(x, y);
      line_lo = std::min(line_lo, line);
      line_hi = std::max(line_hi, line);
      pos_lo = std::min(pos_lo, position);
      pos_hi = std::max(pos_hi, position);
    }
  }
  line_lo = std::floor(line_lo);
  pos_lo = std::floor(pos_lo);
  axes.origin = {line_lo * axes.line_step[0] + pos_lo * axes.along[0],
                 line_lo * axes.line_step[1] + pos_lo * axes.along[1]};
  axes.lines = static_cast<int>(std::ceil(line_hi - line_lo)) + 1;
  axes.length = static_cast<int>(std::ceil(pos_hi - pos_lo)) + 1;
  return axes;
}

ScannerGeometry search_geometry(const ScannerGeometry& g, const SearchAxes& axes) {
  if (axes.axis == SearchAxis::kColumns) return g;
  ScannerGeometry s = g;
  s.width = axes.lines;
  s.height = axes.length;
  const auto [a, b, c, e] = g.laser_plane;
  const auto [k1, k2, p1, p2, k3] = g.distortion;
  if (axes.axis == SearchAxis::kRows) {
    s.fx = g.fy;
    s.fy = g.fx;
    s.cx = g.cy;
    s.cy = g.cx;
    s.distortion = {k1, k2, p2, p1, k3};
    s.laser_plane = {b, a, c, e};
    return s;
  }
  // The inverse depth over the frame, 1/Z = A x + B y + C, in search coordinates.
  const double big_a = -a / (e * g.fx), big_b = -b / (e * g.fy);
  const double big_c = (a * g.cx / g.fx + b * g.cy / g.fy - c) / e;
  const auto& o = axes.origin;
  const auto& l = axes.line_step;
  const auto& w = axes.along;
  const double as = big_a * l[0] + big_b * l[1];
  const double bs = big_a * w[0] + big_b * w[1];
  const double cs = big_a * o[0] + big_b * o[1] + big_c;
  const double f = std::sqrt(g.fx * g.fy);
  const auto [cx, cy] = axes.to_search(g.cx, g.cy);
  s.fx = s.fy = f;
  s.cx = cx;
  s.cy = cy;
  s.laser_plane = {-as * f * e, -bs * f * e, -(cs + as * cx + bs * cy) * e, e};
  // Radial terms are unchanged by a roll; the tangential ones form the vector (p2, p1), which
  // turns with the grid.
  const double q_line = p2 * l[0] + p1 * l[1], q_along = p2 * w[0] + p1 * w[1];
  s.distortion = {k1, k2, q_along, q_line, k3};
  return s;
}

namespace {

// dst (rows = src columns) = transpose of src, for a block of `rows` x `columns` pixels.
void transpose_scalar(const std::uint8_t* src, std::ptrdiff_t src_stride, int rows, int columns,
                      std::uint8_t* dst, std::ptrdiff_t dst_stride) {
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < columns; ++x)
      dst[x * dst_stride + y] = src[y * src_stride + x];
  }
}

#if defined(__SSE2__)
// A 16 x 16 block through four rounds of interleaves (bytes, words, double words, quad words):
// each round doubles the run of one source column held together in a register.
void transpose16(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                 std::ptrdiff_t dst_stride) {
  __m128i r[16], t[16];
  for (int i = 0; i < 16; ++i)
    r[i] = _mm_loadu_si128(reinterpret_cast<const __m128i*>(src + i * src_stride));
  for (int k = 0; k < 8; ++k) {  // rows 2k, 2k+1 paired: columns 0-7, then 8-15
    t[k] = _mm_unpacklo_epi8(r[2 * k], r[2 * k + 1]);
    t[k + 8] = _mm_unpackhi_epi8(r[2 * k], r[2 * k + 1]);
  }
  for (int half = 0; half < 16; half += 8) {  // columns 0-7, then 8-15
    for (int k = 0; k < 4; ++k) {             // rows 4k .. 4k+3: columns +0-3, then +4-7
      r[half + k] = _mm_unpacklo_epi16(t[half + 2 * k], t[half + 2 * k + 1]);
      r[half + k + 4] = _mm_unpackhi_epi16(t[half + 2 * k], t[half + 2 * k + 1]);
    }
  }
  for (int quad = 0; quad < 16; quad += 4) {  // four columns: rows 0-3, 4-7, 8-11, 12-15 in r
    const __m128i low01 = _mm_unpacklo_epi32(r[quad], r[quad + 1]);       // columns 0, 1: rows 0-7
    const __m128i high01 = _mm_unpackhi_epi32(r[quad], r[quad + 1]);      // columns 2, 3: rows 0-7
    const __m128i low23 = _mm_unpacklo_epi32(r[quad + 2], r[quad + 3]);   // rows 8-15
    const __m128i high23 = _mm_unpackhi_epi32(r[quad + 2], r[quad + 3]);  // rows 8-15
    t[quad] = _mm_unpacklo_epi64(low01, low23);
    t[quad + 1] = _mm_unpackhi_epi64(low01, low23);
    t[quad + 2] = _mm_unpacklo_epi64(high01, high23);
    t[quad + 3] = _mm_unpackhi_epi64(high01, high23);
  }
  for (int i = 0; i < 16; ++i)
    _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + i * dst_stride), t[i]);
}
#endif

void transpose(const ImageView& frame, std::uint8_t* dst, std::ptrdiff_t dst_stride) {
  const int w = frame.width, h = frame.height;
  constexpr int kTile = 16;
  const int whole_rows = h / kTile * kTile, whole_columns = w / kTile * kTile;
  for (int y = 0; y < whole_rows; y += kTile) {
    for (int x = 0; x < whole_columns; x += kTile) {
#if defined(__SSE2__)
      transpose16(frame.row(y) + x, frame.stride, dst + x * dst_stride + y, dst_stride);
#else
      transpose_scalar(frame.row(y) + x, frame.stride, kTile, kTile, dst + x * dst_stride + y,
                       dst_stride);
#endif
    }
    transpose_scalar(frame.row(y) + whole_columns, frame.stride, kTile, w - whole_columns,
                     dst + whole_columns * dst_stride + y, dst_stride);
  }
  transpose_scalar(frame.row(whole_rows), frame.stride, h - whole_rows, w, dst + whole_rows,
                   dst_stride);
}

// Bilinear samples of the frame along the rotated grid, the frame's edge continued outside it.
void resample(const ImageView& frame, const SearchAxes& axes, std::uint8_t* dst) {
  const float last_x = static_cast<float>(frame.width - 1);
  const float last_y = static_cast<float>(frame.height - 1);
  const auto lx = static_cast<float>(axes.line_step[0]), ly = static_cast<float>(axes.line_step[1]);
  for (int v = 0; v < axes.length; ++v) {
    const auto [x0, y0] = axes.to_image(0.0, v);
    std::uint8_t* out = dst + static_cast<std::ptrdiff_t>(v) * axes.lines;
    for (int u = 0; u < axes.lines; ++u) {
      const float x = std::clamp(static_cast<float>(x0) + static_cast<float>(u) * lx, 0.0f, last_x);
      const float y = std::clamp(static_cast<float>(y0) + static_cast<float>(u) * ly, 0.0f, last_y);
      const int ix = std::min(static_cast<int>(x), frame.width - 2);
      const int iy = std::min(static_cast<int>(y), frame.height - 2);
      const float fx = x - static_cast<float>(ix), fy = y - static_cast<float>(iy);
      const std::uint8_t* p = frame.row(iy) + ix;
      const float top = p[0] + fx * (static_cast<float>(p[1]) - p[0]);
      const float bottom =
          p[frame.stride] + fx * (static_cast<float>(p[frame.stride + 1]) - p[frame.stride]);
      out[u] = static_cast<std::uint8_t>(top + fy * (bottom - top) + 0.5f);
    }
  }
}

}  // namespace

void SearchImage::reset(const SearchAxes& axes, int width, int height) {
  axes_ = axes;
  width_ = width;
  height_ = height;
  pixels_.assign(axes.identity() ? 0 : static_cast<std::size_t>(axes.lines) * axes.length, 0);
}

ImageView SearchImage::make(const ImageView& frame) {
  switch (axes_.axis) {
    case SearchAxis::kColumns:
      return frame;
    case SearchAxis::kRows:
      transpose(frame, pixels_.data(), axes_.lines);
      break;
    case SearchAxis::kOblique:
      resample(frame, axes_, pixels_.data());
      break;
  }
  return {pixels_.data(), axes_.lines, axes_.length, axes_.lines};
}

}  // namespace laserline::pipeline
