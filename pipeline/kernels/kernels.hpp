// The pipeline's vector kernels: each written once with Google Highway (pipeline/kernels/*.cpp)
// for every CPU it compiles for (SSE4, AVX2, AVX-512 on x86-64; NEON, SVE on arm64; ...), the one
// the CPU runs chosen on the first call and kept for the process. Beside each, in
// `reference::`, its scalar definition: the vector kernels give the same results to the bit
// (tests/test_kernels.cpp checks it on every target compiled).
// No kernel allocates; each takes explicit column ranges (counts from the pointers given).
#pragma once

#include <cstddef>
#include <cstdint>

namespace laserline::pipeline::kernels {

// ---------------------------------------------------------------------------------------------
// III-A/B: normalised rows (pipeline/kernels/normalise_kernels.cpp)

// Interpolation in fixed point, 1/128 grey level: weights of 7 bits summing to 128, so that a
// pixel's weighted sum fits 16 bits. Results keep 7 - shift fractional bits, rounded.
constexpr int kFixedOne = 128;
constexpr int kFixedBits = 7;

// out[u] = (a[u] (128 - fb) + b[u] fb) rounded to 7 - shift fractional bits, u in [0, count).
void interpolate_row(const std::uint8_t* a, const std::uint8_t* b, std::uint16_t fb, int shift,
                     int count, std::uint16_t* out);

// A normalised row of the frame minus the background, warp block by warp block: each block of
// kWarpBlock pixels is a translation of the background, sampled bilinearly with the block's four
// weights (summing to 128), subtracted from the interpolated current rows and clipped at 0.
// Pixels of a block that have not all four neighbours inside the background give 0.
struct WarpRow {
  static constexpr int kWarpBlock = 32;
  const std::uint8_t* a;  // current rows a and b, weight fb of b
  const std::uint8_t* b;
  std::uint16_t fb;
  int shift;
  std::uint16_t* out;
  const std::uint8_t* background;
  std::ptrdiff_t stride;  // the background's
  // Per block: its first pixel's background pixel (integer column and row), whether the block
  // lies wholly inside, that pixel's offset in the background where it does, the weights of
  // the top left, top right, bottom left and bottom right neighbours.
  const std::int32_t* left;
  const std::int32_t* top;
  const std::int32_t* whole;
  const std::int32_t* offset;
  const std::int32_t* w00;
  const std::int32_t* w01;
  const std::int32_t* w10;
  const std::int32_t* w11;
  int blocks, width, last_column, last_row;
  int partial;  // blocks not whole
};
void difference_row(const WarpRow& row);

// Where the warp blocks [first, end) of a row lie in the background: along the row the background
// position is a ratio of linear functions of the column u, (xn0 + xnu u, yn0 + ynu u) /
// (wn0 + wnu u), evaluated at each block's centre and moved to its first pixel (the block moves
// as a whole); held within `far` of 0 (a NaN to -far) so that it converts to int. Into `out`:
// WarpRow's per-block arrays (the weights the bilinear ones in 1/128, rounded so that they sum to
// 128). Returns how many of the blocks are not whole.
struct WarpLine {
  float xn0, xnu, yn0, ynu, wn0, wnu;
  float far;
  int width;
  std::ptrdiff_t stride;  // the background's
  int last_column, last_row;
};
struct WarpBlocks {
  std::int32_t* left;
  std::int32_t* top;
  std::int32_t* whole;
  std::int32_t* offset;
  std::int32_t* w00;
  std::int32_t* w01;
  std::int32_t* w10;
  std::int32_t* w11;
};
int warp_blocks(const WarpLine& line, int first, int end, const WarpBlocks& out);

// ---------------------------------------------------------------------------------------------
// III-C to E: band-pass, noise and peaks of a strip (pipeline/kernels/band_kernels.cpp), in 16- or
// 32-bit lanes.

// One band-pass row from running box sums (modulo 2^bits): inner += inner_in - inner_out,
// outer likewise, out = a inner - b outer (the result fits the lanes); returns the row's largest.
int band_pass_row(std::uint16_t* inner, const std::uint16_t* inner_in,
                  const std::uint16_t* inner_out, std::uint16_t* outer,
                  const std::uint16_t* outer_in, const std::uint16_t* outer_out, std::uint16_t a,
                  std::uint16_t b, int count, std::int16_t* out);
int band_pass_row(std::uint32_t* inner, const std::uint16_t* inner_in,
                  const std::uint16_t* inner_out, std::uint32_t* outer,
                  const std::uint16_t* outer_in, const std::uint16_t* outer_out, std::uint32_t a,
                  std::uint32_t b, int count, std::int32_t* out);

// Bit i (of word i / 64) set for the columns i in [0, count) of row ring + slot[0] at or above
// `threshold` that are strictly above the rows ring + slot[-k] and at least the rows
// ring + slot[k], k = 1 .. reach. Writes the words [0, (count + 63) / 64).
void peak_bits(const std::int16_t* ring, const std::size_t* slot, int reach, std::int16_t threshold,
               int count, std::uint64_t* bits);
void peak_bits(const std::int32_t* ring, const std::size_t* slot, int reach, std::int32_t threshold,
               int count, std::uint64_t* bits);

// The sum of |x| over columns [first, first + count) of the `rows` rows ring + offsets[j] (one
// side of a noise window, its guard band left out; at most 1000 rows). Exact for |x| < 2^15
// (16-bit lanes) or 2^31 (32-bit lanes): the band-pass's range. Reads, and does not use, up to
// kWindowLanes - 1 lanes past each row's last column: the ring must hold them.
constexpr int kWindowLanes = 32;
std::uint64_t window_sum(const std::int16_t* ring, const std::size_t* offsets, int rows, int first,
                         int count);
std::uint64_t window_sum(const std::int32_t* ring, const std::size_t* offsets, int rows, int first,
                         int count);
// window_sum() of the windows [firsts[k], firsts[k] + count) into sums[k], k < n.
void window_sums(const std::int16_t* ring, const std::size_t* offsets, int rows,
                 const std::int32_t* firsts, int n, int count, std::uint64_t* sums);
void window_sums(const std::int32_t* ring, const std::size_t* offsets, int rows,
                 const std::int32_t* firsts, int n, int count, std::uint64_t* sums);

// ---------------------------------------------------------------------------------------------
// III-F: sub-pixel refinement of columns whose samples all lie inside the frame and the
// background (pipeline/kernels/refine_kernels.cpp).

// Per column j < n: its column u, the rows searched [lo, lo + count) (the first largest
// background-free sample is the peak), the guess `centre`, the fit's sample spacing and the rows
// from the peak to the baseline's samples (edge); the column's path through the background, row v
// at (x0 + dx k, y0 + dy k), k = v - centre. A background-free sample is the current pixel minus
// the background's bilinear sample there, clipped at 0. The result: NaN where the peak is a
// clipped core (its pixel at or above `saturation`: the caller centres the run, whose flanks may
// reach beyond the rows these samples may read), else the Gaussian 3-point fit over the straight
// baseline through the samples `edge` rows on either side (where they lie in the frame: else the
// peak's row). Reads 4 bytes from each pixel it samples: u + 4 <= the frame's width, and the
// background's columns x + 4 <= its width.
struct RefineColumns {
  const std::int32_t* u;
  const std::int32_t* centre;
  const std::int32_t* lo;
  const std::int32_t* count;
  const std::int32_t* spacing;
  const std::int32_t* edge;
  const float* x0;
  const float* y0;
  const float* dx;
  const float* dy;
  const std::uint8_t* current;
  std::ptrdiff_t current_stride;
  const std::uint8_t* background;
  std::ptrdiff_t background_stride;
  int last_row;  // the frame's
  int saturation;
};
void refine_columns(const RefineColumns& columns, int n, float* rows);

// ---------------------------------------------------------------------------------------------
// The line selection (pipeline/line_selection.cpp; pipeline/kernels/selection_kernels.cpp).

// A line before the line in hand: its candidates' positions and best totals, j < count; the jump
// it allows for free, the cost per pixel beyond, the cost of the lines skipped to reach it; its
// first candidate's index.
struct PriorLine {
  const float* position;
  const float* score;
  int count;
  float allowed, jump_cost, skipped;
  std::int32_t first;
};
// Per candidate i < n at position[i]: its best through the line,
//   max over j of score[j] - jump_cost * max(0, |position[i] - position[j]| - allowed) - skipped,
// where that is above best[i], replaces it, and from[i] = first + the first j that gives it.
// Reads position and reads and writes best and from up to the next multiple of kSelectionLanes
// past n (what lies there is overwritten).
constexpr int kSelectionLanes = 8;
void best_priors(const PriorLine& line, int n, float* best, std::int32_t* from,
                 const float* position);

// ---------------------------------------------------------------------------------------------
// Whole images (pipeline/kernels/image_kernels.cpp).

// Per column u in [begin, end) of an image `height` rows high (at most 65535): its largest value,
// the first and the last row where it is reached, and the sum of its values.
void column_maxima(const std::uint8_t* image, std::ptrdiff_t stride, int begin, int end, int height,
                   std::uint8_t* max, std::uint16_t* first, std::uint16_t* last,
                   std::uint32_t* sum);

// dst (rows = src columns) = the transpose of the 16 x 16 block at src.
void transpose16(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                 std::ptrdiff_t dst_stride);

// The 2 x 2 box average (rounded half up) of rows a and b into `count` pixels of out: out[u] from
// a and b at 2u and 2u + 1.
void downsample_row(const std::uint8_t* a, const std::uint8_t* b, int count, std::uint8_t* out);

// Copies `rows` rows of `width` bytes, with stores that bypass the cache where the target has
// them: for a copy read again only frames later, which would otherwise first read every
// destination line in and push out what the frame's next stages read.
void copy_rows_past_cache(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                          std::ptrdiff_t dst_stride, int width, int rows);

// The corners' sliding structure tensor sums, for u in [first, last): the products of row `mid`'s
// doubled central differences (gx = mid[u+1] - mid[u-1], gy = down[u] - up[u]) added to the
// column sums in place of those of the row three above, which xx, xy, yy hold and then take.
void slide_structure_row(const std::uint8_t* up, const std::uint8_t* mid, const std::uint8_t* down,
                         std::int32_t* xx, std::int32_t* xy, std::int32_t* yy, std::int32_t* sum_xx,
                         std::int32_t* sum_xy, std::int32_t* sum_yy, int first, int last);

// The smaller eigenvalue of the structure tensor [a b; b c] at u in [first, last), into score[u]:
// a, b, c the sums of sum_xx, sum_xy, sum_yy over u - 1 .. u + 1 (each below 2^24, so exact as
// floats). The vectors round like the scalar reference, operation by operation.
void corner_scores(const std::int32_t* sum_xx, const std::int32_t* sum_xy,
                   const std::int32_t* sum_yy, int first, int last, float* score);

namespace reference {
void column_maxima(const std::uint8_t* image, std::ptrdiff_t stride, int begin, int end, int height,
                   std::uint8_t* max, std::uint16_t* first, std::uint16_t* last,
                   std::uint32_t* sum);
void transpose16(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                 std::ptrdiff_t dst_stride);
void downsample_row(const std::uint8_t* a, const std::uint8_t* b, int count, std::uint8_t* out);
void copy_rows_past_cache(const std::uint8_t* src, std::ptrdiff_t src_stride, std::uint8_t* dst,
                          std::ptrdiff_t dst_stride, int width, int rows);
void corner_scores(const std::int32_t* sum_xx, const std::int32_t* sum_xy,
                   const std::int32_t* sum_yy, int first, int last, float* score);
void slide_structure_row(const std::uint8_t* up, const std::uint8_t* mid, const std::uint8_t* down,
                         std::int32_t* xx, std::int32_t* xy, std::int32_t* yy, std::int32_t* sum_xx,
                         std::int32_t* sum_xy, std::int32_t* sum_yy, int first, int last);
void refine_columns(const RefineColumns& columns, int n, float* rows);
// (Reads and writes only the candidates i < n.)
void best_priors(const PriorLine& line, int n, float* best, std::int32_t* from,
                 const float* position);
void interpolate_row(const std::uint8_t* a, const std::uint8_t* b, std::uint16_t fb, int shift,
                     int count, std::uint16_t* out);
void difference_row(const WarpRow& row);
int warp_blocks(const WarpLine& line, int first, int end, const WarpBlocks& out);
// Pixels [u, u + count) of a row against background rows p (under pixel u) and p + stride.
void difference_pixels(const WarpRow& row, int u, const std::uint8_t* p, int block, int count);
// Pixel u against a background whose last column p is (its right neighbours taken to be as p, the
// border replicated: under a still camera the frame's last column falls on the background's
// own, less than a pixel short of the column beyond it that bilinear weights read).
void difference_last_column(const WarpRow& row, int u, const std::uint8_t* p, int block);
// Of a block partly outside the background (left ix, top iy, `count` pixels from u0): its pixels
// [first, end) have their four neighbours inside; the pixel at `end`, when it lies on the
// background's last column, its left two. Neither: no signal (0).
struct PartialBlock {
  int first = 0, end = 0;
  bool last_column = false;
};
PartialBlock partial_block(const WarpRow& row, int ix, int iy, int count);
int band_pass_row(std::uint16_t* inner, const std::uint16_t* inner_in,
                  const std::uint16_t* inner_out, std::uint16_t* outer,
                  const std::uint16_t* outer_in, const std::uint16_t* outer_out, std::uint16_t a,
                  std::uint16_t b, int count, std::int16_t* out);
int band_pass_row(std::uint32_t* inner, const std::uint16_t* inner_in,
                  const std::uint16_t* inner_out, std::uint32_t* outer,
                  const std::uint16_t* outer_in, const std::uint16_t* outer_out, std::uint32_t a,
                  std::uint32_t b, int count, std::int32_t* out);
void peak_bits(const std::int16_t* ring, const std::size_t* slot, int reach, std::int16_t threshold,
               int count, std::uint64_t* bits);
void peak_bits(const std::int32_t* ring, const std::size_t* slot, int reach, std::int32_t threshold,
               int count, std::uint64_t* bits);
std::uint64_t window_sum(const std::int16_t* ring, const std::size_t* offsets, int rows, int first,
                         int count);
std::uint64_t window_sum(const std::int32_t* ring, const std::size_t* offsets, int rows, int first,
                         int count);
void window_sums(const std::int16_t* ring, const std::size_t* offsets, int rows,
                 const std::int32_t* firsts, int n, int count, std::uint64_t* sums);
void window_sums(const std::int32_t* ring, const std::size_t* offsets, int rows,
                 const std::int32_t* firsts, int n, int count, std::uint64_t* sums);
}  // namespace reference

// The name of the target the kernels run on (e.g. "AVX2", "NEON"), for logs and benchmarks.
const char* target_name();

}  // namespace laserline::pipeline::kernels
