// The search axes (pipeline/search_axes.hpp): which way the epipolar lines run for a laser sheet,
// the scanner as seen in search coordinates, and the search image (the frame, its transpose or
// its bilinear resampling on a rotated grid). Every expectation is computed here from its own
// definition (ray-sheet intersection, the bilinear formula in double precision), never by the
// code under test.
#include "pipeline/search_axes.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "allocation_counter.hpp"

namespace laserline::pipeline {
namespace {

constexpr double kPi = std::numbers::pi;

// A camera with fx != fy and a sheet a X + b Y + c Z + e = 0 whose inverse depth changes over the
// image in the direction `degrees` from the image's v axis towards its u axis (times `sign`).
// c = -1, e = 0.5 and |a|, |b| <= 0.4 * sqrt(fx / fy): the sheet lies in front of the camera
// (0.3 m < Z < 1 m) over the whole frame.
ScannerGeometry geometry_at(double degrees, double sign = 1.0, int width = 640, int height = 480,
                            double fx = 1400, double fy = 1200) {
  ScannerGeometry g;
  g.width = width;
  g.height = height;
  g.fx = fx;
  g.fy = fy;
  g.cx = (width - 1) / 2.0 + 3.25;
  g.cy = (height - 1) / 2.0 - 1.5;
  const double f = std::sqrt(fx * fy), t = degrees * kPi / 180.0;
  g.laser_plane = {sign * 0.4 * std::sin(t) * fx / f, sign * 0.4 * std::cos(t) * fy / f, -1.0, 0.5};
  return g;
}

// The depth at which the ray through pixel (u, v) of the pinhole camera meets the sheet: the ray
// t (x, y, 1) with x = (u - cx) / fx, y = (v - cy) / fy satisfies a t x + b t y + c t + e = 0.
double sheet_depth(const ScannerGeometry& g, double u, double v) {
  const double a = g.laser_plane[0], b = g.laser_plane[1], c = g.laser_plane[2],
               e = g.laser_plane[3];
  const double x = (u - g.cx) / g.fx, y = (v - g.cy) / g.fy;
  return -e / (a * x + b * y + c);
}

// The gradient of the sheet's inverse depth over the pixels, by central differences (1/Z is
// affine in the pixel, so they are exact up to rounding).
std::array<double, 2> inverse_depth_gradient(const ScannerGeometry& g) {
  const double u = g.cx + 17.0, v = g.cy - 11.0, h = 8.0;
  return {(1.0 / sheet_depth(g, u + h, v) - 1.0 / sheet_depth(g, u - h, v)) / (2 * h),
          (1.0 / sheet_depth(g, u, v + h) - 1.0 / sheet_depth(g, u, v - h)) / (2 * h)};
}

// The angle in degrees between the line of the gradient and the image's v axis, in [0, 90].
double angle_from_v_axis(const std::array<double, 2>& gradient) {
  return std::atan2(std::abs(gradient[0]), std::abs(gradient[1])) * 180.0 / kPi;
}

void expect_columns(const SearchAxes& axes, int width, int height) {
  EXPECT_EQ(axes.axis, SearchAxis::kColumns);
  EXPECT_TRUE(axes.identity());
  EXPECT_EQ(axes.origin, (std::array<double, 2>{0.0, 0.0}));
  EXPECT_EQ(axes.line_step, (std::array<double, 2>{1.0, 0.0}));
  EXPECT_EQ(axes.along, (std::array<double, 2>{0.0, 1.0}));
  EXPECT_EQ(axes.lines, width);
  EXPECT_EQ(axes.length, height);
}

void expect_rows(const SearchAxes& axes, int width, int height) {
  EXPECT_EQ(axes.axis, SearchAxis::kRows);
  EXPECT_FALSE(axes.identity());
  EXPECT_EQ(axes.origin, (std::array<double, 2>{0.0, 0.0}));
  EXPECT_EQ(axes.line_step, (std::array<double, 2>{0.0, 1.0}));
  EXPECT_EQ(axes.along, (std::array<double, 2>{1.0, 0.0}));
  EXPECT_EQ(axes.lines, height);
  EXPECT_EQ(axes.length, width);
}

// The two maps are inverse to each other.
void expect_maps_invert(const SearchAxes& axes, int width, int height) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> x(-50.0, width + 50.0), y(-50.0, height + 50.0);
  for (int i = 0; i < 200; ++i) {
    const double px = x(rng), py = y(rng);
    const auto [line, position] = axes.to_search(px, py);
    const auto [bx, by] = axes.to_image(line, position);
    EXPECT_NEAR(bx, px, 1e-9);
    EXPECT_NEAR(by, py, 1e-9);
  }
}

void expect_oblique(const SearchAxes& axes, const ScannerGeometry& g) {
  const auto gradient = inverse_depth_gradient(g);
  const double norm = std::hypot(gradient[0], gradient[1]);
  const auto& l = axes.line_step;
  const auto& w = axes.along;
  EXPECT_EQ(axes.axis, SearchAxis::kOblique);
  EXPECT_FALSE(axes.identity());
  EXPECT_NEAR(std::hypot(w[0], w[1]), 1.0, 1e-12);
  EXPECT_NEAR(std::hypot(l[0], l[1]), 1.0, 1e-12);
  EXPECT_NEAR(l[0] * w[0] + l[1] * w[1], 0.0, 1e-12);
  // along is parallel to the gradient (either sign) and points down the image.
  EXPECT_NEAR((w[0] * gradient[1] - w[1] * gradient[0]) / norm, 0.0, 1e-9);
  EXPECT_GT(w[1], 0.0);
  // [line_step along] is a rotation of the pixel grid (no reflection), as the header says.
  EXPECT_NEAR(l[0] * w[1] - l[1] * w[0], 1.0, 1e-12);
  // The search grid holds every corner of the frame, and is no more than a pixel larger than
  // they need at either end.
  double line_lo = 1e300, line_hi = -1e300, pos_lo = 1e300, pos_hi = -1e300;
  for (const double x : {0.0, g.width - 1.0}) {
    for (const double y : {0.0, g.height - 1.0}) {
      const auto [line, position] = axes.to_search(x, y);
      EXPECT_GE(line, -1e-9) << "corner " << x << ", " << y;
      EXPECT_LE(line, axes.lines - 1 + 1e-9) << "corner " << x << ", " << y;
      EXPECT_GE(position, -1e-9) << "corner " << x << ", " << y;
      EXPECT_LE(position, axes.length - 1 + 1e-9) << "corner " << x << ", " << y;
      line_lo = std::min(line_lo, line);
      line_hi = std::max(line_hi, line);
      pos_lo = std::min(pos_lo, position);
      pos_hi = std::max(pos_hi, position);
    }
  }
  EXPECT_LT(line_lo, 1.0);
  EXPECT_GT(line_hi, axes.lines - 2.0);
  EXPECT_LT(pos_lo, 1.0);
  EXPECT_GT(pos_hi, axes.length - 2.0);
  expect_maps_invert(axes, g.width, g.height);
}

TEST(ChooseSearchAxes, AlongTheVAxisGivesTheColumns) {
  for (const double sign : {1.0, -1.0}) {
    for (const double degrees : {0.0, 180.0}) {
      const ScannerGeometry g = geometry_at(degrees, sign);
      ASSERT_NEAR(angle_from_v_axis(inverse_depth_gradient(g)), 0.0, 1e-9);
      SCOPED_TRACE(std::to_string(degrees) + " deg, sign " + std::to_string(sign));
      expect_columns(choose_search_axes(g), g.width, g.height);
    }
  }
  // The default geometry (the paper's mounting).
  const ScannerGeometry paper;
  expect_columns(choose_search_axes(paper), paper.width, paper.height);
}

TEST(ChooseSearchAxes, AlongTheUAxisGivesTheRows) {
  for (const double sign : {1.0, -1.0}) {
    for (const double degrees : {90.0, -90.0}) {
      ScannerGeometry g = geometry_at(degrees, sign);
      g.laser_plane[1] = 0.0;  // exactly along u
      ASSERT_NEAR(angle_from_v_axis(inverse_depth_gradient(g)), 90.0, 1e-9);
      SCOPED_TRACE(std::to_string(degrees) + " deg, sign " + std::to_string(sign));
      const SearchAxes axes = choose_search_axes(g);
      expect_rows(axes, g.width, g.height);
      expect_maps_invert(axes, g.width, g.height);
      // Rows: line = row, position = column.
      const auto [line, position] = axes.to_search(12.0, 34.0);
      EXPECT_DOUBLE_EQ(line, 34.0);
      EXPECT_DOUBLE_EQ(position, 12.0);
    }
  }
}

TEST(ChooseSearchAxes, WithinTheToleranceOfAnAxisGivesThatAxis) {
  ASSERT_EQ(kAxisToleranceDeg, 5.0);
  for (const double sign : {1.0, -1.0}) {
    // Columns: within 5 deg of v, on either side and for the gradient pointing up the image.
    for (const double degrees : {2.0, 4.9, -4.9, 175.1, -176.0}) {
      const ScannerGeometry g = geometry_at(degrees, sign);
      ASSERT_LE(angle_from_v_axis(inverse_depth_gradient(g)), 4.95);
      SCOPED_TRACE(std::to_string(degrees) + " deg, sign " + std::to_string(sign));
      expect_columns(choose_search_axes(g), g.width, g.height);
    }
    // Rows: within 5 deg of u.
    for (const double degrees : {85.1, 94.9, -85.1, -94.9, 88.0}) {
      const ScannerGeometry g = geometry_at(degrees, sign);
      ASSERT_GE(angle_from_v_axis(inverse_depth_gradient(g)), 85.05);
      SCOPED_TRACE(std::to_string(degrees) + " deg, sign " + std::to_string(sign));
      expect_rows(choose_search_axes(g), g.width, g.height);
    }
  }
}

TEST(ChooseSearchAxes, BeyondTheToleranceTheLinesAreOblique) {
  for (const double sign : {1.0, -1.0}) {
    for (const double degrees :
         {5.1, -5.1, 20.0, -20.0, 30.0, 45.0, 60.0, -60.0, 84.9, 95.1, 120.0, 150.0, -150.0}) {
      const ScannerGeometry g = geometry_at(degrees, sign);
      const double angle = angle_from_v_axis(inverse_depth_gradient(g));
      ASSERT_GT(angle, 5.05);
      ASSERT_LT(angle, 84.95);
      SCOPED_TRACE(std::to_string(degrees) + " deg, sign " + std::to_string(sign));
      expect_oblique(choose_search_axes(g), g);
    }
  }
  // The same sheet with every coefficient negated (e < 0): the gradient is the same.
  ScannerGeometry g = geometry_at(30.0);
  for (auto& k : g.laser_plane)
    k = -k;
  expect_oblique(choose_search_axes(g), g);
  // Other frame sizes, including a tall one and a small one.
  for (const auto& [w, h] : {std::array<int, 2>{200, 150}, {150, 400}, {7, 5}, {2, 2}}) {
    SCOPED_TRACE(std::to_string(w) + " x " + std::to_string(h));
    const ScannerGeometry small = geometry_at(37.0, 1.0, w, h);
    expect_oblique(choose_search_axes(small), small);
  }
}

TEST(ChooseSearchAxes, NoGradientFallsBackToTheColumns) {
  ScannerGeometry g = geometry_at(0.0);
  g.laser_plane = {0.0, 0.0, 1.0, -0.5};  // parallel to the image plane
  expect_columns(choose_search_axes(g), g.width, g.height);
}

// ---- search_geometry ----------------------------------------------------------------------------

// Points of the sheet, projected with the camera (pinhole) and mapped to search coordinates, lie
// on the search geometry's sheet at the same depth.
void expect_same_depths(const ScannerGeometry& g, const SearchAxes& axes) {
  const ScannerGeometry s = search_geometry(g, axes);
  EXPECT_EQ(s.width, axes.lines);
  EXPECT_EQ(s.height, axes.length);
  const double a = g.laser_plane[0], b = g.laser_plane[1], c = g.laser_plane[2],
               e = g.laser_plane[3];
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> lateral(-0.09, 0.09);
  for (int i = 0; i < 40; ++i) {
    // A 3-D point of the sheet: X and Y chosen, Z from a X + b Y + c Z + e = 0.
    const double big_x = lateral(rng), big_y = lateral(rng);
    const double big_z = -(e + a * big_x + b * big_y) / c;
    ASSERT_GT(big_z, 0.1);
    const double u = g.fx * big_x / big_z + g.cx, v = g.fy * big_y / big_z + g.cy;
    const auto [line, position] = axes.to_search(u, v);
    // Back-projected with the search camera onto the search sheet.
    const double xs = (line - s.cx) / s.fx, ys = (position - s.cy) / s.fy;
    const double as = s.laser_plane[0], bs = s.laser_plane[1], cs = s.laser_plane[2],
                 es = s.laser_plane[3];
    const double depth = -es / (as * xs + bs * ys + cs);
    EXPECT_NEAR(depth, big_z, 1e-9 * big_z) << "point " << big_x << ", " << big_y;
  }
}

TEST(SearchGeometry, ColumnsAreTheGeometryItself) {
  ScannerGeometry g = geometry_at(0.0);
  g.distortion = {0.1, -0.05, 0.001, -0.002, 0.01};
  const ScannerGeometry s = search_geometry(g, choose_search_axes(g));
  EXPECT_EQ(s.width, g.width);
  EXPECT_EQ(s.height, g.height);
  EXPECT_EQ(s.fx, g.fx);
  EXPECT_EQ(s.fy, g.fy);
  EXPECT_EQ(s.cx, g.cx);
  EXPECT_EQ(s.cy, g.cy);
  EXPECT_EQ(s.distortion, g.distortion);
  EXPECT_EQ(s.laser_plane, g.laser_plane);
}

TEST(SearchGeometry, RowsAreTheTransposedCamera) {
  for (const double degrees : {90.0, 87.0, -93.0}) {
    SCOPED_TRACE(std::to_string(degrees) + " deg");
    const ScannerGeometry g = geometry_at(degrees);
    const SearchAxes axes = choose_search_axes(g);
    ASSERT_EQ(axes.axis, SearchAxis::kRows);
    const ScannerGeometry s = search_geometry(g, axes);
    EXPECT_EQ(s.fx, g.fy);
    EXPECT_EQ(s.fy, g.fx);
    EXPECT_EQ(s.cx, g.cy);
    EXPECT_EQ(s.cy, g.cx);
    EXPECT_EQ(s.width, g.height);
    EXPECT_EQ(s.height, g.width);
    expect_same_depths(g, axes);
  }
}

TEST(SearchGeometry, ObliqueKeepsTheInverseDepth) {
  for (const double sign : {1.0, -1.0}) {
    for (const double degrees : {30.0, -20.0, 60.0, 5.5, 84.5, 135.0}) {
      SCOPED_TRACE(std::to_string(degrees) + " deg, sign " + std::to_string(sign));
      const ScannerGeometry g = geometry_at(degrees, sign);
      const SearchAxes axes = choose_search_axes(g);
      ASSERT_EQ(axes.axis, SearchAxis::kOblique);
      expect_same_depths(g, axes);
      // The lines run along the gradient: the depth does not change across them.
      const ScannerGeometry s = search_geometry(g, axes);
      EXPECT_NEAR(s.laser_plane[0], 0.0, 1e-12 * std::abs(s.laser_plane[1]));
      EXPECT_NEAR(s.fx, std::sqrt(g.fx * g.fy), 1e-9);
      EXPECT_NEAR(s.fy, std::sqrt(g.fx * g.fy), 1e-9);
    }
  }
}

// With distortion: the search camera sees the ray whose normalised coordinates are the camera's
// turned into search coordinates (rows: swapped; oblique: rotated by [line_step along]^T, exact
// for fx == fy) at the camera's pixel mapped by to_search.
void expect_same_distorted_pixels(const ScannerGeometry& g, const SearchAxes& axes) {
  const ScannerGeometry s = search_geometry(g, axes);
  EXPECT_EQ(s.distortion[0], g.distortion[0]);
  EXPECT_EQ(s.distortion[1], g.distortion[1]);
  EXPECT_EQ(s.distortion[4], g.distortion[4]);
  const auto& l = axes.line_step;
  const auto& w = axes.along;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> normalised(-0.2, 0.2);
  for (int i = 0; i < 40; ++i) {
    const double x = normalised(rng), y = normalised(rng);
    const auto [u, v] = g.pixel(x, y);
    const auto [line, position] = axes.to_search(u, v);
    const auto [sl, sp] = s.pixel(x * l[0] + y * l[1], x * w[0] + y * w[1]);
    EXPECT_NEAR(sl, line, 1e-9) << "ray " << x << ", " << y;
    EXPECT_NEAR(sp, position, 1e-9) << "ray " << x << ", " << y;
  }
}

TEST(SearchGeometry, DistortionTurnsWithTheGrid) {
  {
    ScannerGeometry g = geometry_at(90.0);
    g.distortion = {-0.2, 0.05, 0.003, -0.001, 0.02};
    const SearchAxes axes = choose_search_axes(g);
    ASSERT_EQ(axes.axis, SearchAxis::kRows);
    const ScannerGeometry s = search_geometry(g, axes);
    EXPECT_EQ(s.distortion[2], g.distortion[3]);
    EXPECT_EQ(s.distortion[3], g.distortion[2]);
    expect_same_distorted_pixels(g, axes);
  }
  for (const double degrees : {30.0, -20.0, 60.0, 135.0}) {
    SCOPED_TRACE(std::to_string(degrees) + " deg");
    ScannerGeometry g = geometry_at(degrees, 1.0, 640, 480, 1300, 1300);
    g.distortion = {-0.2, 0.05, 0.003, -0.001, 0.02};
    const SearchAxes axes = choose_search_axes(g);
    ASSERT_EQ(axes.axis, SearchAxis::kOblique);
    expect_same_distorted_pixels(g, axes);
  }
}

// ---- SearchImage --------------------------------------------------------------------------------

// A mono8 frame with `stride` >= width; the padding holds random bytes too, so that reading it
// would show.
struct Frame {
  int width, height, stride;
  std::vector<std::uint8_t> pixels;
  Frame(int w, int h, int s) : width(w), height(h), stride(s), pixels(std::size_t(s) * h) {}
  std::uint8_t& at(int x, int y) { return pixels[std::size_t(y) * stride + x]; }
  std::uint8_t at(int x, int y) const { return pixels[std::size_t(y) * stride + x]; }
  ImageView view() const { return {pixels.data(), width, height, stride}; }
};

Frame random_frame(int w, int h, int stride, unsigned seed) {
  Frame f(w, h, stride);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> byte(0, 255);
  for (auto& p : f.pixels)
    p = static_cast<std::uint8_t>(byte(rng));
  return f;
}

// Random but smooth enough (neighbours differ by at most ~45 grey levels) that 8-bit fixed-point
// interpolation weights stay within one grey level of the exact bilinear value.
Frame smooth_random_frame(int w, int h, int stride, unsigned seed) {
  Frame f = random_frame(w, h, stride, seed);  // the padding stays random
  std::mt19937 rng(seed + 1);
  std::uniform_real_distribution<double> phase(0.0, 2 * kPi);
  std::uniform_int_distribution<int> noise(-16, 16);
  const double p1 = phase(rng), p2 = phase(rng);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double value = 128.0 + 50.0 * std::sin(0.11 * x + 0.07 * y + p1) +
                           40.0 * std::cos(0.05 * x - 0.13 * y + p2) + noise(rng);
      f.at(x, y) = static_cast<std::uint8_t>(std::clamp(std::lround(value), 0L, 255L));
    }
  }
  return f;
}

SearchAxes rows_axes(int width, int height) {
  ScannerGeometry g = geometry_at(90.0, 1.0, width, height);
  g.laser_plane[1] = 0.0;
  const SearchAxes axes = choose_search_axes(g);
  EXPECT_EQ(axes.axis, SearchAxis::kRows);
  return axes;
}

TEST(SearchImage, ColumnsAreTheFrameItself) {
  const Frame frame = random_frame(50, 35, 64, 1);
  SearchImage search;
  search.reset(SearchAxes::columns(50, 35), 50, 35);
  const ImageView view = search.make(frame.view());
  EXPECT_EQ(view.data, frame.pixels.data());
  EXPECT_EQ(view.width, 50);
  EXPECT_EQ(view.height, 35);
  EXPECT_EQ(view.stride, 64);
}

TEST(SearchImage, RowsAreTheExactTranspose) {
  const std::array<int, 2> sizes[] = {{35, 50}, {64, 48}, {37, 53}, {16, 16}, {17, 33}, {48, 64},
                                      {1, 40},  {40, 1},  {1, 1},   {15, 16}, {16, 15}, {100, 3}};
  unsigned seed = 10;
  for (const auto& [w, h] : sizes) {
    for (const int padding : {0, 13, 1}) {
      SCOPED_TRACE(std::to_string(w) + " x " + std::to_string(h) + ", stride " +
                   std::to_string(w + padding));
      const Frame frame = random_frame(w, h, w + padding, ++seed);
      SearchImage search;
      search.reset(rows_axes(w, h), w, h);
      const ImageView view = search.make(frame.view());
      ASSERT_EQ(view.width, h);
      ASSERT_EQ(view.height, w);
      ASSERT_GE(view.stride, view.width);
      int wrong = 0;
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          // Line y, position x.
          if (view.at(y, x) != frame.at(x, y) && ++wrong <= 5) {
            ADD_FAILURE() << "line " << y << " position " << x << ": " << int{view.at(y, x)}
                          << ", frame " << int{frame.at(x, y)};
          }
        }
      }
      EXPECT_EQ(wrong, 0);
    }
  }
}

// Where a search sample lies relative to the part of the frame where bilinear interpolation has
// both neighbours, [0, w - 1) x [0, h - 1): ambiguous within 1e-6 pixel of its edge (the code
// under test places samples in 32.32 fixed point, which may round either way there).
enum class Where { kInside, kOutside, kAmbiguous };

Where where(double x, double y, int w, int h) {
  constexpr double kEps = 1e-6;
  if (x >= kEps && x <= w - 1 - kEps && y >= kEps && y <= h - 1 - kEps) return Where::kInside;
  if (x <= -kEps || x >= w - 1 + kEps || y <= -kEps || y >= h - 1 + kEps) return Where::kOutside;
  return Where::kAmbiguous;
}

// The exact bilinear value at (x, y), the position first clamped to the frame [0, w - 1] x
// [0, h - 1]: inside, the bilinear interpolation; outside, the frame's nearest edge (linear along
// it; a corner's pixel beyond a corner), as OpenCV's warpAffine with BORDER_REPLICATE. Continuous
// across the border, so a sample on the edge itself needs no decision here.
double bilinear_clamped(const Frame& f, double x, double y) {
  x = std::clamp(x, 0.0, f.width - 1.0);
  y = std::clamp(y, 0.0, f.height - 1.0);
  const int ix = std::min(static_cast<int>(std::floor(x)), f.width - 2);
  const int iy = std::min(static_cast<int>(std::floor(y)), f.height - 2);
  const double fx = x - ix, fy = y - iy;
  const double top = f.at(ix, iy) * (1 - fx) + f.at(ix + 1, iy) * fx;
  const double bottom = f.at(ix, iy + 1) * (1 - fx) + f.at(ix + 1, iy + 1) * fx;
  return top * (1 - fy) + bottom * fy;
}

struct ObliqueCounts {
  long inside = 0, outside = 0, grazing_lines = 0;
};

// Every sample within one grey level of the exact bilinear value at its position clamped to the
// frame.
ObliqueCounts expect_resampled(const Frame& frame, const SearchAxes& axes, const ImageView& view) {
  ObliqueCounts counts;
  int wrong = 0;
  const auto fail = [&](int u, int v, const std::string& what) {
    if (++wrong <= 8) {
      const auto [x, y] = axes.to_image(u, v);
      ADD_FAILURE() << "line " << u << " position " << v << " (image " << x << ", " << y
                    << "): " << what;
    }
  };
  for (int u = 0; u < axes.lines; ++u) {
    bool any_inside = false;
    for (int v = 0; v < axes.length; ++v) {
      const auto [x, y] = axes.to_image(u, v);
      const Where w = where(x, y, frame.width, frame.height);
      if (w == Where::kOutside) ++counts.outside;
      if (w == Where::kInside) {
        ++counts.inside;
        any_inside = true;
      }
      const double expected = bilinear_clamped(frame, x, y);
      if (std::abs(view.at(u, v) - expected) > 1.0) {
        fail(u, v,
             "got " + std::to_string(view.at(u, v)) + ", bilinear " + std::to_string(expected) +
                 (w == Where::kInside ? "" : " at the nearest edge"));
      }
    }
    if (!any_inside) ++counts.grazing_lines;  // a line that only grazes a corner
  }
  EXPECT_EQ(wrong, 0);
  return counts;
}

void expect_oblique_image(int w, int h, int stride, double degrees, double sign, unsigned seed) {
  SCOPED_TRACE(std::to_string(w) + " x " + std::to_string(h) + ", stride " +
               std::to_string(stride) + ", " + std::to_string(degrees) + " deg, sign " +
               std::to_string(sign));
  const ScannerGeometry g = geometry_at(degrees, sign, w, h);
  const SearchAxes axes = choose_search_axes(g);
  ASSERT_EQ(axes.axis, SearchAxis::kOblique);
  const Frame frame = smooth_random_frame(w, h, stride, seed);
  SearchImage search;
  search.reset(axes, w, h);
  const ImageView view = search.make(frame.view());
  ASSERT_EQ(view.width, axes.lines);
  ASSERT_EQ(view.height, axes.length);
  ASSERT_GE(view.stride, view.width);
  const ObliqueCounts counts = expect_resampled(frame, axes, view);
  // Not vacuous: a rotation keeps the frame's area, the rest is outside.
  EXPECT_GT(counts.inside, 0.8 * (w - 1) * (h - 1));
  EXPECT_GT(counts.outside, 0);
  EXPECT_LE(counts.grazing_lines, 4);
  // The same image a second time (make() reuses its buffers).
  const ImageView again = search.make(frame.view());
  for (int v = 0; v < axes.length; ++v) {
    for (int u = 0; u < axes.lines; ++u)
      ASSERT_EQ(again.at(u, v), view.at(u, v));
  }
}

TEST(SearchImage, ObliqueIsTheBilinearResamplingWithTheNearestEdgeOutside) {
  unsigned seed = 100;
  for (const double degrees : {30.0, -20.0, 60.0, 5.5, -84.5, 135.0}) {
    for (const double sign : {1.0, -1.0})
      expect_oblique_image(200, 150, 200, degrees, sign, ++seed);
  }
}

TEST(SearchImage, ObliqueWithAStrideBeyondTheWidth) {
  expect_oblique_image(200, 150, 213, 30.0, 1.0, 7);
  expect_oblique_image(200, 150, 256, -20.0, 1.0, 8);
  expect_oblique_image(131, 77, 140, 60.0, -1.0, 9);
}

TEST(SearchImage, ObliqueOnOtherSizes) {
  expect_oblique_image(150, 200, 150, 30.0, 1.0, 21);
  expect_oblique_image(37, 53, 41, 45.0, 1.0, 22);
  expect_oblique_image(64, 48, 64, -70.0, 1.0, 23);
  expect_oblique_image(2, 2, 5, 30.0, 1.0, 24);
  expect_oblique_image(3, 40, 3, 60.0, 1.0, 25);
}

TEST(SearchImage, MakeDoesNotAllocate) {
  ASSERT_TRUE(testing::allocation_counter_works());
  const Frame frame = smooth_random_frame(200, 150, 208, 31);
  const ScannerGeometry oblique = geometry_at(30.0, 1.0, 200, 150);
  for (const SearchAxes& axes :
       {SearchAxes::columns(200, 150), rows_axes(200, 150), choose_search_axes(oblique)}) {
    SCOPED_TRACE(to_string(axes.axis));
    SearchImage search;
    search.reset(axes, 200, 150);
    testing::start_counting_allocations();
    ImageView views[3];
    for (auto& view : views)
      view = search.make(frame.view());
    const testing::Allocations counted = testing::stop_counting_allocations();
    EXPECT_EQ(counted.count, 0) << counted.bytes << " bytes";
    for (const auto& view : views) {
      EXPECT_EQ(view.width, axes.lines);
      EXPECT_EQ(view.height, axes.length);
    }
  }
}

}  // namespace
}  // namespace laserline::pipeline
