#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "pipeline/geometry.hpp"
#include "pipeline/image_view.hpp"

namespace laserline::pipeline {

// Which way the epipolar lines (the lines along which a detector looks for the laser) run in the
// image. The paper's mounting (projector above or below the camera) gives columns; a projector
// beside the camera gives rows; a turned one, lines at an angle.
enum class SearchAxis : std::uint8_t { kColumns, kRows, kOblique };
const char* to_string(SearchAxis axis);

// A detector's search coordinates: (line, position), `line` indexing the epipolar lines and
// `position` running along one, mapped affinely to image pixels (pixel centres at integers):
//   image = origin + line * line_step + position * along.
// Columns: line = column, position = row (the identity). Rows: line = row, position = column (the
// transpose). Oblique: a rotation of the pixel grid, line_step and along unit vectors.
struct SearchAxes {
  SearchAxis axis = SearchAxis::kColumns;
  std::array<double, 2> origin{0.0, 0.0};
  std::array<double, 2> line_step{1.0, 0.0};
  std::array<double, 2> along{0.0, 1.0};
  int lines = 0;   // epipolar lines: the search image's width
  int length = 0;  // positions along a line: the search image's height

  std::array<double, 2> to_image(double line, double position) const {
    return {origin[0] + line * line_step[0] + position * along[0],
            origin[1] + line * line_step[1] + position * along[1]};
  }
  // The inverse map (line_step and along are orthonormal).
  std::array<double, 2> to_search(double x, double y) const {
    const double dx = x - origin[0], dy = y - origin[1];
    return {dx * line_step[0] + dy * line_step[1], dx * along[0] + dy * along[1]};
  }
  bool identity() const { return axis == SearchAxis::kColumns; }

  // The paper's mounting for a width x height image.
  static SearchAxes columns(int width, int height);
};

// Within this angle of an image axis, epipolar lines are searched along the axis itself (at most
// 1 - cos 5deg = 0.4 % more line width to cross, and no resampling).
inline constexpr double kAxisToleranceDeg = 5.0;

// The search axes of a scanner. Epipolar lines run along the gradient of the laser sheet's
// inverse depth over the image (the direction in which a point on the sheet moves when its depth
// changes, i.e. from the projector's image through the line): columns when it is within
// kAxisToleranceDeg of the image's v axis, rows when within it of the u axis, else oblique, the
// search image a rotation of the frame that holds the whole frame.
SearchAxes choose_search_axes(const ScannerGeometry& geometry);

// The scanner as seen in search coordinates, for the detectors: columns the same; rows the
// transposed camera (fx and fy, cx and cy, p1 and p2 swapped; the sheet's a and b swapped: exact);
// oblique the camera rolled about its optical axis with focal length sqrt(fx fy) and the sheet's
// inverse depth over the search image exactly that over the frame.
ScannerGeometry search_geometry(const ScannerGeometry& geometry, const SearchAxes& axes);

// Makes the search image of a frame: the frame itself (columns), its transpose (rows, 16 x 16
// blocks) or its bilinear resampling on the rotated grid (oblique; positions outside the frame
// take its nearest edge, so that its border is no edge). reset() allocates; make() does not.
// Thread context: one thread at a time per instance.
class SearchImage {
 public:
  void reset(const SearchAxes& axes, int width, int height);
  // The search image of `frame` (width x height as reset); valid until the next make().
  ImageView make(const ImageView& frame);

 private:
  struct Grid {
    std::int64_t x0, y0, x_line, y_line, x_along, y_along, x_max, y_max;
  };
  Grid grid() const;
  void resample(const ImageView& frame);

  SearchAxes axes_;
  int width_ = 0, height_ = 0;
  std::vector<std::uint8_t> pixels_;
  std::vector<std::uint8_t> first_column_, last_column_;  // oblique: the frame's side edges
};

}  // namespace laserline::pipeline
