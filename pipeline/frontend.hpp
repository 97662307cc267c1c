#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "pipeline/detector.hpp"
#include "pipeline/geometry.hpp"
#include "pipeline/image_view.hpp"
#include "pipeline/motion.hpp"
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
  // Laser width in original pixels at original row v.
  double width_px(double v) const { return alpha_ + beta_ * v; }

 private:
  double alpha_ = 0, beta_ = 0;  // l(v) = alpha + beta v
  double scale_ = 1;             // normalised width W
  double r0_ = 0;                // normalised row offset
  std::vector<float> source_row_;
};

// The front-end of Section III on one frame, as separately callable stages over preallocated
// buffers of the normalised size (row-major, `stride()` values per row; the normalised image is
// kept as 32-bit column prefix sums in 1/256 grey level, the band-pass as floats):
//   normalise() or normalise_subtracting()  III-A/B  -> normalised_at()
//   band_pass()                             III-C    -> band_passed()
//   find_candidates()                       III-D/E  -> Profile in original coordinates
// III-D is evaluated only where it matters: a pixel can pass the threshold only where the
// band-pass itself exceeds it (the noise is at least 1), so the SNR is computed at the band-pass
// peaks. snr_at() is the one formula; signal_to_noise_image() applies it everywhere, for pictures
// and tests. reset() allocates; the stages do not. Thread context: one thread at a time.
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
  void reset(int width, int height);

  // III-B on the frame itself (the `fir` detector).
  void normalise(const ImageView& current);
  // III-A + B: the frame minus the background frame seen through `current_to_background` (a
  // pixel of the current frame to where the same scene point was in the background frame),
  // resampled to normalised rows in one pass. Negative differences (the background was brighter:
  // the laser of the previous frame, or texture moving in) are clipped to 0: the laser only adds
  // light. The background may be any image (e.g. a band of rows of the previous frame): the
  // homography says where a current pixel is in it. The warp is evaluated exactly once per block
  // of kWarpBlock pixels and as a translation within it (error bound at kWarpBlock).
  void normalise_subtracting(const ImageView& current, const ImageView& background,
                             const Homography& current_to_background);
  void band_pass();
  // Local maxima of the band-pass along each column whose SNR passes the threshold, at most
  // max_candidates_per_column (the strongest). The strongest is the valid point, refined to a
  // sub-pixel row in the original image (Gaussian 3-point fit on the background-free column; the
  // centre of the run where the core is clipped); the others are not valid and keep the row of
  // their band-pass peak, good to half a laser width. Uses the frames given to the last
  // normalise call; they must still be valid.
  void find_candidates(Profile& out);

  int width() const { return width_; }
  int stride() const { return stride_; }
  float normalised_at(int r, int u) const;
  std::span<const float> band_passed() const { return band_passed_; }
  // III-D: band-pass over the mean |band-pass| around the pixel (a guard band around it left
  // out), the noise at least 1. Amplitude ratio.
  float snr_at(int r, int u) const;
  // snr_at() for every pixel into `out` (rows() x stride() floats).
  void signal_to_noise_image(std::span<float> out) const;

  // Pixels warped as one block. Within a block the warp is a translation: exact to
  // kWarpBlock / 2 * max(|d(x - u)/du|, |dy/du|), 0.05 px for a roll of 0.2 degrees between frames.
  static constexpr int kWarpBlock = 32;

 private:
  float refine_row(int u, float v_guess) const;

  ScannerGeometry geometry_;
  FrontendOptions options_;
  RowNormalisation rows_;
  int inner_ = 3, outer_ = 9;  // band-pass boxes, normalised rows (odd)
  int guard_ = 5, noise_half_ = 15, noise_pad_ = 4;
  float noise_norm_ = 1;
  int width_ = 0, height_ = 0, stride_ = 0;

  // Inputs of the last normalise call (views, valid during the call to find_candidates).
  ImageView current_{};
  ImageView background_{};
  bool subtracting_ = false;
  Homography to_background_;

  // (rows() + 1) x stride_: column prefix sums of the normalised image, 1/256 grey levels
  std::vector<std::int32_t> prefix_;
  std::vector<float> band_passed_;       // rows() x stride_
  std::vector<float> abs_prefix_;        // (rows() + 1) x stride_: column prefix sums of |band|
  std::vector<std::uint32_t> row_mask_;  // one row: band-pass peaks above the threshold
  struct Peak {
    float v = 0;     // first guess of the original row
    float snr = 0;   // amplitude ratio
    float band = 0;  // band-pass amplitude
  };
  std::vector<Peak> column_best_;  // max_candidates_per_column per column
  std::vector<std::uint8_t> column_count_;
};

}  // namespace laserline::pipeline
