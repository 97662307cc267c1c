// The laser line's width in frames against the width the calibration predicts, for tools that
// extract with someone else's calibration (laserline-extract).
#pragma once

#include <cstddef>
#include <opencv2/core.hpp>
#include <vector>

#include "pipeline/geometry.hpp"
#include "pipeline/profile.hpp"

namespace laserline::tools {

// The front end rescales each epipolar line so that a line of the predicted width f l_w / Z
// becomes normalised_width_px wide (paper III-B) and sizes its band-pass for that; a real line is
// often much wider (focus, bloom) or narrower than a sheet width given as a guess, and a band-pass
// sized for another width answers it weakly. The width measured is the line's full width at half
// maximum along its epipolar line at the profile's valid points (where its core is not clipped),
// as laserline-calibrate measures the sheet width: the ratio of measured to predicted widths is
// what the sheet width l_w is to be scaled by.
class LineWidthMeter {
 public:
  LineWidthMeter(const pipeline::ScannerGeometry& geometry, int saturation_level);

  // Measures at the valid points of `profile`, found in `frame` (mono8: the laser's channel as
  // the detector searched it, before any background subtraction).
  void add(const cv::Mat& frame, const pipeline::Profile& profile);
  // Points measured so far.
  std::size_t measured() const { return ratios_.size(); }
  // Measured / predicted width, the median over the points measured; 0 before any.
  double ratio() const;

 private:
  pipeline::ScannerGeometry geometry_;
  int saturation_level_;
  mutable std::vector<double> ratios_;
};

}  // namespace laserline::tools
