// Features of a frame for the motion stage: its image pyramid (2x2 box averages), Shi-Tomasi
// corners one per grid cell at the detect level, and the laser filter (paper IV-A) that keeps
// features on the laser line out.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "pipeline/kernels/kernels.hpp"
#include "pipeline/motion.hpp"
#include "pipeline/motion_internal.hpp"

namespace laserline::pipeline {

using namespace motion_detail;

namespace {

// Rows [first, end) of `coarse`, from the rows twice as far down of the finer image.
void downsample_rows(const std::uint8_t* fine, std::ptrdiff_t stride, Level& coarse, int first,
                     int end) {
  for (int v = first; v < end; ++v) {
    kernels::downsample_row(fine + 2 * v * stride, fine + (2 * v + 1) * stride, coarse.width,
                            coarse.pixels.data() + static_cast<std::ptrdiff_t>(v) * coarse.width);
  }
}

// The largest of score[first .. last) where it is above 0 (else at most 0): the bits of a
// positive float order as it does, so the loop is one over integers the compiler vectorises.
[[gnu::noinline]] float largest_positive(const float* __restrict score, int first, int last) {
  std::int32_t most = 0;
  for (int u = first; u < last; ++u)
    most = std::max(most, std::bit_cast<std::int32_t>(score[u]));
  return std::bit_cast<float>(most);
}

// Paper IV-A: summed |Haar d/dv| over summed |Haar d/du| in the neighbourhood of (u, v), detect
// level coordinates. A bright line along the rows answers across it (d/dv) far more than along it.
// Wavelets of kHaarSize on a grid of step kHaarSize / 2, built from sums of half x half blocks.
bool looks_like_laser(const ImageView& level, int u, int v, int radius, double ratio) {
  constexpr int half = kHaarSize / 2;
  // Wavelet centres (x, y): du compares columns x-half .. x-1 with x .. x+half-1, dv rows alike.
  const int u_lo = std::max(u - radius, half), u_hi = std::min(u + radius, level.width - half);
  const int v_lo = std::max(v - radius, half), v_hi = std::min(v + radius, level.height - half);
  if (u_hi < u_lo || v_hi < v_lo) return false;
  const int columns = (u_hi - u_lo) / half + 1, rows = (v_hi - v_lo) / half + 1;
  // block[j][i]: sum of the half x half block whose top left corner is
  // (u_lo - half + i * half, v_lo - half + j * half).
  std::array<std::array<int, kMaxHaarBlocks>, kMaxHaarBlocks> block;
  for (int j = 0; j <= rows; ++j) {
    for (int i = 0; i <= columns; ++i) {
      int sum = 0;
      for (int y = 0; y < half; ++y) {
        const std::uint8_t* p = level.row(v_lo - half + j * half + y) + (u_lo - half + i * half);
        for (int x = 0; x < half; ++x)
          sum += p[x];
      }
      block[j][i] = sum;
    }
  }
  long long sum_du = 0, sum_dv = 0;
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i < columns; ++i) {
      const int top_left = block[j][i], top_right = block[j][i + 1];
      const int bottom_left = block[j + 1][i], bottom_right = block[j + 1][i + 1];
      sum_du += std::abs(top_right + bottom_right - top_left - bottom_left);
      sum_dv += std::abs(bottom_left + bottom_right - top_left - top_right);
    }
  }
  return static_cast<double>(sum_dv) > ratio * static_cast<double>(sum_du);
}

}  // namespace

namespace motion_detail {

void build_pyramid(const ImageView& frame, int levels, Pyramid& pyramid, int first, int end) {
  if (levels <= 1) return;
  downsample_rows(frame.data, frame.stride, pyramid.levels[1], first, end);
  for (int l = 2; l < levels; ++l) {
    const Level& fine = pyramid.levels[l - 1];
    Level& coarse = pyramid.levels[l];
    downsample_rows(fine.pixels.data(), fine.width, coarse, first >> (l - 1),
                    std::min(end >> (l - 1), coarse.height));
  }
}

}  // namespace motion_detail

void MotionEstimator::find_corners(int index, const ImageView& frame, int part) {
  State& s = *state_;
  const MotionOptions& o = options_;
  CornerScratch& scratch = s.corner_scratch[static_cast<std::size_t>(part)];
  const ImageView level =
      o.detect_level == 0 ? frame : s.pyramids[index].levels[o.detect_level].view();
  const int width = level.width;
  // The part's grid rows and the rows of the level they cover.
  const auto [first_grid_row, end_grid_row] = part_range(o.grid_rows, part, s.parts);
  if (first_grid_row == end_grid_row) return;
  const int first_cell = first_grid_row * o.grid_columns;
  const int end_cell = end_grid_row * o.grid_columns;
  std::fill(s.cell_u.begin() + first_cell, s.cell_u.begin() + end_cell, -1);

  // Gradient products (doubled central differences, integers) of the last three rows, and their
  // sums over those rows (kept sliding); summed over columns u-1 .. u+1 they are the structure
  // tensor of (u, v), four times over.
  const int v_first = s.grid_row_start[first_grid_row];
  const int v_end = s.grid_row_start[end_grid_row];
  const int first = v_first - 1;
  const int u_first = s.margin - 1, u_last = width - s.margin;  // inclusive
  std::int32_t* __restrict sum_xx = scratch.column_xx.data();
  std::int32_t* __restrict sum_xy = scratch.column_xy.data();
  std::int32_t* __restrict sum_yy = scratch.column_yy.data();
  for (int u = u_first; u <= u_last; ++u)
    sum_xx[u] = sum_xy[u] = sum_yy[u] = 0;
  for (auto* rows : {&scratch.gxx, &scratch.gxy, &scratch.gyy})
    for (auto& row : *rows)
      std::fill(row.begin(), row.end(), 0);
  // Adds row v's products to the sums, replacing those of row v-3.
  const auto slide = [&](int v) {
    const int slot = v % 3;
    kernels::slide_structure_row(level.row(v - 1), level.row(v), level.row(v + 1),
                                 scratch.gxx[slot].data(), scratch.gxy[slot].data(),
                                 scratch.gyy[slot].data(), sum_xx, sum_xy, sum_yy, u_first,
                                 u_last + 1);
  };
  const float floor4 = 4.0f * kMinEigenvalue;
  std::fill(s.cell_score.begin() + first_cell, s.cell_score.begin() + end_cell, floor4);
  slide(first);
  slide(first + 1);
  float* score = scratch.score.data();
  for (int v = v_first; v < v_end; ++v) {
    slide(v + 1);
    kernels::corner_scores(sum_xx, sum_xy, sum_yy, s.margin, width - s.margin, score);
    float* cell_score = s.cell_score.data() + s.cell_of_row[v] * o.grid_columns;
    int* cell_u = s.cell_u.data() + s.cell_of_row[v] * o.grid_columns;
    int* cell_v = s.cell_v.data() + s.cell_of_row[v] * o.grid_columns;
    // Per cell the first pixel of the row's largest score, where it beats the cell's best so far
    // (which is above 0). (Every pixel is scored, in vectors: a score never exceeds min(a, c),
    // in floats too, so no bound picks fewer pixels.)
    for (int column = 0; column < o.grid_columns; ++column) {
      const int u_first_in_cell = s.cell_start[column], u_end = s.cell_start[column + 1];
      const float most = largest_positive(score, u_first_in_cell, u_end);
      if (!(most > cell_score[column])) continue;
      int u = u_first_in_cell;
      while (score[u] != most)
        ++u;
      cell_score[column] = most;
      cell_u[column] = u;
      cell_v[column] = v;
    }
  }

  for (int cell = first_cell; cell < end_cell; ++cell) {
    s.cell_on_laser[cell] =
        s.cell_u[cell] >= 0 && looks_like_laser(level, s.cell_u[cell], s.cell_v[cell],
                                                2 * o.window_radius, o.laser_filter_ratio);
  }
}

void MotionEstimator::detect_features(int index, const ImageView& frame) {
  State& s = *state_;
  const MotionOptions& o = options_;
  const int cells = o.grid_columns * o.grid_rows;

  // Full-size position of a detect-level pixel: the whole pixel nearest its block's centre, so
  // the full-size template needs no interpolation.
  const int factor = 1 << o.detect_level;
  const int offset = factor / 2;
  int kept = 0, rejected = 0;
  for (int cell = 0; cell < cells; ++cell) {
    if (s.cell_u[cell] < 0) continue;
    const Point p{static_cast<float>(s.cell_u[cell] * factor + offset),
                  static_cast<float>(s.cell_v[cell] * factor + offset)};
    if (s.cell_on_laser[cell]) {
      s.rejected[index][rejected++] = p;
    } else {
      // The full-size template for the tracker, (2r+3)^2 around the feature.
      const int n = o.window_radius + 1;
      std::uint8_t* patch =
          s.patches[index].data() + static_cast<std::ptrdiff_t>(kept) * s.patch_bytes;
      for (int j = -n; j <= n; ++j) {
        std::memcpy(patch, frame.row(static_cast<int>(p[1]) + j) + (static_cast<int>(p[0]) - n),
                    static_cast<std::size_t>(2 * n + 1));
        patch += 2 * n + 1;
      }
      s.features[index][kept++] = p;
    }
  }
  s.feature_count[index] = kept;
  s.rejected_count[index] = rejected;
}

}  // namespace laserline::pipeline
