#include "pipeline/search_axes.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <utility>

#include "pipeline/kernels/kernels.hpp"

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
  // The gradient of 1/Z = -(a (u - cx) / fx + b (v - cy) / fy + c) / e over the pixels is
  // proportional to (a / fx, b / fy).
  const double gu = g.laser_plane[0] / g.fx, gv = g.laser_plane[1] / g.fy;
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
  const double a = g.laser_plane[0], b = g.laser_plane[1], c = g.laser_plane[2],
               e = g.laser_plane[3];
  const auto [k1, k2, p1, p2, k3] = g.distortion;
  if (axes.axis == SearchAxis::kRows) {
    s.fx = g.fy;
    s.fy = g.fx;
    s.cx = g.cy;
    s.cy = g.cx;
    s.distortion = {k1, k2, p2, p1, k3};
    s.laser_plane = Eigen::Vector4d{b, a, c, e};
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
  s.laser_plane = Eigen::Vector4d{-as * f * e, -bs * f * e, -(cs + as * cx + bs * cy) * e, e};
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

void transpose(const ImageView& frame, std::uint8_t* dst, std::ptrdiff_t dst_stride) {
  const int w = frame.width, h = frame.height;
  constexpr int kTile = 16;
  const int whole_rows = h / kTile * kTile, whole_columns = w / kTile * kTile;
  for (int y = 0; y < whole_rows; y += kTile) {
    for (int x = 0; x < whole_columns; x += kTile) {
      kernels::transpose16(frame.row(y) + x, frame.stride, dst + x * dst_stride + y, dst_stride);
    }
    transpose_scalar(frame.row(y) + whole_columns, frame.stride, kTile, w - whole_columns,
                     dst + whole_columns * dst_stride + y, dst_stride);
  }
  transpose_scalar(frame.row(whole_rows), frame.stride, h - whole_rows, w, dst + whole_rows,
                   dst_stride);
}

// floor(a / b) for b != 0.
std::int64_t floor_div(std::int64_t a, std::int64_t b) {
  const std::int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

// The integers t with lo <= start + t * step <= hi, intersected with [first, last].
std::pair<std::int64_t, std::int64_t> solve_range(std::int64_t start, std::int64_t step,
                                                  std::int64_t lo, std::int64_t hi,
                                                  std::int64_t first, std::int64_t last) {
  if (step == 0) {
    if (start >= lo && start <= hi) return {first, last};
    return {1, 0};
  }
  std::int64_t t_lo, t_hi;
  if (step > 0) {
    t_lo = -floor_div(start - lo, step);  // ceil((lo - start) / step)
    t_hi = floor_div(hi - start, step);
  } else {
    t_lo = -floor_div(hi - start, -step);  // ceil((start - hi) / -step)
    t_hi = floor_div(start - lo, -step);
  }
  return {std::max(t_lo, first), std::min(t_hi, last)};
}

}  // namespace

// The rotated grid in 32.32 fixed point, so that whether a sample lies inside the frame is one
// exact predicate: its rows' and its lines' ranges inside agree to the sample.
SearchImage::Grid SearchImage::grid() const {
  constexpr double kOne = 4294967296.0;  // 2^32
  Grid g;
  g.x0 = std::llround(axes_.origin[0] * kOne);
  g.y0 = std::llround(axes_.origin[1] * kOne);
  g.x_line = std::llround(axes_.line_step[0] * kOne);
  g.y_line = std::llround(axes_.line_step[1] * kOne);
  g.x_along = std::llround(axes_.along[0] * kOne);
  g.y_along = std::llround(axes_.along[1] * kOne);
  // Inside: both bilinear neighbours exist (integer part at most width - 2, height - 2).
  g.x_max = (static_cast<std::int64_t>(width_ - 1) << 32) - 1;
  g.y_max = (static_cast<std::int64_t>(height_ - 1) << 32) - 1;
  return g;
}

// One bilinear sample in 8-bit fixed-point weights at (x, y) in 32.32 fixed point, both bilinear
// neighbours inside the frame.
inline std::uint8_t bilinear(const ImageView& frame, std::int64_t x, std::int64_t y) {
  const std::uint8_t* p = frame.row(static_cast<int>(y >> 32)) + (x >> 32);
  const int fx = static_cast<int>((x >> 24) & 0xff), fy = static_cast<int>((y >> 24) & 0xff);
  const int top = (p[0] << 8) + fx * (p[1] - p[0]);
  const int bottom = (p[frame.stride] << 8) + fx * (p[frame.stride + 1] - p[frame.stride]);
  return static_cast<std::uint8_t>(((top << 8) + fy * (bottom - top) + (1 << 15)) >> 16);
}

// Bilinear samples of the frame on the rotated grid. Outside the frame a sample takes the
// frame's nearest edge (its position clamped, linear along the edge): continuous across the border,
// so that the border is no edge along a line, and what lies there is texture like the frame's, not
// a flat run whose small noise would make any bump stand out.
void SearchImage::resample(const ImageView& frame) {
  const Grid g = grid();
  const int lines = axes_.lines, length = axes_.length;
  std::uint8_t* const dst = pixels_.data();
  // Inside, in tiles, so that the frame pixels a tile reads (a rotated square) stay in the L1
  // cache.
  constexpr int kTileLines = 64, kTileRows = 32;
  for (int v0 = 0; v0 < length; v0 += kTileRows) {
    const int v1 = std::min(v0 + kTileRows, length);
    for (int u0 = 0; u0 < lines; u0 += kTileLines) {
      const int u1 = std::min(u0 + kTileLines, lines) - 1;
      for (int v = v0; v < v1; ++v) {
        const std::int64_t x_row = g.x0 + v * g.x_along, y_row = g.y0 + v * g.y_along;
        const auto [x_first, x_last] = solve_range(x_row, g.x_line, 0, g.x_max, u0, u1);
        const auto [first, last] = solve_range(y_row, g.y_line, 0, g.y_max, x_first, x_last);
        std::uint8_t* out = dst + static_cast<std::ptrdiff_t>(v) * lines;
        std::int64_t x = x_row + first * g.x_line, y = y_row + first * g.y_line;
        for (std::int64_t u = first; u <= last; ++u, x += g.x_line, y += g.y_line)
          out[u] = bilinear(frame, x, y);
      }
    }
  }
  // Outside: each row's samples before and after its range inside, from the frame's border (its
  // first and last columns copied out, so that they are read along, not across, the rows).
  for (int y = 0; y < height_; ++y) {
    first_column_[y] = frame.row(y)[0];
    last_column_[y] = frame.row(y)[width_ - 1];
  }
  const std::uint8_t* const top_row = frame.row(0);
  const std::uint8_t* const bottom_row = frame.row(height_ - 1);
  const auto linear = [](const std::uint8_t* p, std::int64_t t) {
    const int i = static_cast<int>(t >> 32), f = static_cast<int>((t >> 24) & 0xff);
    return static_cast<std::uint8_t>(((p[i] << 8) + f * (p[i + 1] - p[i]) + (1 << 7)) >> 8);
  };
  for (int v = 0; v < length; ++v) {
    std::uint8_t* out = dst + static_cast<std::ptrdiff_t>(v) * lines;
    const std::int64_t x_row = g.x0 + v * g.x_along, y_row = g.y0 + v * g.y_along;
    const auto [x_first, x_last] = solve_range(x_row, g.x_line, 0, g.x_max, 0, lines - 1);
    const auto [first, last] = solve_range(y_row, g.y_line, 0, g.y_max, x_first, x_last);
    const auto clamped = [&](std::int64_t from, std::int64_t to) {
      std::int64_t x = x_row + from * g.x_line, y = y_row + from * g.y_line;
      for (std::int64_t u = from; u < to; ++u, x += g.x_line, y += g.y_line) {
        if (x < 0 || x > g.x_max) {
          out[u] = linear(x < 0 ? first_column_.data() : last_column_.data(),
                          std::clamp<std::int64_t>(y, 0, g.y_max));
        } else {
          out[u] = linear(y < 0 ? top_row : bottom_row, x);
        }
      }
    };
    if (first > last) {
      clamped(0, lines);
    } else {
      clamped(0, first);
      clamped(last + 1, lines);
    }
  }
}

void SearchImage::reset(const SearchAxes& axes, int width, int height) {
  axes_ = axes;
  width_ = width;
  height_ = height;
  pixels_.assign(axes.identity() ? 0 : static_cast<std::size_t>(axes.lines) * axes.length, 0);
  const std::size_t border = axes.axis == SearchAxis::kOblique ? height : 0;
  first_column_.assign(border, 0);
  last_column_.assign(border, 0);
}

ImageView SearchImage::make(const ImageView& frame) {
  switch (axes_.axis) {
    case SearchAxis::kColumns:
      return frame;
    case SearchAxis::kRows:
      transpose(frame, pixels_.data(), axes_.lines);
      break;
    case SearchAxis::kOblique:
      resample(frame);
      break;
  }
  return {pixels_.data(), axes_.lines, axes_.length, axes_.lines};
}

}  // namespace laserline::pipeline
