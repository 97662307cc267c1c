// The front end (paper Section III): its sizes from the options and the geometry, the row
// normalisation (III-B: the background warped and subtracted, rows resampled to a constant line
// width; its vector kernels in pipeline/kernels/), and the choice of the line among the
// candidates. The pass down the rows is in frontend_roll.cpp, the sub-pixel refinement in
// frontend_refine.cpp.
#include "pipeline/frontend.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <tuple>
#include <type_traits>

#include "pipeline/frontend_common.hpp"
#include "pipeline/kernels/kernels.hpp"
#include "pipeline/subpixel.hpp"

namespace laserline::pipeline {

using namespace frontend_detail;

namespace {

constexpr float kDecibelsPerNeper = 8.68588963806503655f;  // 20 / ln 10

int odd_at_least_one(double x) {
  const int n = std::max(1, static_cast<int>(std::lround(x)));
  return n % 2 == 1 ? n : n + 1;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// III-B

RowNormalisation::RowNormalisation(const ScannerGeometry& g, const FrontendOptions& options,
                                   int margin) {
  const double a = g.laser_plane[0], b = g.laser_plane[1], c = g.laser_plane[2],
               e = g.laser_plane[3];
  if (!(g.sheet_width_m > 0)) throw std::invalid_argument("the sheet width must be > 0");
  if (e == 0.0) throw std::invalid_argument("laser plane passes through the camera centre");
  // l(v) = fy l_w / Z(cx, v), 1 / Z = -(b (v - cy) / fy + c) / e: the width is modelled on the
  // centre column. The columns are searched when the sheet's depth changes along them within a
  // few degrees (pipeline/search_axes.hpp), so a changes it across the image only a little:
  // l(u, v) = l(v) + gamma (u - cx).
  beta_ = -g.sheet_width_m * b / e;
  alpha_ = -g.fy * g.sheet_width_m * (c - b * g.cy / g.fy) / e;
  if (std::abs(beta_) * g.height < 1e-6 * std::abs(alpha_) || !std::isfinite(beta_)) {
    throw std::invalid_argument(
        "laser plane: the sheet's depth must change along the epipolar lines (its normal must "
        "not be along the optical axis)");
  }
  const double gamma = -g.fy * g.sheet_width_m * a / (e * g.fx);
  scale_ = options.normalised_width_px;
  blur_ = options.line_blur_px;
  const double l_far = g.fy * g.sheet_width_m / options.max_depth_m;
  const double l_near = g.fy * g.sheet_width_m / options.min_depth_m;
  // The rows where some column sees the sheet within the depth range: the union over the first
  // and last column (l is affine in u), kept where the centre column's width stays positive.
  double v_lo = std::numeric_limits<double>::infinity(), v_hi = -v_lo;
  for (const double u : {0.0, static_cast<double>(g.width - 1)}) {
    const double offset = alpha_ + gamma * (u - g.cx);
    for (const double l : {l_far, l_near}) {
      v_lo = std::min(v_lo, (l - offset) / beta_);
      v_hi = std::max(v_hi, (l - offset) / beta_);
    }
  }
  const double positive = (0.5 * l_far - alpha_) / beta_;  // centre column at twice max_depth
  if (beta_ > 0) v_lo = std::max(v_lo, positive);
  if (beta_ < 0) v_hi = std::min(v_hi, positive);
  v_lo = std::max(v_lo, 0.0);
  v_hi = std::min(v_hi, static_cast<double>(g.height - 1));
  if (!(v_lo < v_hi)) {
    throw std::invalid_argument(
        "no image row sees the laser sheet between min_depth_m and max_depth_m");
  }
  r0_ = 0.0;
  r0_ = static_cast<double>(margin) - to_normalised(v_lo);
  const int count = static_cast<int>(std::ceil(to_normalised(v_hi))) + 1 + margin;
  single_alpha_ = static_cast<float>(alpha_);
  single_inverse_beta_ = static_cast<float>(1.0 / beta_);
  single_rate_ = static_cast<float>(beta_ / scale_);
  single_r0_ = static_cast<float>(r0_);
  single_blur_ = static_cast<float>(blur_);
  source_row_.resize(static_cast<std::size_t>(count));
  const float last = static_cast<float>(g.height - 1);
  for (int r = 0; r < count; ++r) {
    source_row_[static_cast<std::size_t>(r)] =
        std::clamp(static_cast<float>(to_source(r)), 0.0f, last);
  }
}

// dr/dv = W / w(v), w(v) = sqrt(l(v)^2 + b^2): r = (W / beta) asinh(l(v) / b), which for b = 0
// is (W / beta) ln l(v) (up to a constant); l(v) > 0 wherever the sheet is in front of the camera.
// (asinh and sinh from exp, log and sqrt: the libraries of every architecture give these the same
// results, and the profiles must be the same on all of them.)
double RowNormalisation::to_normalised(double v) const {
  const double sheet = alpha_ + beta_ * v;
  double t = 0.0;
  if (blur_ > 0.0) {
    const double x = std::abs(sheet / blur_);
    t = std::copysign(std::log(x + std::sqrt(x * x + 1.0)), sheet);
  } else {
    t = std::log(std::max(sheet, 1e-12));
  }
  return scale_ / beta_ * t + r0_;
}

double RowNormalisation::to_source(double r) const {
  const double t = (r - r0_) * beta_ / scale_;
  const double sheet = blur_ > 0.0 ? 0.5 * blur_ * (std::exp(t) - std::exp(-t)) : std::exp(t);
  return (sheet - alpha_) / beta_;
}

float RowNormalisation::to_source_single(float r) const {
  const float t = (r - single_r0_) * single_rate_;
  const float sheet =
      single_blur_ > 0.0f ? 0.5f * single_blur_ * (std::exp(t) - std::exp(-t)) : std::exp(t);
  return (sheet - single_alpha_) * single_inverse_beta_;
}

// ---------------------------------------------------------------------------------------------

Frontend::Frontend(const ScannerGeometry& geometry, const FrontendOptions& options)
    : geometry_(geometry), options_(options), selector_(options.selection) {
  options.validate();
  inner_ = odd_at_least_one(options.normalised_width_px);
  outer_ = odd_at_least_one(options.normalised_width_px * options.passband_ratio);
  if (outer_ <= inner_) outer_ = inner_ + 2;
  // The noise window leaves out a guard band as wide as the band-pass response of a line at the
  // pixel itself (as a CFAR detector does): otherwise a strong line raises its own noise estimate
  // and scores lower than faint texture next to it.
  guard_ = inner_ / 2 + outer_ / 2;
  noise_half_ = std::max(options.noise_rows / 2, guard_ + 1);
  noise_pad_ = std::max(options.noise_columns, 1) / 2;
  noise_side_ratio_ = options.noise_side_ratio;
  noise_norm_ = 1.0f / static_cast<float>(2 * (noise_half_ - guard_) * (2 * noise_pad_ + 1));
  // The band-pass as an integer: inner mean - outer mean = g (a S_inner - b S_outer) /
  // (inner outer one), with a = outer / g, b = inner / g (g their gcd) and one the normalised
  // rows' fixed-point one. Its extremes are +-255 (1 - inner / outer) grey levels, so it fits
  // 16-bit lanes when 255 one (outer - inner) inner / g does (and the outer box's sum,
  // 255 one outer, fits 16 unsigned bits): with the most fractional bits of the normalised rows
  // (at most 4, at least 2) for which that holds, else 32-bit lanes and the 7 of the
  // interpolation.
  const int g = std::gcd(inner_, outer_);
  band_a_ = outer_ / g;
  band_b_ = inner_ / g;
  const long extreme = 255L * (outer_ - inner_) * inner_ / g;
  int bits = kFixedBits;
  narrow_band_ = false;
  for (int narrow_bits = 4; narrow_bits >= 2 && !narrow_band_; --narrow_bits) {
    if ((extreme << narrow_bits) <= 32767 && (255L << narrow_bits) * outer_ <= 65535) {
      narrow_band_ = true;
      bits = narrow_bits;
    }
  }
  normalised_shift_ = kFixedBits - bits;
  band_unit_ = static_cast<float>(g) / static_cast<float>(inner_ * outer_ * (1 << bits));
  // Candidates are local maxima of the band-pass within one laser width along the column: the
  // noise window (guard band excluded) is the same to within a row there, so these are the
  // maxima of the SNR too.
  reach_ = std::max(1, inner_ / 2 + 1);
  // A line's band-pass is negative on both sides, most so about an inner box away (the outer box
  // holds the line, the inner one not), an edge's on one side only: the ridge test looks for the
  // negative lobe within half an outer box beyond where the band-pass crosses zero (farther out
  // for a line wider than the model: a clipped or blurred one).
  ridge_ = outer_ / 2 + 1;
  half_per_normalised_width_ = 0.5 / options.normalised_width_px;
  margin_ = outer_ / 2 + 2;
  rows_ = RowNormalisation(geometry, options, margin_);
}

void Frontend::reset(int width, int height) {
  if (width != geometry_.width || height != geometry_.height) {
    throw std::invalid_argument("frame size " + std::to_string(width) + "x" +
                                std::to_string(height) + " differs from the calibration's " +
                                std::to_string(geometry_.width) + "x" +
                                std::to_string(geometry_.height));
  }
  if (width < 2 * kWarpBlock || height < 4) {
    throw std::invalid_argument("frame smaller than " + std::to_string(2 * kWarpBlock) +
                                "x4 pixels");
  }
  width_ = width;
  height_ = height;
  stride_ = (width + kBlock - 1) / kBlock * kBlock;
  // Each strip's band-pass ring holds the rows from the oldest the noise window of the block's
  // first row r reaches (r - noise/2; a peak is compared with fewer) to the newest the block's
  // last row looks at; the normalised ring the rows the band-pass boxes of the block's rows reach.
  // (A row's slot in a ring is looked up once per block of rows, so the rings are no larger than
  // they must be: they stay in the cache.)
  const int look = std::max({noise_half_, reach_, ridge_});
  band_ring_rows_ = kRowBlock + 2 * look;
  normalised_ring_rows_ = kRowBlock + look + outer_ + 2;
  const int strips = (width + kStripColumns - 1) / kStripColumns;
  // A strip holds its columns and the noise window's reach on either side, the same count for
  // every strip (a constant trip count for its kernels): the normalised rows are padded with
  // zeros on both sides for the strips at the image's edges to read.
  ring_stride_ = (kStripColumns + 2 * noise_pad_ + kBlock - 1) / kBlock * kBlock;
  normalised_pad_ = (noise_pad_ + kBlock - 1) / kBlock * kBlock;
  normalised_stride_ = normalised_pad_ + strips * kStripColumns + ring_stride_;
  const auto ring = static_cast<std::size_t>(ring_stride_);
  const auto s = static_cast<std::size_t>(normalised_stride_);
  band_most_.assign(static_cast<std::size_t>(strips * (band_ring_rows_ + 1)), 0);
  // Each strip's rings end with a row of zeros (the rows beyond the ends), and a register's lanes
  // more for the noise sums to read past it (not into the next strip's ring, which another part
  // may be writing).
  band_strip_size_ = static_cast<std::size_t>(band_ring_rows_ + 1) * ring + kernels::kWindowLanes;
  const auto band_ring = static_cast<std::size_t>(strips) * band_strip_size_;
  narrow_.assign(narrow_band_ ? band_ring : 0, narrow_band_ ? strips * ring : 0);
  wide_.assign(narrow_band_ ? 0 : band_ring, narrow_band_ ? 0 : strips * ring);
  // Each part's buffers (its strips and warp blocks are placed for each pass: place_parts()).
  const int blocks = (width + kWarpBlock - 1) / kWarpBlock;
  parts_.resize(static_cast<std::size_t>(std::clamp(runner_->parts(), 1, kMaxParts)));
  for (Part& part : parts_) {
    part.normalised_ring.assign(static_cast<std::size_t>(normalised_ring_rows_) * s, 0);
    part.band_rows.assign(static_cast<std::size_t>(kRowBlock + 2 * look), 0);
    part.band_slots.assign(part.band_rows.size(), 0);
    part.normalised_rows.assign(static_cast<std::size_t>(kRowBlock + look + outer_ + 3), nullptr);
    for (std::vector<std::int32_t>* warp :
         {&part.warp_left, &part.warp_top, &part.warp_whole, &part.warp_offset})
      warp->assign(static_cast<std::size_t>(blocks), 0);
    for (std::vector<std::int32_t>& weights : part.warp_weights)
      weights.assign(static_cast<std::size_t>(blocks), 0);
    part.peak_bits.assign((ring + 63) / 64, 0u);
    for (std::vector<std::int32_t>* buffer :
         {&part.peak_column, &part.peak_slot, &part.peak_clipped, &part.window_first})
      buffer->assign(ring, 0);
    part.peak_rank.assign(ring, 0.0f);
    part.window_sum_above.assign(ring, 0u);
    part.window_sum_below.assign(ring, 0u);
  }
  zero_normalised_.assign(s, 0);
  column_best_.assign(static_cast<std::size_t>(width) * options_.max_candidates_per_column, {});
  column_count_.assign(static_cast<std::size_t>(width), 0);
  line_candidates_.assign(static_cast<std::size_t>(width) * options_.max_candidates_per_column, {});
  eligible_.assign(line_candidates_.size(), {});
  eligible_count_.assign(static_cast<std::size_t>(width), 0);
  eligible_point_.assign(line_candidates_.size(), 0);
  chosen_.assign(static_cast<std::size_t>(width), -1);
  selector_.reset(width, options_.max_candidates_per_column);
  probe_count_ = 0;
  previous_line_.assign(static_cast<std::size_t>(width), kNoPreviousLine);
  refine_columns_.assign(static_cast<std::size_t>(width), 0);
  refine_guesses_.assign(static_cast<std::size_t>(width), 0.0f);
  refine_points_.assign(static_cast<std::size_t>(width), 0);
  RefineLanes& lanes = refine_lanes_;
  for (std::vector<std::int32_t>* field :
       {&lanes.u, &lanes.centre, &lanes.lo, &lanes.count, &lanes.spacing, &lanes.edge})
    field->assign(static_cast<std::size_t>(width), 0);
  for (std::vector<float>* field : {&lanes.x0, &lanes.y0, &lanes.dx, &lanes.dy, &lanes.rows})
    field->assign(static_cast<std::size_t>(width), 0.0f);
  lanes.point.assign(static_cast<std::size_t>(width), 0);
  update_bounds();
}

Frontend::PassBounds Frontend::whole_bounds() const {
  return {0, width_, 0, rows_.rows(), 0, width_};
}

double Frontend::refine_reach(double v) const {
  // refine_start()'s search reach and the fit's half row, with a row to spare.
  return std::max(rows_.width_px(v), 1.0) * half_per_normalised_width_ + 4.0;
}

void Frontend::set_region(const DetectionRegion& region) {
  region_ = region;
  update_bounds();
}

void Frontend::update_bounds() {
  if (width_ == 0) return;  // (reset() comes back here)
  const DetectionRegion r = region_.in_frame(width_, height_);
  candidate_row_begin_ = r.y;
  candidate_row_end_ = static_cast<double>(r.y) + r.height;
  if (region_.whole()) {
    bounds_ = whole_bounds();
    return;
  }
  bounds_ = PassBounds{};
  if (r.width == 0 || r.height == 0) return;
  PassBounds& b = bounds_;
  b.column_begin = r.x;
  b.column_end = r.x + r.width;
  // The normalised rows whose band-pass peaks (within half a row) map to the region's rows or
  // within the refinement's reach of them, and one more on each side for the single-precision map.
  const double rows = rows_.rows();
  const double top = r.y - 0.5, bottom = r.y + r.height - 0.5;
  const double first = std::floor(rows_.to_normalised(top - refine_reach(top))) - 1.0;
  const double last = std::ceil(rows_.to_normalised(bottom + refine_reach(bottom))) + 1.0;
  b.row_begin = static_cast<int>(std::clamp(first, 0.0, rows));
  b.row_end = static_cast<int>(std::clamp(last + 1.0, static_cast<double>(b.row_begin), rows));
  // The noise window reaches noise_pad_ columns to either side; the warp goes by whole blocks.
  b.normalise_begin = std::max(0, b.column_begin - noise_pad_) / kWarpBlock * kWarpBlock;
  b.normalise_end =
      std::min(width_, (b.column_end + noise_pad_ + kWarpBlock - 1) / kWarpBlock * kWarpBlock);
}

void Frontend::place_parts(const PassBounds& bounds) {
  const int strip_begin = bounds.column_begin / kStripColumns;
  const int strip_end = (bounds.column_end + kStripColumns - 1) / kStripColumns;
  const int blocks = (width_ + kWarpBlock - 1) / kWarpBlock;
  const int normalise_begin = bounds.normalise_begin / kWarpBlock;
  const int normalise_end = std::min((bounds.normalise_end + kWarpBlock - 1) / kWarpBlock, blocks);
  for (std::size_t p = 0; p < parts_.size(); ++p) {
    Part& part = parts_[p];
    const auto [first, end] =
        part_range(strip_end - strip_begin, static_cast<int>(p), static_cast<int>(parts_.size()));
    part.first_strip = strip_begin + first;
    part.end_strip = strip_begin + end;
    part.first_block = part.end_block = 0;
    if (first == end) continue;
    // The normalised columns its strips read: their own and the noise window's reach beyond (up
    // to a strip's ring stride), within those the pass makes.
    const int first_column = part.first_strip * kStripColumns - noise_pad_;
    const int end_column = (part.end_strip - 1) * kStripColumns - noise_pad_ + ring_stride_;
    part.first_block = std::max(std::max(first_column, 0) / kWarpBlock, normalise_begin);
    part.end_block = std::max(std::min((end_column + kWarpBlock - 1) / kWarpBlock, normalise_end),
                              part.first_block);
  }
}

namespace {

static_assert(Frontend::kWarpBlock == kernels::WarpRow::kWarpBlock);

inline std::uint16_t fixed_weight(float t) {
  return static_cast<std::uint16_t>(std::clamp(t, 0.0f, 1.0f) * kFixedOne + 0.5f);
}

// The two rows of the frame a normalised row is interpolated from, and the weight of the lower.
struct SourceRow {
  SourceRow(const ImageView& image, float v) {
    const int last = image.height - 1;
    const int v0 = std::min(static_cast<int>(v), last);
    a = image.row(v0);
    b = image.row(std::min(v0 + 1, last));
    fb = fixed_weight(v - static_cast<float>(v0));
  }
  const std::uint8_t* a;
  const std::uint8_t* b;
  std::uint16_t fb;
};

}  // namespace

void Frontend::set_frame(const ImageView& current) {
  current_ = current;
  subtracting_ = fit_with_background_ = false;
}

void Frontend::set_frame_minus_background(const ImageView& current, const ImageView& background,
                                          const Homography& current_to_background,
                                          bool fit_with_background) {
  current_ = current;
  background_ = background;
  to_background_ = current_to_background;
  subtracting_ = true;
  fit_with_background_ = fit_with_background;
}

void Frontend::normalise_row(Part& part, int r, std::uint16_t* out) {
  const float v = rows_.source_row(r);
  const SourceRow row(current_, v);
  // The part's columns [u0, u1): whole warp blocks (each is evaluated as in one part: alike).
  const int u0 = part.first_block * kWarpBlock;
  const int u1 = std::min(part.end_block * kWarpBlock, width_);
  if (u0 >= u1) return;
  if (!subtracting_) {
    kernels::interpolate_row(row.a + u0, row.b + u0, row.fb, normalised_shift_, u1 - u0, out + u0);
    return;
  }
  // The background may be a band of rows of the frame (its own size; the homography says where).
  const ImageView& background = background_;
  const auto bg_width = static_cast<float>(background.width);
  const auto bg_height = static_cast<float>(background.height);
  // Along the row the background position is a ratio of linear functions of u: numerators and
  // denominator at u = 0, and their steps per pixel.
  const auto& g = to_background_.h;
  const auto xn0 = static_cast<float>(g(0, 1) * v + g(0, 2)), xnu = static_cast<float>(g(0, 0));
  const auto yn0 = static_cast<float>(g(1, 1) * v + g(1, 2)), ynu = static_cast<float>(g(1, 0));
  const auto wn0 = static_cast<float>(g(2, 1) * v + g(2, 2)), wnu = static_cast<float>(g(2, 0));
  const int first_block = part.first_block, blocks = part.end_block - part.first_block;
  const int width = width_, stride = background.stride, last_column = background.width - 1;
  const int last_row = background.height - 1;
  // Where each block was in the background, for all blocks of the row at once (positions held
  // within two background sizes).
  // (The kernels index the blocks from the part's first.)
  std::int32_t* left = part.warp_left.data();
  std::int32_t* top = part.warp_top.data();
  std::int32_t* whole = part.warp_whole.data();
  std::int32_t* offset = part.warp_offset.data();
  std::int32_t* w00 = part.warp_weights[0].data();
  std::int32_t* w01 = part.warp_weights[1].data();
  std::int32_t* w10 = part.warp_weights[2].data();
  std::int32_t* w11 = part.warp_weights[3].data();
  const float far = 2.0f * std::max(bg_width, bg_height);
  const int partial = kernels::warp_blocks(
      {xn0, xnu, yn0, ynu, wn0, wnu, far, width, stride, last_column, last_row}, first_block,
      first_block + blocks, {left, top, whole, offset, w00, w01, w10, w11});
  const auto j = static_cast<std::size_t>(first_block);
  kernels::difference_row({row.a + u0,      row.b + u0, row.fb,      normalised_shift_, out + u0,
                           background.data, stride,     left + j,    top + j,           whole + j,
                           offset + j,      w00 + j,    w01 + j,     w10 + j,           w11 + j,
                           blocks,          width - u0, last_column, last_row,          partial});
}

bool Frontend::water_glows(const ImageView& frame) const {
  if (probe_count_ == 0 || frame.data == nullptr) return false;
  // At each point where the line was last found: the mean brightness of the few widths just in
  // front of it (the near side) and just behind it, and the line's own brightness.
  const int near = rows_.near_side();
  std::array<float, kProbes> excess{}, line{};
  std::size_t n = 0;
  for (std::size_t i = 0; i < probe_count_; ++i) {
    const int u = std::clamp(static_cast<int>(std::lround(probes_[i][0])), 0, frame.width - 1);
    const double v = probes_[i][1];
    const int w = std::max(1, static_cast<int>(std::lround(rows_.width_px(v))));
    const int centre = static_cast<int>(std::lround(v));
    auto mean = [&](int side) {
      int sum = 0, count = 0;
      for (int d = w; d <= 4 * w; ++d) {
        const int r = centre + side * d;
        if (r < 0 || r >= frame.height) continue;
        sum += frame.at(u, r);
        ++count;
      }
      return count > 0 ? static_cast<float>(sum) / static_cast<float>(count) : -1.0f;
    };
    const float in_front = mean(near), behind = mean(-near);
    if (in_front < 0 || behind < 0 || centre < 0 || centre >= frame.height) continue;
    excess[n] = in_front - behind;
    line[n] = static_cast<float>(frame.at(u, centre)) - behind;
    ++n;
  }
  if (n == 0) return false;
  // Along three quarters of the line at least: texture beside the line is brighter in front of it
  // at about half the points, and the median of a few dozen such differences can be well above
  // zero (a fan narrower than the image, a short line); a glow is there all along.
  const auto middle = static_cast<std::ptrdiff_t>(n / 2),
             quarter = static_cast<std::ptrdiff_t>(n / 4);
  std::nth_element(excess.begin(), excess.begin() + quarter, excess.begin() + n);
  std::nth_element(line.begin(), line.begin() + middle, line.begin() + n);
  return excess[quarter] > 0.25f * std::max(line[middle], 1.0f);
}

void Frontend::find_candidates(Profile& out) {
  collect_candidates(out);
  select_line(out);
}

void Frontend::collect_candidates(Profile& out) {
  out.clear();
  glowing_ = water_glows(current_);
  roll(nullptr);  // (and line_candidates_, see line_candidates())
  const int per_column = options_.max_candidates_per_column;
  const bool all_rows = region_.whole();
  for (int u = 0; u < width_; ++u) {
    const LineCandidate* line = line_candidates_.data() + static_cast<std::size_t>(u) * per_column;
    const int n = column_count_[u];
    for (int i = 0; i < n; ++i) {
      // Outside the region's rows, those the refinement can bring into them (kept until then).
      if (!all_rows) {
        const double v = line[i].position;
        const double reach = refine_reach(v);
        if (v < candidate_row_begin_ - 0.5 - reach || v >= candidate_row_end_ - 0.5 + reach) {
          continue;
        }
      }
      ProfilePoint point;
      point.u = u;
      point.v = line[i].position;
      point.snr_db = line[i].snr_db;
      point.valid = true;  // eligible, until validation or the line selection says otherwise
      if (!out.add(point)) break;
    }
  }
  collected_ = out.size();
}

void Frontend::line_candidates(int first, int end) {
  const int per_column = options_.max_candidates_per_column;
  for (int u = first; u < end; ++u) {
    Peak* best = column_best_.data() + static_cast<std::size_t>(u) * per_column;
    LineCandidate* line = line_candidates_.data() + static_cast<std::size_t>(u) * per_column;
    const int n = column_count_[u];
    // By row (normalised rows grow with the original rows).
    std::sort(best, best + n, [](const Peak& a, const Peak& b) { return a.r < b.r; });
    for (int i = 0; i < n; ++i) {
      // The band-pass peak's row, good to about half a laser width: only the chosen point gets
      // the sub-pixel fit (the costly part of this stage, done for all columns at the end).
      line[i].position = rows_.to_source_single(best[i].r);
      line[i].snr_db = kDecibelsPerNeper * std::log(best[i].snr);  // 20 log10 (cheaper)
      line[i].amplitude_db = kDecibelsPerNeper * std::log(std::max(best[i].band, 1e-3f));
    }
  }
}

void Frontend::select_line(Profile& out) {
  // The eligible candidates of each column, in the order collect_candidates() added them.
  const int per_column = options_.max_candidates_per_column;
  std::fill(eligible_count_.begin(), eligible_count_.end(), 0);
  const std::span<ProfilePoint> points = out.mutable_points();
  const std::size_t collected = std::min(collected_, points.size());
  for (std::size_t k = 0; k < collected; ++k) {
    ProfilePoint& p = points[k];
    if (!p.valid || p.u < 0 || p.u >= width_) continue;
    const auto u = static_cast<std::size_t>(p.u);
    const std::size_t slot = u * static_cast<std::size_t>(per_column) + eligible_count_[u];
    if (eligible_count_[u] == per_column) continue;  // (never: one column gives at most that)
    const LineCandidate* line = line_candidates_.data() + u * static_cast<std::size_t>(per_column);
    // The candidate itself: its column's candidates were added in order, by position.
    for (int i = 0; i < column_count_[u]; ++i) {
      if (line[i].position == p.v) {
        eligible_[slot] = line[i];
        break;
      }
    }
    eligible_point_[slot] = k;
    ++eligible_count_[u];
    p.valid = false;
  }
  // One laser point per epipolar line; the others stay in the profile, not valid.
  selector_.select(eligible_, eligible_count_, static_cast<float>(options_.snr_threshold_db),
                   chosen_);
  std::size_t waiting = 0;  // valid points waiting for their sub-pixel row
  for (int u = 0; u < width_; ++u) {
    const int i = chosen_[static_cast<std::size_t>(u)];
    if (i < 0) continue;
    const std::size_t k =
        eligible_point_[static_cast<std::size_t>(u) * static_cast<std::size_t>(per_column) +
                        static_cast<std::size_t>(i)];
    points[k].valid = true;
    refine_columns_[waiting] = u;
    refine_guesses_[waiting] = points[k].v;
    refine_points_[waiting] = k;
    ++waiting;
  }
  refine(points, waiting);
  // Where the line is now: where the next frame's threshold is lower (hysteresis), where it looks
  // for the glow (and the background detector measures the motion across the line).
  std::fill(previous_line_.begin(), previous_line_.end(), kNoPreviousLine);
  for (std::size_t k = 0; k < waiting; ++k) {
    const ProfilePoint& p = points[refine_points_[k]];
    previous_line_[static_cast<std::size_t>(p.u)] = p.v;
  }
  if (waiting > 0) {
    const std::size_t step = std::max<std::size_t>(1, waiting / kProbes);
    probe_count_ = 0;
    for (std::size_t k = 0; k < waiting && probe_count_ < kProbes; k += step) {
      const ProfilePoint& p = points[refine_points_[k]];
      probes_[probe_count_++] = {static_cast<float>(p.u), p.v};
    }
  }
  if (!region_.whole()) {
    // The region's rows exactly, now that the points are where they are.
    out.keep_if([&](const ProfilePoint& p) {
      const double row = std::round(static_cast<double>(p.v));
      return row >= candidate_row_begin_ && row < candidate_row_end_;
    });
  }
}

}  // namespace laserline::pipeline
