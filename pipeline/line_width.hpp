#pragma once

#include <cstddef>
#include <vector>

#include "pipeline/geometry.hpp"
#include "pipeline/image_view.hpp"
#include "pipeline/profile.hpp"
#include "pipeline/search_axes.hpp"

namespace laserline::pipeline {

// The laser line's width in frames against the width the calibration predicts. The front end
// rescales each epipolar line so that a line of the predicted width f l_w / Z becomes
// normalised_width_px wide (paper III-B) and its band-pass is sized for that width; a real line is
// often wider (focus, blur, bloom, a clipped core) or narrower than the sheet's thickness
// projected, and a band-pass sized for another width answers it weakly. The measured width is the
// full width at half maximum of the line's profile along its epipolar line at the profile's valid
// points, less what the pixels and the lens add to any line (in quadrature). The ratio of measured
// to predicted widths is what the sheet width l_w is scaled by for the filters.
// Not for the frame path: it keeps every measurement (tools, calibration).
class LineWidthMeter {
 public:
  explicit LineWidthMeter(const ScannerGeometry& geometry);

  // Measures at the valid points of `profile`, found in `frame` (the image the detector searched:
  // the laser's channel, before any background subtraction).
  void add(const ImageView& frame, const Profile& profile);
  // Points measured so far: their profile rose clearly above its surroundings and fell below half
  // its height on both sides within the window.
  std::size_t measured() const { return ratios_.size(); }
  // Measured / predicted width, the median over the points measured; 0 before any.
  double ratio() const;

 private:
  ScannerGeometry geometry_;
  mutable std::vector<double> ratios_;
  std::vector<float> samples_;
};

}  // namespace laserline::pipeline
