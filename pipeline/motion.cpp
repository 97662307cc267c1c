#include "pipeline/motion.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

namespace laserline::pipeline {

namespace {

constexpr int kMaxLevels = 8;
constexpr int kMaxWindowRadius = 15;
// Sampled patch around a tracked point: the window plus one pixel each side for the gradient.
constexpr int kMaxPatch = 2 * kMaxWindowRadius + 3;
// Shi-Tomasi floor: the weaker eigenvalue of the 3x3 structure tensor (half central differences,
// grey levels) must exceed this, i.e. about one grey level per pixel of gradient in the weaker
// direction. Sensor noise at the detect level (averaged over 2^level squared pixels) stays well
// below.
constexpr float kMinEigenvalue = 9.0f;
// Laser filter Haar wavelets at the detect level: boxes of kHaarSize x kHaarSize/2 (difference of
// the two halves), laid on a grid of step kHaarSize/2 across the neighbourhood. Boxes integrate
// along the line, where the laser is coherent and the texture is not.
constexpr int kHaarSize = 4;
// Blocks across the laser filter's neighbourhood (radius 2 * window_radius) and one more.
constexpr int kMaxHaarBlocks = (4 * kMaxWindowRadius) / (kHaarSize / 2) + 2;
// A track has converged when its last update at full size moved it less than this (pixels).
constexpr float kConvergedStep = 0.05f;
constexpr float kStopStep = 0.01f;
constexpr float kCoarseStopStep = 0.05f;
constexpr double kRansacConfidence = 0.999;
constexpr std::uint64_t kRansacSeed = 0x9e3779b97f4a7c15ull;

struct Level {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;  // stride = width
  const std::uint8_t* row(int v) const {
    return pixels.data() + static_cast<std::ptrdiff_t>(v) * width;
  }
  ImageView view() const { return ImageView{pixels.data(), width, height, width}; }
};

struct Pyramid {
  std::array<Level, kMaxLevels> levels;
};

using Point = std::array<float, 2>;

// splitmix64: small, fast and the same everywhere, so RANSAC repeats bit for bit.
struct Random {
  std::uint64_t state;
  std::uint64_t next() {
    std::uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  int below(int n) { return static_cast<int>(next() % static_cast<std::uint64_t>(n)); }
};

using Matrix3 = Eigen::Matrix3d;

// Similarity that moves the points' centroid to the origin and their mean distance to sqrt(2)
// (Hartley's normalisation, which keeps the DLT well conditioned).
Matrix3 normalising_transform(const double* x, const double* y, const int* index, int count) {
  double cx = 0, cy = 0;
  for (int i = 0; i < count; ++i) {
    cx += x[index[i]];
    cy += y[index[i]];
  }
  cx /= count;
  cy /= count;
  double mean_distance = 0;
  for (int i = 0; i < count; ++i)
    mean_distance += std::hypot(x[index[i]] - cx, y[index[i]] - cy);
  mean_distance /= count;
  const double s = mean_distance > 1e-12 ? std::sqrt(2.0) / mean_distance : 1.0;
  Matrix3 t;
  t << s, 0, -s * cx, 0, s, -s * cy, 0, 0, 1;
  return t;
}

Matrix3 to_matrix(const Homography& h) {
  Matrix3 m;
  m << h.h[0], h.h[1], h.h[2], h.h[3], h.h[4], h.h[5], h.h[6], h.h[7], h.h[8];
  return m;
}

Homography to_homography(const Matrix3& m_in) {
  Matrix3 m = m_in;
  if (std::abs(m(2, 2)) > 1e-12) {
    m /= m(2, 2);
  } else {
    m /= m.norm();
  }
  Homography h;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      h.h[r * 3 + c] = m(r, c);
  return h;
}

// Twice the signed area of the triangle a, b, c.
double twice_area(double ax, double ay, double bx, double by, double cx, double cy) {
  return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
}

}  // namespace

Homography Homography::inverse() const {
  const Matrix3 m = to_matrix(*this);
  const double det = m.determinant();
  if (!(std::abs(det) > 0)) return Homography{{0, 0, 0, 0, 0, 0, 0, 0, 0}};
  // The adjugate is the inverse up to scale, and a homography is defined up to scale only.
  Matrix3 adjugate;
  adjugate(0, 0) = m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1);
  adjugate(0, 1) = m(0, 2) * m(2, 1) - m(0, 1) * m(2, 2);
  adjugate(0, 2) = m(0, 1) * m(1, 2) - m(0, 2) * m(1, 1);
  adjugate(1, 0) = m(1, 2) * m(2, 0) - m(1, 0) * m(2, 2);
  adjugate(1, 1) = m(0, 0) * m(2, 2) - m(0, 2) * m(2, 0);
  adjugate(1, 2) = m(0, 2) * m(1, 0) - m(0, 0) * m(1, 2);
  adjugate(2, 0) = m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0);
  adjugate(2, 1) = m(0, 1) * m(2, 0) - m(0, 0) * m(2, 1);
  adjugate(2, 2) = m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0);
  return to_homography(adjugate / det);
}

struct MotionEstimator::State {
  int width = 0;
  int height = 0;
  bool has_previous = false;
  std::array<Pyramid, 2> pyramids;
  int previous = 0;  // index of the previous frame's pyramid and features

  // Features found in each pyramid's frame, full-size coordinates, and the ones the laser filter
  // kept out.
  std::array<std::vector<Point>, 2> features;
  std::array<int, 2> feature_count{};
  std::array<std::vector<Point>, 2> rejected;
  std::array<int, 2> rejected_count{};
  int reported_rejected = -1;  // index of the rejected list the last update() reports, -1: none
  // Full-size frames are not kept, only the (2r+3)^2 patch around each feature (what the
  // tracker's full-size template needs): patch_bytes per feature.
  std::array<std::vector<std::uint8_t>, 2> patches;
  int patch_bytes = 0;

  std::vector<FeatureTrack> tracks;
  int track_count = 0;

  // Feature detection at the detect level: border kept clear, grid cells of the area within.
  int margin = 0;
  std::vector<int> cell_of_row;
  std::vector<int> cell_start;  // first column of each grid column, and one past the last
  std::array<std::vector<std::int32_t>, 3> gxx, gxy, gyy;     // rolling rows of gradient products
  std::vector<std::int32_t> column_xx, column_xy, column_yy;  // their sums over three rows
  std::vector<std::int32_t> eigen_bound;  // per column of the row: bound of the smaller eigenvalue
  std::vector<float> cell_score;
  std::vector<int> cell_u, cell_v;

  // RANSAC, per tracked pair: full-size coordinates as double, indices of the converged tracks.
  std::vector<double> px, py, cx, cy;
  std::vector<int> all_index;  // 0..n-1 in some order (RANSAC shuffles it to draw samples)
  std::vector<int> inlier_index;
  std::vector<std::uint8_t> is_inlier;
  std::vector<std::uint8_t> best_inlier;
};

MotionEstimator::MotionEstimator(const MotionOptions& options) : options_(options) {
  const auto require = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(std::string("MotionOptions: ") + what);
  };
  require(options.grid_columns >= 1 && options.grid_rows >= 1,
          "grid_columns and grid_rows must be >= 1");
  require(options.pyramid_levels >= 1 && options.pyramid_levels <= kMaxLevels,
          "pyramid_levels must be within [1, 8]");
  require(options.detect_level >= 0 && options.detect_level < options.pyramid_levels,
          "detect_level must be within [0, pyramid_levels)");
  require(options.window_radius >= 1 && options.window_radius <= kMaxWindowRadius,
          "window_radius must be within [1, 15]");
  require(options.max_iterations >= 1, "max_iterations must be >= 1");
  require(options.ransac_iterations >= 1, "ransac_iterations must be >= 1");
  require(std::isfinite(options.inlier_px) && options.inlier_px > 0, "inlier_px must be > 0");
  require(options.min_inliers >= 4, "min_inliers must be >= 4");
  require(options.laser_filter_ratio >= 1.0, "laser_filter_ratio must be >= 1");
  require(options.essential_ransac_iterations >= 1, "essential_ransac_iterations must be >= 1");
  require(std::isfinite(options.essential_inlier_px) && options.essential_inlier_px > 0,
          "essential_inlier_px must be > 0");
  require(
      std::isfinite(options.essential_min_parallax_px) && options.essential_min_parallax_px >= 0,
      "essential_min_parallax_px must be >= 0");
  require(options.scale_tracks >= 0, "scale_tracks must be >= 0");
  state_ = new State;
}

MotionEstimator::~MotionEstimator() {
  delete state_;
}

void MotionEstimator::reset(int width, int height, const ScannerGeometry* geometry) {
  const MotionOptions& o = options_;
  const std::string size = std::to_string(width) + "x" + std::to_string(height);
  if (width <= 0 || height <= 0 || width > 65535 || height > 65535) {
    throw std::invalid_argument("MotionEstimator::reset: image size " + size +
                                " must be within 1x1 .. 65535x65535");
  }
  if (geometry != nullptr) {
    if (geometry->width != width || geometry->height != height) {
      throw std::invalid_argument(
          "MotionEstimator::reset: image size " + size + " differs from the geometry's " +
          std::to_string(geometry->width) + "x" + std::to_string(geometry->height));
    }
    if (!(geometry->fx > 0 && geometry->fy > 0 && std::isfinite(geometry->fx) &&
          std::isfinite(geometry->fy) && std::isfinite(geometry->cx) &&
          std::isfinite(geometry->cy))) {
      throw std::invalid_argument(
          "MotionEstimator::reset: the geometry's fx, fy must be > 0 and "
          "cx, cy finite");
    }
    for (double k : geometry->distortion) {
      if (!std::isfinite(k)) {
        throw std::invalid_argument(
            "MotionEstimator::reset: the geometry's distortion must be finite");
      }
    }
  }
  State& s = *state_;
  // Until this reset() completes, update() refuses every frame (a refused size leaves no half
  // sized state behind).
  s.width = s.height = 0;
  s.has_previous = false;
  s.reported_rejected = -1;
  s.track_count = 0;

  // Every level must hold a whole tracking window with its gradient border.
  const int top = o.pyramid_levels - 1;
  const int min_side = 2 * (o.window_radius + 2) + 1;
  const int top_width = width >> top, top_height = height >> top;
  if (top_width < min_side || top_height < min_side) {
    throw std::invalid_argument(
        "MotionEstimator::reset: image " + size + " is too small for " +
        std::to_string(o.pyramid_levels) + " pyramid levels: level " + std::to_string(top) +
        " would be " + std::to_string(top_width) + "x" + std::to_string(top_height) +
        ", tracking with window_radius " + std::to_string(o.window_radius) + " needs at least " +
        std::to_string(min_side) + "x" + std::to_string(min_side));
  }
  // Features keep clear of the border by a tracking window at the coarsest level, so that they
  // can be tracked at every level.
  const int detect_width = width >> o.detect_level, detect_height = height >> o.detect_level;
  s.margin = (o.window_radius + 2) << std::max(0, top - o.detect_level);
  const int valid_width = detect_width - 2 * s.margin, valid_height = detect_height - 2 * s.margin;
  if (valid_width < o.grid_columns || valid_height < o.grid_rows) {
    throw std::invalid_argument("MotionEstimator::reset: image " + size + " is too small for a " +
                                std::to_string(o.grid_columns) + "x" + std::to_string(o.grid_rows) +
                                " feature grid at detect_level " + std::to_string(o.detect_level) +
                                " (" + std::to_string(detect_width) + "x" +
                                std::to_string(detect_height) + " with a border of " +
                                std::to_string(s.margin) + ")");
  }

  for (Pyramid& pyramid : s.pyramids) {
    for (int l = 0; l < kMaxLevels; ++l) {
      Level& level = pyramid.levels[l];
      // Full size is not kept (see State::patches).
      if (l >= 1 && l < o.pyramid_levels) {
        level.width = width >> l;
        level.height = height >> l;
        level.pixels.assign(static_cast<std::size_t>(level.width) * level.height, 0);
      } else {
        level = Level{};
      }
    }
  }
  const int cells = o.grid_columns * o.grid_rows;
  s.patch_bytes = (2 * o.window_radius + 3) * (2 * o.window_radius + 3);
  for (int i = 0; i < 2; ++i) {
    s.features[i].assign(cells, Point{});
    s.patches[i].assign(static_cast<std::size_t>(cells) * s.patch_bytes, 0);
    s.rejected[i].assign(cells, Point{});
    s.feature_count[i] = 0;
    s.rejected_count[i] = 0;
  }
  s.tracks.assign(cells, FeatureTrack{});

  s.cell_of_row.assign(detect_height, -1);
  for (int v = s.margin; v < detect_height - s.margin; ++v)
    s.cell_of_row[v] = (v - s.margin) * o.grid_rows / valid_height;
  for (int i = 0; i < 3; ++i) {
    s.gxx[i].assign(detect_width, 0);
    s.gxy[i].assign(detect_width, 0);
    s.gyy[i].assign(detect_width, 0);
  }
  for (auto* v : {&s.column_xx, &s.column_xy, &s.column_yy, &s.eigen_bound})
    v->assign(detect_width, 0);
  s.cell_start.assign(o.grid_columns + 1, 0);
  for (int column = 0; column <= o.grid_columns; ++column)
    s.cell_start[column] = s.margin + (column * valid_width + o.grid_columns - 1) / o.grid_columns;
  s.cell_score.assign(cells, 0);
  s.cell_u.assign(cells, 0);
  s.cell_v.assign(cells, 0);

  for (auto* v : {&s.px, &s.py, &s.cx, &s.cy})
    v->assign(cells, 0);
  s.all_index.assign(cells, 0);
  s.inlier_index.assign(cells, 0);
  s.is_inlier.assign(cells, 0);
  s.best_inlier.assign(cells, 0);
  s.width = width;
  s.height = height;
}

std::span<const FeatureTrack> MotionEstimator::tracks() const {
  return {state_->tracks.data(), static_cast<std::size_t>(state_->track_count)};
}

std::span<const std::array<float, 2>> MotionEstimator::rejected_features() const {
  const State& s = *state_;
  if (s.reported_rejected < 0) return {};
  return {s.rejected[s.reported_rejected].data(),
          static_cast<std::size_t>(s.rejected_count[s.reported_rejected])};
}

namespace {

// Calls body(i) for i in [first, last). The blocks of a fixed length are what GCC's default -O2
// ("very cheap") cost model is willing to vectorise; the rest runs one by one. Flattened, so
// that the body is inlined too. Its callers take __restrict pointers and stay out of line
// (noinline): inlined, GCC loses the promise and declines to vectorise.
template <typename Body>
[[gnu::always_inline, gnu::flatten]] inline void for_each_index(int first, int last, Body body) {
  constexpr int kBlock = 16;
  int i = first;
  for (; i + kBlock <= last; i += kBlock) {
    for (int k = 0; k < kBlock; ++k)
      body(i + k);
  }
  for (; i < last; ++i)
    body(i);
}

// 2x2 box average (rounded) of rows a and b into `count` pixels of out.
[[gnu::noinline]] void downsample_row(const std::uint8_t* __restrict a,
                                      const std::uint8_t* __restrict b,
                                      std::uint8_t* __restrict out, int count) {
  for_each_index(0, count, [&](int u) {
    const unsigned sum = 2u + a[2 * u] + a[2 * u + 1] + b[2 * u] + b[2 * u + 1];
    out[u] = static_cast<std::uint8_t>(sum >> 2);
  });
}

// Level 1 of the frame (full size is not kept: the tracker keeps patches of it, see State).
void downsample_frame(const ImageView& frame, Level& level1) {
  for (int v = 0; v < level1.height; ++v) {
    downsample_row(frame.row(2 * v), frame.row(2 * v + 1),
                   level1.pixels.data() + static_cast<std::ptrdiff_t>(v) * level1.width,
                   level1.width);
  }
}

void downsample(const Level& fine, Level& coarse) {
  for (int v = 0; v < coarse.height; ++v) {
    downsample_row(fine.row(2 * v), fine.row(2 * v + 1),
                   coarse.pixels.data() + static_cast<std::ptrdiff_t>(v) * coarse.width,
                   coarse.width);
  }
}

// Adds the gradient products of the row `mid` (doubled central differences) to the column sums
// and replaces the products of the row three above (in xx, xy, yy) with them, for u in
// [first, last).
[[gnu::noinline]] void slide_structure_row(
    const std::uint8_t* __restrict up, const std::uint8_t* __restrict mid,
    const std::uint8_t* __restrict down, std::int32_t* __restrict xx, std::int32_t* __restrict xy,
    std::int32_t* __restrict yy, std::int32_t* __restrict sum_xx, std::int32_t* __restrict sum_xy,
    std::int32_t* __restrict sum_yy, int first, int last) {
  for_each_index(first, last, [&](int u) {
    const std::int32_t gx = mid[u + 1] - mid[u - 1];
    const std::int32_t gy = down[u] - up[u];
    const std::int32_t pxx = gx * gx, pxy = gx * gy, pyy = gy * gy;
    sum_xx[u] += pxx - xx[u];
    sum_xy[u] += pxy - xy[u];
    sum_yy[u] += pyy - yy[u];
    xx[u] = pxx;
    xy[u] = pxy;
    yy[u] = pyy;
  });
}

// min(a, c) of the 3x3 structure tensor [a b; b c]: a bound of its smaller eigenvalue.
[[gnu::noinline]] void eigenvalue_bound_row(const std::int32_t* __restrict sum_xx,
                                            const std::int32_t* __restrict sum_yy,
                                            std::int32_t* __restrict bound, int first, int last) {
  for_each_index(first, last, [&](int u) {
    const std::int32_t a = sum_xx[u - 1] + sum_xx[u] + sum_xx[u + 1];
    const std::int32_t c = sum_yy[u - 1] + sum_yy[u] + sum_yy[u + 1];
    bound[u] = std::min(a, c);
  });
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

// Samples a (2n+1)^2 patch of `image` centred on (x, y) with bilinear interpolation; every
// sample shares the same sub-pixel weights, so rows are interpolated once and blended. False when
// a sample would fall outside.
bool sample_patch(const ImageView& image, float x, float y, int n, float* out) {
  const float fx = std::floor(x), fy = std::floor(y);
  if (!(fx - n >= 0 && fy - n >= 0 && fx + n + 1 < image.width && fy + n + 1 < image.height))
    return false;
  const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
  const float ax = x - fx, ay = y - fy;
  const int side = 2 * n + 1;
  std::array<float, kMaxPatch + 2> rows[2];
  const auto interpolate_row = [&](int v, float* row) {
    const std::uint8_t* p = image.row(v) + (ix - n);
    for (int i = 0; i < side; ++i) {
      const float a = p[i];
      row[i] = a + ax * (static_cast<float>(p[i + 1]) - a);
    }
  };
  float* upper = rows[0].data();
  float* lower = rows[1].data();
  interpolate_row(iy - n, upper);
  for (int j = 0; j < side; ++j) {
    interpolate_row(iy - n + j + 1, lower);
    float* o = out + j * side;
    for (int i = 0; i < side; ++i)
      o[i] = upper[i] + ay * (lower[i] - upper[i]);
    std::swap(upper, lower);
  }
  return true;
}

struct TrackResult {
  float u = 0, v = 0;
  bool converged = false;
};

// Pyramidal Lucas-Kanade (translation only) of the point (pu, pv), full-size whole pixels, from
// the previous frame into the current one, coarse to fine. Below full size both frames are
// pyramid levels; at full size the previous frame is the (2r+3)^2 patch around the point kept
// when it was detected, the current frame is the frame itself. Coarse levels where the window
// does not fit are skipped; the full-size level must fit.
TrackResult track_point(const Pyramid& previous, const Pyramid& current,
                        const std::uint8_t* full_size_patch, const ImageView& frame,
                        const MotionOptions& o, float pu, float pv) {
  const int r = o.window_radius;
  const int side = 2 * r + 1;
  const int patch_side = side + 2;
  std::array<float, kMaxPatch * kMaxPatch> templ;
  std::array<float, kMaxPatch * kMaxPatch> grad_x, grad_y;
  std::array<float, kMaxPatch * kMaxPatch> warped;
  float du = 0, dv = 0;  // displacement, full-size pixels
  TrackResult result;
  for (int l = o.pyramid_levels - 1; l >= 0; --l) {
    const float scale = 1.0f / static_cast<float>(1 << l);
    const ImageView cur_level = l == 0 ? frame : current.levels[l].view();
    if (l == 0) {
      for (int k = 0; k < patch_side * patch_side; ++k)
        templ[k] = full_size_patch[k];
    } else {
      const float x = (pu + 0.5f) * scale - 0.5f, y = (pv + 0.5f) * scale - 0.5f;
      if (!sample_patch(previous.levels[l].view(), x, y, r + 1, templ.data())) continue;
    }
    // Template gradients (central differences) and the 2x2 normal matrix.
    float gxx = 0, gxy = 0, gyy = 0;
    for (int j = 0; j < side; ++j) {
      const float* t = templ.data() + (j + 1) * patch_side + 1;
      float* out_x = grad_x.data() + j * side;
      float* out_y = grad_y.data() + j * side;
      for (int i = 0; i < side; ++i) {
        const float gx = 0.5f * (t[i + 1] - t[i - 1]);
        const float gy = 0.5f * (t[i + patch_side] - t[i - patch_side]);
        out_x[i] = gx;
        out_y[i] = gy;
        gxx += gx * gx;
        gxy += gx * gy;
        gyy += gy * gy;
      }
    }
    const double det = static_cast<double>(gxx) * gyy - static_cast<double>(gxy) * gxy;
    const double trace = static_cast<double>(gxx) + gyy;
    // Flat or edge-only window: this level cannot tell where the point went.
    if (!(det > 1e-6 * trace * trace) || trace < 1e-3) {
      if (l == 0) return result;
      continue;
    }
    const auto inv_det = static_cast<float>(1.0 / det);
    float cx = (pu + du + 0.5f) * scale - 0.5f, cy = (pv + dv + 0.5f) * scale - 0.5f;
    // Coarse levels only need to land within the next level's reach.
    const float stop_step = l == 0 ? kStopStep : kCoarseStopStep;
    float last_step = 1e9f;
    bool inside = true;
    for (int iteration = 0; iteration < o.max_iterations; ++iteration) {
      if (!sample_patch(cur_level, cx, cy, r, warped.data())) {
        inside = false;
        break;
      }
      float bx = 0, by = 0;
      for (int j = 0; j < side; ++j) {
        const float* t = templ.data() + (j + 1) * patch_side + 1;
        const float* w = warped.data() + j * side;
        const float* gx = grad_x.data() + j * side;
        const float* gy = grad_y.data() + j * side;
        for (int i = 0; i < side; ++i) {
          const float e = t[i] - w[i];
          bx += e * gx[i];
          by += e * gy[i];
        }
      }
      const float step_x = inv_det * (gyy * bx - gxy * by);
      const float step_y = inv_det * (gxx * by - gxy * bx);
      cx += step_x;
      cy += step_y;
      last_step = std::sqrt(step_x * step_x + step_y * step_y);
      if (last_step < stop_step) break;
    }
    if (!inside) {
      if (l == 0) return result;
      continue;
    }
    du = (cx + 0.5f) / scale - 0.5f - pu;
    dv = (cy + 0.5f) / scale - 0.5f - pv;
    if (l == 0) {
      result.u = pu + du;
      result.v = pv + dv;
      result.converged = last_step < kConvergedStep;
    }
  }
  return result;
}

}  // namespace

MotionEstimate MotionEstimator::update(const ImageView& frame) {
  State& s = *state_;
  const MotionOptions& o = options_;
  MotionEstimate estimate;
  s.track_count = 0;
  s.reported_rejected = -1;
  if (s.width == 0 || frame.width != s.width || frame.height != s.height || frame.data == nullptr ||
      frame.stride < frame.width) {
    return estimate;
  }

  const int current = 1 - s.previous;
  Pyramid& pyramid = s.pyramids[current];
  if (o.pyramid_levels > 1) downsample_frame(frame, pyramid.levels[1]);
  for (int l = 2; l < o.pyramid_levels; ++l)
    downsample(pyramid.levels[l - 1], pyramid.levels[l]);

  if (s.has_previous) {
    estimate = estimate_from_previous(current, frame);
    s.reported_rejected = s.previous;
  }
  detect_features(current, frame);
  s.previous = current;
  s.has_previous = true;
  return estimate;
}

void MotionEstimator::detect_features(int index, const ImageView& frame) {
  State& s = *state_;
  const MotionOptions& o = options_;
  const ImageView level =
      o.detect_level == 0 ? frame : s.pyramids[index].levels[o.detect_level].view();
  const int width = level.width;
  const int cells = o.grid_columns * o.grid_rows;
  std::fill(s.cell_u.begin(), s.cell_u.end(), -1);

  // Gradient products (doubled central differences, integers) of the last three rows, and their
  // sums over those rows (kept sliding); summed over columns u-1 .. u+1 they are the structure
  // tensor of (u, v), four times over.
  const int first = s.margin - 1, last = level.height - s.margin;
  const int u_first = s.margin - 1, u_last = width - s.margin;  // inclusive
  std::int32_t* __restrict sum_xx = s.column_xx.data();
  std::int32_t* __restrict sum_xy = s.column_xy.data();
  std::int32_t* __restrict sum_yy = s.column_yy.data();
  for (int u = u_first; u <= u_last; ++u)
    sum_xx[u] = sum_xy[u] = sum_yy[u] = 0;
  for (auto* rows : {&s.gxx, &s.gxy, &s.gyy})
    for (auto& row : *rows)
      std::fill(row.begin(), row.end(), 0);
  // Adds row v's products to the sums, replacing those of row v-3.
  const auto slide = [&](int v) {
    const int slot = v % 3;
    slide_structure_row(level.row(v - 1), level.row(v), level.row(v + 1), s.gxx[slot].data(),
                        s.gxy[slot].data(), s.gyy[slot].data(), sum_xx, sum_xy, sum_yy, u_first,
                        u_last + 1);
  };
  const float floor4 = 4.0f * kMinEigenvalue;
  std::fill(s.cell_score.begin(), s.cell_score.end(), floor4);
  slide(first);
  slide(first + 1);
  std::int32_t* __restrict bound = s.eigen_bound.data();
  for (int v = s.margin; v < last; ++v) {
    slide(v + 1);
    // The smaller eigenvalue is at most min(a, c): most pixels stop at that bound.
    eigenvalue_bound_row(sum_xx, sum_yy, bound, s.margin, width - s.margin);
    float* cell_score = s.cell_score.data() + s.cell_of_row[v] * o.grid_columns;
    int* cell_u = s.cell_u.data() + s.cell_of_row[v] * o.grid_columns;
    int* cell_v = s.cell_v.data() + s.cell_of_row[v] * o.grid_columns;
    for (int column = 0; column < o.grid_columns; ++column) {
      float best = cell_score[column];
      int best_u = -1;
      const int u_end = s.cell_start[column + 1];
      for (int u = s.cell_start[column]; u < u_end; ++u) {
        if (static_cast<float>(bound[u]) <= best) continue;
        const std::int32_t a = sum_xx[u - 1] + sum_xx[u] + sum_xx[u + 1];
        const std::int32_t c = sum_yy[u - 1] + sum_yy[u] + sum_yy[u + 1];
        const std::int32_t b = sum_xy[u - 1] + sum_xy[u] + sum_xy[u + 1];
        const float half_difference = 0.5f * static_cast<float>(a - c);
        const float bf = static_cast<float>(b);
        const float score = 0.5f * static_cast<float>(a + c) -
                            std::sqrt(half_difference * half_difference + bf * bf);
        if (score > best) {
          best = score;
          best_u = u;
        }
      }
      if (best_u >= 0) {
        cell_score[column] = best;
        cell_u[column] = best_u;
        cell_v[column] = v;
      }
    }
  }

  // Full-size position of a detect-level pixel: the whole pixel nearest its block's centre, so
  // the full-size template needs no interpolation.
  const int factor = 1 << o.detect_level;
  const int offset = factor / 2;
  int kept = 0, rejected = 0;
  for (int cell = 0; cell < cells; ++cell) {
    if (s.cell_u[cell] < 0) continue;
    const Point p{static_cast<float>(s.cell_u[cell] * factor + offset),
                  static_cast<float>(s.cell_v[cell] * factor + offset)};
    if (looks_like_laser(level, s.cell_u[cell], s.cell_v[cell], 2 * o.window_radius,
                         o.laser_filter_ratio)) {
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

MotionEstimate MotionEstimator::estimate_from_previous(int current, const ImageView& frame) {
  State& s = *state_;
  const MotionOptions& o = options_;
  MotionEstimate estimate;
  const int previous = s.previous;
  estimate.detected = s.feature_count[previous] + s.rejected_count[previous];
  estimate.rejected_on_laser = s.rejected_count[previous];

  int n = 0;
  for (int i = 0; i < s.feature_count[previous]; ++i) {
    const Point p = s.features[previous][i];
    const TrackResult t =
        track_point(s.pyramids[previous], s.pyramids[current],
                    s.patches[previous].data() + static_cast<std::ptrdiff_t>(i) * s.patch_bytes,
                    frame, o, p[0], p[1]);
    if (!t.converged) continue;
    FeatureTrack& track = s.tracks[s.track_count++];
    track = FeatureTrack{p[0], p[1], t.u, t.v, false};
    s.px[n] = p[0];
    s.py[n] = p[1];
    s.cx[n] = t.u;
    s.cy[n] = t.v;
    s.all_index[n] = n;
    ++n;
  }
  estimate.tracked = n;
  if (n < std::max(4, o.min_inliers)) return estimate;

  Homography h;
  int inliers = 0;
  if (!fit_homography(n, h, inliers)) return estimate;

  double sum_squared = 0;
  for (int i = 0; i < n; ++i) {
    s.tracks[i].inlier = s.is_inlier[i] != 0;
    if (!s.is_inlier[i]) continue;
    const auto q = h.map(s.px[i], s.py[i]);
    sum_squared += (q[0] - s.cx[i]) * (q[0] - s.cx[i]) + (q[1] - s.cy[i]) * (q[1] - s.cy[i]);
  }
  estimate.inliers = inliers;
  estimate.rms_px = static_cast<float>(std::sqrt(sum_squared / std::max(inliers, 1)));
  estimate.previous_to_current = h;
  // A frame-to-frame motion never mirrors the image: the local scale at the centre is positive.
  const double cu = 0.5 * (s.width - 1), cv = 0.5 * (s.height - 1);
  const double w = h.h[6] * cu + h.h[7] * cv + h.h[8];
  const double determinant = to_matrix(h).determinant();
  estimate.valid = inliers >= o.min_inliers && w > 0 && determinant > 0;
  return estimate;
}

namespace {

using Matrix8 = Eigen::Matrix<double, 8, 8>;
using Vector8 = Eigen::Matrix<double, 8, 1>;
using Matrix9 = Eigen::Matrix<double, 9, 9>;
using Vector9 = Eigen::Matrix<double, 9, 1>;

// Homography through four correspondences (h33 = 1; with the points normalised around their
// centroid h33 = 0 would need a transformation far beyond any frame-to-frame motion).
bool minimal_homography(const double* x, const double* y, const double* xp, const double* yp,
                        Matrix3& out) {
  Matrix8 a;
  Vector8 b;
  for (int k = 0; k < 4; ++k) {
    a.row(2 * k) << x[k], y[k], 1, 0, 0, 0, -x[k] * xp[k], -y[k] * xp[k];
    a.row(2 * k + 1) << 0, 0, 0, x[k], y[k], 1, -x[k] * yp[k], -y[k] * yp[k];
    b(2 * k) = xp[k];
    b(2 * k + 1) = yp[k];
  }
  const Eigen::FullPivLU<Matrix8> lu(a);
  if (!lu.isInvertible()) return false;
  const Vector8 h = lu.solve(b);
  out << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), 1;
  return out.allFinite();
}

}  // namespace

bool MotionEstimator::fit_homography(int n, Homography& result, int& inlier_count) {
  State& s = *state_;
  const MotionOptions& o = options_;
  const double* px = s.px.data();
  const double* py = s.py.data();
  const double* cx = s.cx.data();
  const double* cy = s.cy.data();
  const double threshold_squared = o.inlier_px * o.inlier_px;

  // Errors in full-size pixels of the current frame; MSAC cost (inliers by their error, outliers
  // by the threshold) picks the better of two hypotheses with as many inliers.
  const auto score = [&](const Matrix3& h, std::uint8_t* flags, int& count) {
    double cost = 0;
    count = 0;
    for (int i = 0; i < n; ++i) {
      const double w = h(2, 0) * px[i] + h(2, 1) * py[i] + h(2, 2);
      const double ex = (h(0, 0) * px[i] + h(0, 1) * py[i] + h(0, 2)) / w - cx[i];
      const double ey = (h(1, 0) * px[i] + h(1, 1) * py[i] + h(1, 2)) / w - cy[i];
      const double e = ex * ex + ey * ey;
      const bool inlier = w > 0 && e < threshold_squared;
      flags[i] = inlier ? 1 : 0;
      count += inlier ? 1 : 0;
      cost += inlier ? e : threshold_squared;
    }
    return cost;
  };

  const Matrix3 t_previous = normalising_transform(px, py, s.all_index.data(), n);
  const Matrix3 t_current = normalising_transform(cx, cy, s.all_index.data(), n);
  const Matrix3 t_current_inverse = t_current.inverse();

  Random random{kRansacSeed};
  double best_cost = 0;
  int best_count = 0;
  bool found = false;
  int iterations_needed = o.ransac_iterations;
  for (int iteration = 0; iteration < iterations_needed; ++iteration) {
    // Four distinct tracks: the first steps of a Fisher-Yates shuffle (bounded, no retries).
    int* order = s.all_index.data();
    int pick[4];
    for (int k = 0; k < 4; ++k) {
      std::swap(order[k], order[k + random.below(n - k)]);
      pick[k] = order[k];
    }
    double x[4], y[4], xp[4], yp[4];
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d a = t_previous * Eigen::Vector3d(px[pick[k]], py[pick[k]], 1);
      const Eigen::Vector3d b = t_current * Eigen::Vector3d(cx[pick[k]], cy[pick[k]], 1);
      x[k] = a(0);
      y[k] = a(1);
      xp[k] = b(0);
      yp[k] = b(1);
    }
    // Three nearly collinear points make the sample degenerate.
    bool degenerate = false;
    for (int k = 0; k < 4 && !degenerate; ++k) {
      const int i0 = (k + 1) % 4, i1 = (k + 2) % 4, i2 = (k + 3) % 4;
      degenerate = std::abs(twice_area(x[i0], y[i0], x[i1], y[i1], x[i2], y[i2])) < 1e-2 ||
                   std::abs(twice_area(xp[i0], yp[i0], xp[i1], yp[i1], xp[i2], yp[i2])) < 1e-2;
    }
    if (degenerate) continue;
    Matrix3 h_normalised;
    if (!minimal_homography(x, y, xp, yp, h_normalised)) continue;
    const Matrix3 h = t_current_inverse * h_normalised * t_previous;
    int count = 0;
    const double cost = score(h, s.is_inlier.data(), count);
    if (!found || cost < best_cost) {
      found = true;
      best_cost = cost;
      best_count = count;
      std::copy(s.is_inlier.begin(), s.is_inlier.begin() + n, s.best_inlier.begin());
      // Stop once a sample of all inliers has been drawn with the wanted confidence.
      const double inlier_ratio = static_cast<double>(count) / n;
      const double all_inliers = std::pow(inlier_ratio, 4);
      if (all_inliers >= 1.0) {
        iterations_needed = std::min(iterations_needed, iteration + 1);
      } else if (all_inliers > 0) {
        const double needed = std::log(1 - kRansacConfidence) / std::log(1 - all_inliers) + 1;
        if (needed < iterations_needed) iterations_needed = static_cast<int>(needed);
      }
    }
  }
  if (!found || best_count < 4) return false;

  // Least-squares refit on the inliers (normalised DLT), repeated while the inlier set grows.
  std::copy(s.best_inlier.begin(), s.best_inlier.begin() + n, s.is_inlier.begin());
  Matrix3 h_best;
  int count = best_count;
  bool refitted = false;
  for (int round = 0; round < 3; ++round) {
    int m = 0;
    for (int i = 0; i < n; ++i)
      if (s.is_inlier[i]) s.inlier_index[m++] = i;
    if (m < 4) break;
    const Matrix3 tp = normalising_transform(px, py, s.inlier_index.data(), m);
    const Matrix3 tc = normalising_transform(cx, cy, s.inlier_index.data(), m);
    Matrix9 normal = Matrix9::Zero();
    for (int k = 0; k < m; ++k) {
      const int i = s.inlier_index[k];
      const double x = tp(0, 0) * px[i] + tp(0, 2), y = tp(1, 1) * py[i] + tp(1, 2);
      const double xp = tc(0, 0) * cx[i] + tc(0, 2), yp = tc(1, 1) * cy[i] + tc(1, 2);
      Vector9 r1, r2;
      r1 << x, y, 1, 0, 0, 0, -xp * x, -xp * y, -xp;
      r2 << 0, 0, 0, x, y, 1, -yp * x, -yp * y, -yp;
      normal.noalias() += r1 * r1.transpose();
      normal.noalias() += r2 * r2.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Matrix9> solver(normal);
    if (solver.info() != Eigen::Success) break;
    const Vector9 v = solver.eigenvectors().col(0);
    Matrix3 h_normalised;
    h_normalised << v(0), v(1), v(2), v(3), v(4), v(5), v(6), v(7), v(8);
    const Matrix3 h = tc.inverse() * h_normalised * tp;
    if (!h.allFinite() || std::abs(h(2, 2)) < 1e-12) break;
    const Matrix3 h_scaled = h / h(2, 2);
    int new_count = 0;
    score(h_scaled, s.best_inlier.data(), new_count);
    h_best = h_scaled;
    refitted = true;
    const bool grew = new_count > count;
    count = new_count;
    std::copy(s.best_inlier.begin(), s.best_inlier.begin() + n, s.is_inlier.begin());
    if (!grew) break;
  }
  if (!refitted) return false;
  result = to_homography(h_best);
  inlier_count = count;
  return true;
}

}  // namespace laserline::pipeline
