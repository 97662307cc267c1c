#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <type_traits>
#include <vector>

#include "pipeline/detector.hpp"
#include "pipeline/geometry.hpp"
#include "pipeline/image_view.hpp"
#include "pipeline/line_selection.hpp"
#include "pipeline/motion.hpp"
#include "pipeline/parts.hpp"
#include "pipeline/profile.hpp"

namespace laserline::pipeline {

// Paper III-B, in the OpenCV convention (v down). The projected sheet width is linear in the row,
// l(v) = f l_w / Z(v) = alpha + beta v, so rescaling the rows by s(v) = W / l(v) makes it W pixels
// everywhere; integrated, the normalised row is r(v) = (W / beta) ln(l(v)) + r0: logarithmic.
// Only rows where the sheet lies within [min_depth, max_depth] are kept (elsewhere the laser
// cannot appear), plus `margin` normalised rows on each side for the filters.
class RowNormalisation {
 public:
  RowNormalisation() = default;
  // Throws std::invalid_argument when the geometry puts no row of the image in the depth range, or
  // the sheet does not cross the image columns.
  RowNormalisation(const ScannerGeometry& geometry, const FrontendOptions& options, int margin);

  int rows() const { return static_cast<int>(source_row_.size()); }
  // Original row (fractional) of normalised row r, clamped to the image.
  float source_row(int r) const { return source_row_[static_cast<std::size_t>(r)]; }
  // The exact mapping both ways, for fractional rows (not clamped).
  double to_source(double r) const;
  double to_normalised(double v) const;
  // to_source() in single precision (good to ~1e-3 pixel), at a fraction of the cost: for
  // candidates, thousands per frame.
  float to_source_single(float r) const;
  // Laser width in original pixels at original row v.
  double width_px(double v) const {
    const double sheet = alpha_ + beta_ * v;
    return std::sqrt(sheet * sheet + blur_ * blur_);
  }
  // +1 when rows further down see the sheet nearer the camera, -1 when further up: the side of the
  // line where the laser lights the water in front of the surface.
  int near_side() const { return beta_ > 0 ? 1 : -1; }

 private:
  double alpha_ = 0, beta_ = 0;  // l(v) = alpha + beta v
  double blur_ = 0;              // FrontendOptions::line_blur_px
  double scale_ = 1;             // normalised width W
  double r0_ = 0;                // normalised row offset
  float single_alpha_ = 0, single_inverse_beta_ = 1, single_rate_ = 0, single_r0_ = 0;
  float single_blur_ = 0;
  std::vector<float> source_row_;
};

// The front-end of Section III on one frame. set_frame() or set_frame_minus_background() names
// the input (III-A: the frame, or the frame minus the motion-compensated background); then
// find_candidates() runs III-B to III-E in one pass down the normalised rows, each stage a row
// kernel over small rings of rows that stay in the cache:
//   normalised row r       III-B: frame (minus background) resampled to normalised row r
//   band-pass row r        III-C: inner minus outer box mean down the columns (running sums)
//   noise of row r         III-D: mean |band-pass| around the pixel, a guard band left out
//                          (summed from the band-pass ring at candidates only)
//   candidates of row r    III-E: band-pass peaks whose SNR passes the threshold (only pixels
//                          whose band-pass reaches it can: the noise is at least 1) and that are
//                          ridges (the band-pass negative on both sides: a line, not an edge;
//                          where the water glows, on the far side: the line ends the glow)
// The band-pass of row r needs the normalised rows up to r + outer/2 and the noise of row r the
// band-pass rows up to r + noise_rows/2, so the pass runs that far ahead. stage_images() runs the
// same pass and keeps every row of the three intermediate images, for tests and pictures.
// reset() allocates; the stages do not. Thread context: one thread at a time.
class Frontend {
 public:
  Frontend(const ScannerGeometry& geometry, const FrontendOptions& options);

  const FrontendOptions& options() const { return options_; }
  const RowNormalisation& rows() const { return rows_; }
  // Most points find_candidates() can give for a frame this wide.
  std::size_t max_points(int width) const {
    return static_cast<std::size_t>(width) *
           static_cast<std::size_t>(options_.max_candidates_per_column);
  }
  // Splits the pass down the rows (III-B to E) and the refinement (III-F) of each frame into
  // runner.parts() parts, each a range of strips of columns; before reset(), which sizes each
  // part's buffers. The runner must outlive the front end's use. Default: one part.
  void use_parts(PartRunner& runner) { runner_ = &runner; }
  void reset(int width, int height);

  // III-B on the frame itself (the `fir` detector). The view must stay valid until the last call
  // that reads it (find_candidates(), stage_images()).
  void set_frame(const ImageView& current);
  // III-A + B: the frame minus the background frame seen through `current_to_background` (a
  // pixel of the current frame to where the same scene point was in the background frame).
  // Negative differences (the background was brighter: the laser of the previous frame, or
  // texture moving in) are clipped to 0: the laser only adds light. The background may be any
  // image (e.g. a band of rows of the previous frame): the homography says where a current pixel
  // is in it. The warp is evaluated exactly once per block of kWarpBlock pixels and as a
  // translation within it (error bound at kWarpBlock). fit_with_background false: the sub-pixel
  // fit reads the frame itself (a background whose own line was taken out holds an estimate of
  // the surface under that line, good enough to find the line against, not to centre it).
  void set_frame_minus_background(const ImageView& current, const ImageView& background,
                                  const Homography& current_to_background,
                                  bool fit_with_background = true);

  // Candidates only in `region` (search coordinates; DetectionRegion::whole(): everywhere), from
  // the next pass on: only its columns are searched, and only the normalised rows that reach its
  // rows; the filters read the rows and columns around it as on the whole frame, so that the
  // candidates inside are those the whole frame gives. No allocation.
  void set_region(const DetectionRegion& region);
  DetectionRegion region() const {
    return region_.in_frame(width_ > 0 ? width_ : geometry_.width,
                            height_ > 0 ? height_ : geometry_.height);
  }

  // Local maxima of the band-pass along each column whose SNR passes the threshold, at most
  // max_candidates_per_column (the strongest). At most one per column is the valid point, chosen
  // by the line selection (pipeline/line_selection.hpp: SNR, continuity along the line and with
  // the previous frame's choice), refined to a sub-pixel row in the original image (Gaussian
  // 3-point fit on the background-free column; the centre of the run where the core is clipped);
  // the others are not valid and keep the row of their band-pass peak, good to half a laser width.
  void find_candidates(Profile& out);
  // find_candidates() in two steps, for a validation in between (paper IV): every candidate into
  // `out` at its band-pass peak's row, all marked valid (eligible); then the line selection among
  // those still valid, the chosen ones refined. `out` must be the profile collect_candidates()
  // filled, its points in the same order.
  void collect_candidates(Profile& out);
  void select_line(Profile& out);
  // Forgets the previous frame's candidates, which the line selection favours, and where its
  // line was (for tests that run the same frame twice).
  void forget_previous_frame() {
    selector_.forget();
    probe_count_ = 0;
    std::fill(previous_line_.begin(), previous_line_.end(), kNoPreviousLine);
  }

  // Whether the water in front of the surface glows (backscatter) in `frame` (the original
  // frame), next to where the line was last found: a brightness that ends at the line on its near
  // side (the side where the sheet is nearer the camera) for at least half the line's contrast.
  // Texture is as bright on either side. Then the line is the end of a step rather than a ridge.
  bool water_glows(const ImageView& frame) const;
  // Where the line was last found (search coordinates: column, row), at most kProbes points.
  static constexpr std::size_t kProbes = 32;
  std::span<const std::array<float, 2>> probes() const { return {probes_.data(), probe_count_}; }

  // The intermediate images of the frame set last, rows() x stride() floats each (any may be
  // empty, then it is not kept): normalised image (grey levels), band-pass (III-C), SNR (III-D:
  // band-pass over the mean |band-pass| around the pixel, a guard band left out, the noise at
  // least 1; amplitude ratio).
  void stage_images(std::span<float> normalised, std::span<float> band_pass,
                    std::span<float> signal_to_noise);

  // The band-pass is exact in units of this many grey levels (an integer multiple of it); where a
  // box is cut short by an end of the rows it is rounded to it.
  float band_pass_unit() const { return band_unit_; }

  int width() const { return width_; }
  int stride() const { return stride_; }

  // Pixels warped as one block. Within a block the warp is a translation: exact to
  // kWarpBlock / 2 * max(|d(x - u)/du|, |dy/du|), 0.05 px for a roll of 0.2 degrees between frames.
  static constexpr int kWarpBlock = 32;

 private:
  // Where a pass goes: candidates in columns [column_begin, column_end) and normalised rows
  // [row_begin, row_end); normalised rows made over columns [normalise_begin, normalise_end)
  // (whole warp blocks).
  struct PassBounds {
    int column_begin = 0, column_end = 0, row_begin = 0, row_end = 0;
    int normalise_begin = 0, normalise_end = 0;
  };
  PassBounds whole_bounds() const;
  void update_bounds();
  // How far (original rows) the refinement can move a candidate at row v.
  double refine_reach(double v) const;
  struct StageImages;
  // The pass down the rows: candidates into column_best_ / column_count_, and the intermediate
  // rows into `images` where given, in 16- or 32-bit band-pass lanes (see the constructor); then
  // line_candidates() of every column.
  void roll(const StageImages* images);
  // The candidates of columns [first, end) by row, as the line selection sees them.
  void line_candidates(int first, int end);
  // work(part) for each part: by the runner, or one after another when the runner does not run
  // the parts reset() sized for (one part, or a runner given after reset()).
  template <class Work>
  void run_parts(Work& work) {
    if (parts_.size() > 1 && runner_->parts() == static_cast<int>(parts_.size())) {
      runner_->run(PartWork(work));
    } else {
      for (std::size_t p = 0; p < parts_.size(); ++p)
        work(static_cast<int>(p));
    }
  }
  void roll_narrow(const StageImages* images, const PassBounds& bounds, int part);
  void roll_wide(const StageImages* images, const PassBounds& bounds, int part);
  // What one part of the pass owns: its strips [first_strip, end_strip) (its columns; the pass's
  // strips split between the parts, place_parts()), the warp blocks [first_block, end_block)
  // whose normalised columns its strips read (within the pass's), and its own rings and scratch
  // rows (the columns it reads beyond its own are made again by each part).
  struct Part {
    int first_strip = 0, end_strip = 0, first_block = 0, end_block = 0;
    std::vector<std::uint16_t> normalised_ring;  // 8 - normalised_shift_ fractional bits
    // Per warp block of the row being normalised: where its first pixel lies in the background
    // (integer column and row), whether the block lies wholly inside it, the offset of its first
    // pixel's in the background where whole, its four bilinear weights (top left, top right,
    // bottom left, bottom right).
    std::vector<std::int32_t> warp_left, warp_top, warp_whole, warp_offset;
    std::array<std::vector<std::int32_t>, 4> warp_weights;
    // Per block of rows: where each row it touches is (offsets into a strip's rings, pointers to
    // the normalised rows), from the first it touches on.
    std::vector<std::size_t> band_rows;
    std::vector<int> band_slots;  // the band-pass rows' slots (band_rows = slot * ring stride)
    std::vector<const std::uint16_t*> normalised_rows;
    std::vector<std::uint64_t> peak_bits;  // one row of a strip's candidates, as bits
    // One row of a strip's peaks that would be kept, awaiting their noise level: their ring
    // column, the slot they would take, their rank, whether clipped; their noise window's first
    // ring column and its sums above and below the row (kernels::window_sums()).
    std::vector<std::int32_t> peak_column, peak_slot, peak_clipped;
    std::vector<float> peak_rank;
    std::vector<std::int32_t> window_first;
    std::vector<std::uint64_t> window_sum_above, window_sum_below;
  };
  // Each part's strips and warp blocks for a pass within `bounds` (no allocation).
  void place_parts(const PassBounds& bounds);
  // The strips' band-pass rows and running box sums (modulo 2^bits).
  template <class Lane>
  struct BandRings {
    std::vector<Lane> band;
    std::vector<std::make_unsigned_t<Lane>> inner, outer;
    void assign(std::size_t band_size, std::size_t sums_size) {
      band.assign(band_size, 0);
      inner.assign(sums_size, 0);
      outer.assign(sums_size, 0);
    }
  };
  template <class Lane>
  void roll_with(const StageImages* images, const PassBounds& bounds, BandRings<Lane>& rings,
                 Part& part);
  // Its stages (see frontend.cpp): the pass's settings, the normalised rows (III-B), where a
  // block's rows are, a strip's band-pass rows (III-C), a row's candidates (III-D/E).
  template <class Lane>
  struct RollPass;
  template <class Lane>
  struct StripRows;
  template <class Lane>
  RollPass<Lane> roll_pass() const;
  std::uint16_t* normalised_slot(Part& part, int r);
  const std::uint16_t* normalised_at(Part& part, int r, int rows);
  void normalise_until(Part& part, int last, int rows, float normalised_one, int& next,
                       const StageImages* images);
  void place_block_rows(Part& part, int rows, int band_base, int band_top, int normalised_base,
                        int normalised_top);
  template <class Lane>
  void band_pass_rows(const RollPass<Lane>& pass, const StripRows<Lane>& strip, int first, int end,
                      const StageImages* images);
  template <class Lane>
  int lowest_beside(const RollPass<Lane>& pass, const StripRows<Lane>& strip, int r, int i,
                    int side, int enough) const;
  template <class Lane>
  void row_candidates(const RollPass<Lane>& pass, const StripRows<Lane>& strip, int r,
                      const StageImages* images);
  // The columns of normalised row r the part's warp blocks cover into out (column 0 at out[0]).
  void normalise_row(Part& part, int r, std::uint16_t* out);
  // The noise window of a row less its guard band: `rows` rows from each of `above` and `below`
  // (offsets of the rows in a strip's band-pass ring); whether both lie within the frame's rows
  // (beyond them the band-pass is 0: no quieter side).
 public:
  struct NoiseWindow {
    const std::size_t* above;
    const std::size_t* below;
    int rows;
    bool inside;
  };

 private:
  // III-D at column u (`ring` holding columns from `begin` on): the mean |band-pass| over the
  // window around it, at least 1.
  template <class Lane>
  float noise_level(const Lane* ring, const NoiseWindow& window, int u, int begin) const;
  // The noise window's sum from the sums of its rows above and below the pixel: both, or twice
  // the quieter where one is noise_side_ratio times the other (an edge on one side: a
  // checkerboard's square, the rim of a bright patch) and both sides lie inside the frame.
  std::uint64_t noise_sum(std::uint64_t above, std::uint64_t below, bool inside) const {
    if (inside && noise_side_ratio_ > 0.0 &&
        (static_cast<double>(above) > noise_side_ratio_ * static_cast<double>(below) ||
         static_cast<double>(below) > noise_side_ratio_ * static_cast<double>(above)))
      return 2 * std::min(above, below);
    return above + below;
  }
  // The sub-pixel row of the valid point of column u, from its guess (see find_candidates()).
  struct RefineStart;
  RefineStart refine_start(float v_guess) const;
  float refine_row(int u, float v_guess) const;
  // Whether (u, v) lies in a clipped laser core: a run of pixels at or above the saturation level
  // along column u no longer than kClippedCoreWidths laser widths. A longer run is a bright patch
  // clipped by the exposure (texture, a lamp's reflection): its ends are edges, not a line.
  bool in_clipped_core(int u, int v) const;
  // Whether (u, v) or a pixel beside it along column u is at or above the saturation level: a
  // peak there is centred on its clipped run by the refinement (whose window reaches it).
  bool touches_clipped_run(int u, int v) const;
  static constexpr double kClippedCoreWidths = 2.5;
  static constexpr float kClippedCoreRank = 1e6f;  // above any band-pass amplitude
  // refine_row() of the first `count` points waiting for it (refine_columns_, ...): into the
  // profile's points.
  void refine(std::span<ProfilePoint> points, std::size_t count);
  void refine_range(std::span<ProfilePoint> points, std::size_t first, std::size_t end);

  ScannerGeometry geometry_;
  FrontendOptions options_;
  RowNormalisation rows_;
  int inner_ = 3, outer_ = 9;  // band-pass boxes, normalised rows (odd)
  int guard_ = 5, noise_half_ = 15, noise_pad_ = 4;
  int reach_ = 2;         // a candidate is the maximum within this many rows up and down
  int ridge_ = 5;         // ... and the band-pass goes negative within this many rows of its zero
  bool glowing_ = false;  // the frame's water glows in front of the line (water_glows())
  std::array<std::array<float, 2>, kProbes> probes_{};
  std::size_t probe_count_ = 0;
  // Per epipolar line: the previous frame's point on it (original pixels), where the SNR
  // threshold is lower by snr_hysteresis_db; kNoPreviousLine none.
  static constexpr float kNoPreviousLine = std::numeric_limits<float>::quiet_NaN();
  std::vector<float> previous_line_;
  int margin_ = 6;  // normalised rows beyond the depth range on each side (for the filters)
  float noise_norm_ = 1;
  double noise_side_ratio_ = 0;
  double half_per_normalised_width_ = 0.5;  // 0.5 / normalised_width_px (refine_row())
  // The band-pass, in units of band_unit_ grey levels: band_a_ S_inner - band_b_ S_outer of the
  // normalised rows, which keep 8 - normalised_shift_ fractional bits; 16-bit lanes where it fits.
  int band_a_ = 3, band_b_ = 1, normalised_shift_ = 4;
  float band_unit_ = 1;
  bool narrow_band_ = true;
  int width_ = 0, height_ = 0, stride_ = 0;

  DetectionRegion region_;  // as set (search coordinates)
  PassBounds bounds_;       // of region_ in frames of the size reset() was given
  // Original rows whose candidates are kept: [candidate_row_begin_, candidate_row_end_).
  double candidate_row_begin_ = 0, candidate_row_end_ = 0;

  // Inputs of the last set_frame call (views, valid during find_candidates).
  ImageView current_{};
  ImageView background_{};
  bool subtracting_ = false;
  bool fit_with_background_ = false;  // subtracting_, and the fit reads the background too
  Homography to_background_;

  // The pass goes down the rows in blocks of kRowBlock and, within a block, across the image in
  // strips of kStripColumns: a strip's band-pass ring (about 38 rows, 21 KB) and the sums being
  // written then stay in the first-level cache while the block's rows are done. (Measured: 256
  // columns beat 128, whose work per row and strip weighs more, and 512; going down a whole strip
  // before the next, the normalised rows made strip by strip, was slower still.)
  static constexpr int kRowBlock = 8;
  static constexpr int kStripColumns = 256;
  // Rings of rows, indexed by row % ring rows: the normalised rows (normalised_stride_ values per
  // row), and per strip the band-pass rows (ring_stride_ values per row, and after the last row a
  // row of zeros); the per-strip sums are as wide.
  int normalised_ring_rows_ = 0, band_ring_rows_ = 0, ring_stride_ = 0;
  std::size_t band_strip_size_ = 0;  // values of a strip's band-pass ring
  // Normalised rows: zeros on either side of the image's columns, `normalised_pad_` on the left.
  int normalised_pad_ = 0, normalised_stride_ = 0;
  PartRunner* runner_ = &one_part();
  std::vector<Part> parts_;
  BandRings<std::int16_t> narrow_;
  BandRings<std::int32_t> wide_;
  std::vector<int> band_most_;                  // per band-pass row of a strip: its largest value
  std::vector<std::uint16_t> zero_normalised_;  // a row of zeros: the rows beyond the ends
  struct Peak {
    float r = 0;     // normalised row of the band-pass peak (sub-row)
    float snr = 0;   // amplitude ratio
    float band = 0;  // band-pass amplitude
    float rank = 0;  // which candidates a full column keeps: the band-pass, clipped cores first
  };
  std::vector<Peak> column_best_;  // max_candidates_per_column per column
  std::vector<std::uint8_t> column_count_;
  // The candidates as the line selection sees them (by row within each column), its choice.
  std::vector<LineCandidate> line_candidates_;
  // The eligible ones (still valid in the profile when select_line() runs) by column, and where
  // each is in the profile.
  std::vector<LineCandidate> eligible_;
  std::vector<std::uint8_t> eligible_count_;
  std::vector<std::size_t> eligible_point_;
  std::size_t collected_ = 0;  // points collect_candidates() put in the profile
  std::vector<int> chosen_;
  LineSelector selector_;
  // The valid points waiting for refine_row(): column, guess, index in the profile.
  std::vector<int> refine_columns_;
  std::vector<float> refine_guesses_;
  std::vector<std::size_t> refine_points_;
  // Those refined together (kernels::refine_columns()): their columns, starts and lines through
  // the background (see refine()), results, and indices in the profile.
  struct RefineLanes {
    std::vector<std::int32_t> u, centre, lo, count, spacing, edge;
    std::vector<float> x0, y0, dx, dy, rows;
    std::vector<std::size_t> point;
  };
  RefineLanes refine_lanes_;
};

}  // namespace laserline::pipeline
