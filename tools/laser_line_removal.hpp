// The laser line in an image of the checkerboard: taken out (so that the corners under it can be
// found), its width measured, its straight course found; what the plane calibration and the
// removal share.
#pragma once

#include <cstddef>
#include <opencv2/core.hpp>
#include <vector>

namespace laserline::tools {

// The laser line taken out of a laser-on image so that the checkerboard under it can be found:
// `points` are the line's points as detectors found them (raw pixels, any order; points off the
// line are outliers) in `laser` (the laser's light), `board` the image the board is searched in
// (mono8, same size). The line, in any direction, is followed as a straight line bent by the lens
// (a polynomial across it); it must stand out of its surroundings on both sides in `laser` (a
// step or a row of squares' edges does not). Its width is measured in `board` across it, and
// only that band is filled in `out` (a copy of `board`), each pixel interpolated along the
// line's normal between the pixels just beyond the band on either side: the squares' edges that
// cross the line continue across it; what ran along the line inside the band is lost (see
// `band`). `points` is 0 when no line was found (fewer than a dozen points on one, or not
// standing out): `out` is then `board` unchanged.
struct LineRemoval {
  int points = 0;                    // the points followed
  double half_width_px[2] = {0, 0};  // the band filled on either side of the line's centre
  cv::Mat band;                      // mono8, 255 where filled (empty when nothing was)
};
LineRemoval remove_laser_line(const cv::Mat& board, const cv::Mat& laser,
                              const std::vector<cv::Point2d>& points, cv::Mat& out);

// The straight line through most `points` (within `tolerance` pixels), by RANSAC with a fixed
// seed then least squares; returns the inliers' indices.
std::vector<std::size_t> straight_line_inliers(const std::vector<cv::Point2d>& points,
                                               double tolerance);

// The line's full width at half maximum across it at `p`, in pixels, along the unit `normal`:
// its peak within `peak_within_px` of `p`, each side's floor where the profile stops falling, and
// each side measured half way down to its own floor (a glow in front of the line or a brighter
// surface beside it raises one side's). NaN where the core is clipped (at or above `saturation`:
// the width at half of a clipped height is too wide), or where the profile does not fall to half on
// both sides within kMaxHalfWidthPx.
double full_width_at_half_maximum(const cv::Mat& image, cv::Point2d p, cv::Point2d normal,
                                  double saturation, double peak_within_px = 1.0);

// A grey level of a mono8 image between pixels (bilinear), the image's edge extended. The image
// is at least 2x2.
double sample_bilinear(const cv::Mat& image, double x, double y);

}  // namespace laserline::tools
