#include "pipeline/motion.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace laserline::pipeline {

namespace {

constexpr int kMaxLevels = MotionOptions::kMaxPyramidLevels;
constexpr int kMaxWindowRadius = MotionOptions::kMaxWindowRadius;
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

Homography Homography::after(const Homography& first) const {
  return to_homography(to_matrix(*this) * to_matrix(first));
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

  // Camera motion (with a geometry only): the camera estimator's points to follow from the
  // previous frame, the whole pixels they are tracked from, their full-size patches (empty where
  // the patch does not fit), and where they were found in the current frame (NaN: lost).
  bool has_camera = false;
  std::vector<Point> follow_from;
  std::vector<Point> follow_pixel;
  std::vector<std::uint8_t> follow_has_patch;
  std::vector<std::uint8_t> follow_patches;
  int follow_count = 0;
  std::vector<std::array<float, 2>> followed;
};

MotionEstimator::MotionEstimator(const MotionOptions& options)
    : options_(options), camera_(options) {
  options.validate();
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

  s.has_camera = geometry != nullptr;
  const int follow = s.has_camera ? std::min(cells, o.scale_tracks) : 0;
  s.follow_from.assign(follow, Point{});
  s.follow_pixel.assign(follow, Point{});
  s.follow_has_patch.assign(follow, 0);
  s.follow_patches.assign(static_cast<std::size_t>(follow) * s.patch_bytes, 0);
  s.followed.assign(follow, {});
  s.follow_count = 0;
  if (s.has_camera) camera_.reset(*geometry, cells);
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
  if (s.has_camera) keep_follow_patches(frame);
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
  if (s.has_camera) {
    const int followed = follow_points(current, frame);
    estimate.camera = camera_.estimate({s.tracks.data(), static_cast<std::size_t>(s.track_count)},
                                       {s.followed.data(), static_cast<std::size_t>(followed)});
  }
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

int MotionEstimator::follow_points(int current, const ImageView& frame) {
  State& s = *state_;
  constexpr float kLost = std::numeric_limits<float>::quiet_NaN();
  for (int k = 0; k < s.follow_count; ++k) {
    s.followed[k] = {kLost, kLost};
    if (!s.follow_has_patch[k]) continue;
    const Point from = s.follow_pixel[k];
    const TrackResult t =
        track_point(s.pyramids[s.previous], s.pyramids[current],
                    s.follow_patches.data() + static_cast<std::ptrdiff_t>(k) * s.patch_bytes, frame,
                    options_, from[0], from[1]);
    // The point moves like the whole pixel next to it: the same sub-pixel offset.
    if (t.converged) {
      s.followed[k] = {t.u + (s.follow_from[k][0] - from[0]),
                       t.v + (s.follow_from[k][1] - from[1])};
    }
  }
  return s.follow_count;
}

void MotionEstimator::keep_follow_patches(const ImageView& frame) {
  State& s = *state_;
  const std::span<const std::array<float, 2>> points = camera_.to_follow();
  const int n = options_.window_radius + 1;
  const int count =
      std::min(static_cast<int>(points.size()), static_cast<int>(s.follow_from.size()));
  for (int k = 0; k < count; ++k) {
    const Point p = points[k];
    const Point pixel{std::round(p[0]), std::round(p[1])};
    const int u = static_cast<int>(pixel[0]), v = static_cast<int>(pixel[1]);
    s.follow_from[k] = p;
    s.follow_pixel[k] = pixel;
    s.follow_has_patch[k] = u - n >= 0 && v - n >= 0 && u + n < s.width && v + n < s.height;
    if (!s.follow_has_patch[k]) continue;
    std::uint8_t* patch = s.follow_patches.data() + static_cast<std::ptrdiff_t>(k) * s.patch_bytes;
    for (int j = -n; j <= n; ++j) {
      std::memcpy(patch, frame.row(v + j) + (u - n), static_cast<std::size_t>(2 * n + 1));
      patch += 2 * n + 1;
    }
  }
  s.follow_count = count;
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

// ---------------------------------------------------------------------------------------------
// Camera motion: five-point essential matrix

namespace laserline::pipeline {

namespace {

using Matrix10 = Eigen::Matrix<double, 10, 10>;
using Vector3 = Eigen::Vector3d;

// Polynomials in x, y, z of degree <= 3, coefficients by monomial, in order of degree: 1; x y z;
// x2 xy xz y2 yz z2; x3 x2y x2z xy2 xyz xz2 y3 y2z yz2 z3. A polynomial of degree <= d uses the
// first 1, 4, 10 or 20 coefficients.
using Polynomial = std::array<double, 20>;
constexpr std::array<std::array<int, 3>, 20> kMonomials{
    {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {2, 0, 0}, {1, 1, 0}, {1, 0, 1},
     {0, 2, 0}, {0, 1, 1}, {0, 0, 2}, {3, 0, 0}, {2, 1, 0}, {2, 0, 1}, {1, 2, 0},
     {1, 1, 1}, {1, 0, 2}, {0, 3, 0}, {0, 2, 1}, {0, 1, 2}, {0, 0, 3}}};

// kProduct[i][j]: the monomial i * j (for the degrees multiplied here it is always <= 3).
constexpr std::array<std::array<int, 10>, 10> kProduct = [] {
  std::array<std::array<int, 10>, 10> table{};
  for (int i = 0; i < 10; ++i) {
    for (int j = 0; j < 10; ++j) {
      table[i][j] = -1;
      for (int k = 0; k < 20; ++k) {
        if (kMonomials[k][0] == kMonomials[i][0] + kMonomials[j][0] &&
            kMonomials[k][1] == kMonomials[i][1] + kMonomials[j][1] &&
            kMonomials[k][2] == kMonomials[i][2] + kMonomials[j][2]) {
          table[i][j] = k;
        }
      }
    }
  }
  return table;
}();

// out += sign * a * b, a using its first na coefficients, b its first 4 (linear) or 10.
void multiply_add(const Polynomial& a, int na, const Polynomial& b, int nb, double sign,
                  Polynomial& out) {
  for (int i = 0; i < na; ++i) {
    if (a[i] == 0) continue;
    for (int j = 0; j < nb; ++j)
      out[kProduct[i][j]] += sign * a[i] * b[j];
  }
}

// The eight-point normal matrix row of one correspondence: current^T E previous = row . e.
Eigen::Matrix<double, 9, 1> epipolar_row(double x1, double y1, double x2, double y2) {
  Eigen::Matrix<double, 9, 1> row;
  row << x2 * x1, x2 * y1, x2, y2 * x1, y2 * y1, y2, x1, y1, 1;
  return row;
}

// The Sampson distance of a correspondence to the epipolar geometry E (normalised units) is
// residual / sqrt(denominator).
struct SampsonTerms {
  double residual, denominator;
};

SampsonTerms sampson_terms(const Matrix3& e, double x1, double y1, double x2, double y2) {
  const double ex0 = e(0, 0) * x1 + e(0, 1) * y1 + e(0, 2);
  const double ex1 = e(1, 0) * x1 + e(1, 1) * y1 + e(1, 2);
  const double ex2 = e(2, 0) * x1 + e(2, 1) * y1 + e(2, 2);
  const double etx0 = e(0, 0) * x2 + e(1, 0) * y2 + e(2, 0);
  const double etx1 = e(0, 1) * x2 + e(1, 1) * y2 + e(2, 1);
  return {x2 * ex0 + y2 * ex1 + ex2, ex0 * ex0 + ex1 * ex1 + etx0 * etx0 + etx1 * etx1};
}

// Squared Sampson distance (infinite where it is undefined).
double sampson_squared(const Matrix3& e, double x1, double y1, double x2, double y2) {
  const SampsonTerms s = sampson_terms(e, x1, y1, x2, y2);
  return s.denominator > 0 ? s.residual * s.residual / s.denominator
                           : std::numeric_limits<double>::infinity();
}

// Depths (d1 in the previous camera, d2 in the current one) of the point seen along (x1, y1, 1)
// and (x2, y2, 1), least squares of d2 x2 = d1 R x1 + t. False when the rays are parallel.
bool triangulate_depths(const Matrix3& r, const Vector3& t, double x1, double y1, double x2,
                        double y2, double& d1, double& d2) {
  const Vector3 a = r * Vector3(x1, y1, 1);
  const Vector3 b(x2, y2, 1);
  const double aa = a.dot(a), bb = b.dot(b), ab = a.dot(b), at = a.dot(t), bt = b.dot(t);
  const double det = aa * bb - ab * ab;
  if (!(det > 1e-14 * aa * bb)) return false;
  d1 = (-at * bb + ab * bt) / det;
  d2 = (aa * bt - ab * at) / det;
  return true;
}

// The essential matrix nearest to m (singular values (s, s, 0)), as U, V with det = +1.
bool essential_decomposition(const Matrix3& e, Matrix3& u, Matrix3& v) {
  const Eigen::JacobiSVD<Matrix3> svd(e, Eigen::ComputeFullU | Eigen::ComputeFullV);
  u = svd.matrixU();
  v = svd.matrixV();
  if (u.determinant() < 0) u = -u;
  if (v.determinant() < 0) v = -v;
  return svd.singularValues()(1) > 1e-9 * svd.singularValues()(0);
}

Matrix3 skew(const Vector3& t) {
  Matrix3 m;
  m << 0, -t(2), t(1), t(2), 0, -t(0), -t(1), t(0), 0;
  return m;
}

// Signed Sampson distance (normalised units): its square is sampson_squared() (0 where undefined).
double sampson_signed(const Matrix3& e, double x1, double y1, double x2, double y2) {
  const SampsonTerms s = sampson_terms(e, x1, y1, x2, y2);
  return s.denominator > 0 ? s.residual / std::sqrt(s.denominator) : 0.0;
}

// Levenberg-Marquardt on the inliers' Sampson distances over the five degrees of freedom of
// (R, t / |t|): the minimal and linear solutions fit a few points exactly or minimise an
// algebraic error, this minimises (nearly) the image error. Bounded iterations; the
// Jacobian by forward differences (five more essential matrices per iteration).
void refine_motion(const double* x1, const double* y1, const double* x2, const double* y2,
                   const std::uint8_t* inlier, int n, Matrix3& rotation, Vector3& translation) {
  using Vector5 = Eigen::Matrix<double, 5, 1>;
  using Matrix5 = Eigen::Matrix<double, 5, 5>;
  const auto apply = [](const Matrix3& r, const Vector3& t, const Vector5& delta, Matrix3& r_out,
                        Vector3& t_out) {
    const Vector3 w = delta.head<3>();
    const double angle = w.norm();
    r_out = angle > 0 ? Matrix3(Eigen::AngleAxisd(angle, w / angle).toRotationMatrix() * r) : r;
    // Two directions across t.
    const Vector3 helper = std::abs(t(0)) < 0.9 ? Vector3::UnitX() : Vector3::UnitY();
    const Vector3 b1 = t.cross(helper).normalized();
    const Vector3 b2 = t.cross(b1);
    t_out = (t + delta(3) * b1 + delta(4) * b2).normalized();
  };
  const auto cost = [&](const Matrix3& e) {
    double sum = 0;
    for (int i = 0; i < n; ++i) {
      if (!inlier[i]) continue;
      const double d = sampson_signed(e, x1[i], y1[i], x2[i], y2[i]);
      sum += d * d;
    }
    return sum;
  };
  constexpr double kStep = 1e-7;
  double lambda = 1e-3;
  double current = cost(skew(translation) * rotation);
  for (int iteration = 0; iteration < 10; ++iteration) {
    const Matrix3 e = skew(translation) * rotation;
    std::array<Matrix3, 5> moved;
    for (int k = 0; k < 5; ++k) {
      Vector5 delta = Vector5::Zero();
      delta(k) = kStep;
      Matrix3 r;
      Vector3 t;
      apply(rotation, translation, delta, r, t);
      moved[k] = skew(t) * r;
    }
    Matrix5 normal = Matrix5::Zero();
    Vector5 gradient = Vector5::Zero();
    for (int i = 0; i < n; ++i) {
      if (!inlier[i]) continue;
      const double d = sampson_signed(e, x1[i], y1[i], x2[i], y2[i]);
      Vector5 j;
      for (int k = 0; k < 5; ++k)
        j(k) = (sampson_signed(moved[k], x1[i], y1[i], x2[i], y2[i]) - d) / kStep;
      normal.noalias() += j * j.transpose();
      gradient.noalias() += j * d;
    }
    bool improved = false;
    for (int attempt = 0; attempt < 4 && !improved; ++attempt) {
      Matrix5 damped = normal;
      for (int k = 0; k < 5; ++k)
        damped(k, k) += lambda * std::max(normal(k, k), 1e-12);
      const Vector5 delta = damped.ldlt().solve(-gradient);
      if (!delta.allFinite()) return;
      Matrix3 r;
      Vector3 t;
      apply(rotation, translation, delta, r, t);
      const double candidate = cost(skew(t) * r);
      if (candidate < current) {
        const bool converged = current - candidate < 1e-10 * current;
        rotation = r;
        translation = t;
        current = candidate;
        lambda = std::max(lambda * 0.1, 1e-9);
        improved = true;
        if (converged) return;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) return;
  }
}

Matrix3 project_to_essential(const Matrix3& m) {
  const Eigen::JacobiSVD<Matrix3> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d s = svd.singularValues();
  const double mean = 0.5 * (s(0) + s(1));
  return svd.matrixU() * Eigen::Vector3d(mean, mean, 0).asDiagonal() * svd.matrixV().transpose();
}

}  // namespace

int five_point_essentials(const std::array<std::array<double, 2>, 5>& previous,
                          const std::array<std::array<double, 2>, 5>& current,
                          std::array<std::array<double, 9>, 10>& essentials) {
  // E = x X + y Y + z Z + W over the null space of the five epipolar constraints.
  Eigen::Matrix<double, 9, 5> constraints;
  for (int k = 0; k < 5; ++k) {
    constraints.col(k) = epipolar_row(previous[k][0], previous[k][1], current[k][0], current[k][1]);
  }
  const Eigen::HouseholderQR<Eigen::Matrix<double, 9, 5>> qr(constraints);
  const Eigen::Matrix<double, 9, 9> q = qr.householderQ();
  // Rank below five: the sample does not fix a four-dimensional null space.
  const auto& r = qr.matrixQR();
  double largest = 0;
  for (int k = 0; k < 5; ++k)
    largest = std::max(largest, std::abs(r(k, k)));
  for (int k = 0; k < 5; ++k)
    if (!(std::abs(r(k, k)) > 1e-10 * largest)) return 0;

  // Entries of E as linear polynomials: coefficients of 1, x, y, z.
  std::array<std::array<Polynomial, 3>, 3> e{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Polynomial& p = e[i][j];
      p.fill(0);
      p[0] = q(3 * i + j, 8);
      p[1] = q(3 * i + j, 5);
      p[2] = q(3 * i + j, 6);
      p[3] = q(3 * i + j, 7);
    }
  }
  // Ten cubic constraints: det(E) = 0 and 2 E E^T E - trace(E E^T) E = 0.
  std::array<Polynomial, 10> equations{};
  for (Polynomial& p : equations)
    p.fill(0);
  {
    Polynomial minor{};
    const auto cofactor = [&](int r1, int c1, int r2, int c2) {
      minor.fill(0);
      multiply_add(e[r1][c1], 4, e[r2][c2], 4, 1, minor);
      multiply_add(e[r1][c2], 4, e[r2][c1], 4, -1, minor);
    };
    cofactor(1, 1, 2, 2);
    multiply_add(minor, 10, e[0][0], 4, 1, equations[0]);
    cofactor(1, 0, 2, 2);
    multiply_add(minor, 10, e[0][1], 4, -1, equations[0]);
    cofactor(1, 0, 2, 1);
    multiply_add(minor, 10, e[0][2], 4, 1, equations[0]);
  }
  std::array<std::array<Polynomial, 3>, 3> eet{};
  Polynomial trace{};
  trace.fill(0);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      eet[i][j].fill(0);
      for (int k = 0; k < 3; ++k)
        multiply_add(e[i][k], 4, e[j][k], 4, 1, eet[i][j]);
    }
    for (int k = 0; k < 10; ++k)
      trace[k] += eet[i][i][k];
  }
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Polynomial& p = equations[1 + 3 * i + j];
      for (int k = 0; k < 3; ++k)
        multiply_add(eet[i][k], 10, e[k][j], 4, 2, p);
      multiply_add(trace, 10, e[i][j], 4, -1, p);
    }
  }

  // Gauss-Jordan: the ten cubic monomials in terms of the ten monomials of degree <= 2, the
  // basis b = (x2 xy xz y2 yz z2 x y z 1) of the quotient ring.
  constexpr std::array<int, 10> kBasis{4, 5, 6, 7, 8, 9, 1, 2, 3, 0};
  Matrix10 cubic, rest;
  for (int row = 0; row < 10; ++row) {
    for (int k = 0; k < 10; ++k) {
      cubic(row, k) = equations[row][10 + k];
      rest(row, k) = equations[row][kBasis[k]];
    }
  }
  const Eigen::FullPivLU<Matrix10> lu(cubic);
  if (!lu.isInvertible()) return 0;
  const Matrix10 reduced = lu.solve(rest);  // cubic monomials = -reduced * b
  // Multiplication by x on the basis: x b = action * b; the eigenvectors at the solutions are b.
  Matrix10 action = Matrix10::Zero();
  for (int k = 0; k < 6; ++k)  // x * (x2 xy xz y2 yz z2) = x3 x2y x2z xy2 xyz xz2
    action.row(k) = -reduced.row(k);
  action(6, 0) = 1;  // x * x = x2
  action(7, 1) = 1;  // x * y = xy
  action(8, 2) = 1;  // x * z = xz
  action(9, 6) = 1;  // x * 1 = x
  if (!action.allFinite()) return 0;
  // Eigenvalues only (the Schur vectors cost as much again); the eigenvector of a real one
  // from (action - x I) b = 0 with b's last entry 1, in the least-squares sense.
  const Eigen::EigenSolver<Matrix10> eigen(action, false);
  if (eigen.info() != Eigen::Success) return 0;
  int count = 0;
  for (int k = 0; k < 10; ++k) {
    const std::complex<double> lambda = eigen.eigenvalues()(k);
    if (std::abs(lambda.imag()) > 1e-8 * (1 + std::abs(lambda.real()))) continue;
    Eigen::Matrix<double, 10, 9> shifted = action.leftCols<9>();
    for (int i = 0; i < 9; ++i)
      shifted(i, i) -= lambda.real();
    Eigen::Matrix<double, 10, 1> right = -action.col(9);
    right(9) += lambda.real();
    const Eigen::ColPivHouseholderQR<Eigen::Matrix<double, 10, 9>> solver(shifted);
    if (solver.rank() < 9) continue;
    const Eigen::Matrix<double, 9, 1> b = solver.solve(right);
    const double x = b(6), y = b(7), z = b(8);
    std::array<double, 9>& out = essentials[count];
    double norm = 0;
    for (int i = 0; i < 9; ++i) {
      out[i] = x * q(i, 5) + y * q(i, 6) + z * q(i, 7) + q(i, 8);
      norm += out[i] * out[i];
    }
    norm = std::sqrt(norm);
    if (!(norm > 0) || !std::isfinite(norm)) continue;
    for (double& value : out)
      value /= norm;
    ++count;
  }
  return count;
}

CameraMotionEstimator::CameraMotionEstimator(const MotionOptions& options) : options_(options) {}

void CameraMotionEstimator::reset(const ScannerGeometry& geometry, int max_tracks) {
  if (max_tracks < 0) throw std::invalid_argument("CameraMotionEstimator::reset: max_tracks < 0");
  geometry_ = geometry;
  focal_ = std::sqrt(geometry.fx * geometry.fy);
  const auto size = static_cast<std::size_t>(max_tracks);
  for (auto* v : {&x1_, &y1_, &x2_, &y2_, &residual_})
    v->assign(size, 0);
  order_.assign(size, 0);
  inlier_.assign(size, 0);
  candidate_.assign(size, 0);
  const auto follow = std::min(size, static_cast<std::size_t>(options_.scale_tracks));
  follow_.assign(follow, {});
  follow_depth_.assign(follow, 0);
  track_count_ = 0;
  follow_count_ = 0;
}

void CameraMotionEstimator::forget() {
  follow_count_ = 0;
  track_count_ = 0;
}

std::array<double, 2> CameraMotionEstimator::normalise(double u, double v) const {
  double x = 0, y = 0;
  // Beyond the lens model's fold (far outside the calibrated field) the distorted ray is the best
  // there is; its track then most likely ends as an outlier.
  if (!geometry_.normalised(u, v, x, y))
    return {(u - geometry_.cx) / geometry_.fx, (v - geometry_.cy) / geometry_.fy};
  return {x, y};
}

CameraMotion CameraMotionEstimator::estimate(std::span<const FeatureTrack> tracks,
                                             std::span<const std::array<float, 2>> followed) {
  const MotionOptions& o = options_;
  CameraMotion result;
  const int n = static_cast<int>(std::min(tracks.size(), x1_.size()));
  track_count_ = static_cast<std::size_t>(n);
  // The points followed into this frame, consumed below; new ones are chosen at the end.
  const std::size_t previous_follow = followed.size() == follow_count_ ? follow_count_ : 0;
  follow_count_ = 0;
  for (int i = 0; i < n; ++i) {
    const auto a = normalise(tracks[i].previous_u, tracks[i].previous_v);
    const auto b = normalise(tracks[i].u, tracks[i].v);
    x1_[i] = a[0];
    y1_[i] = a[1];
    x2_[i] = b[0];
    y2_[i] = b[1];
    order_[i] = i;
    inlier_[i] = 0;
  }
  if (n < std::max(5, o.min_inliers)) return result;

  // MSAC cost over Sampson distances in pixels (focal length times the normalised distance).
  const double threshold = o.essential_inlier_px / focal_;
  const double threshold_squared = threshold * threshold;
  // Stops early (flags and count then incomplete) once the cost reaches `limit`: most hypotheses
  // of a sample are wrong, and a wrong one is out after a few outliers.
  constexpr double kNoLimit = std::numeric_limits<double>::infinity();
  const auto score = [&](const Matrix3& e, std::uint8_t* flags, int& count, double limit) {
    double cost = 0;
    count = 0;
    for (int i = 0; i < n && cost < limit; ++i) {
      const double d = sampson_squared(e, x1_[i], y1_[i], x2_[i], y2_[i]);
      const bool inlier = d < threshold_squared;
      flags[i] = inlier ? 1 : 0;
      count += inlier ? 1 : 0;
      cost += inlier ? d : threshold_squared;
    }
    return cost;
  };

  Random random{kRansacSeed};
  Matrix3 best_e;
  double best_cost = 0;
  int best_count = 0;
  bool found = false;
  int iterations_needed = o.essential_ransac_iterations;
  std::array<std::array<double, 2>, 5> sample_previous, sample_current;
  std::array<std::array<double, 9>, 10> solutions;
  for (int iteration = 0; iteration < iterations_needed; ++iteration) {
    for (int k = 0; k < 5; ++k) {
      std::swap(order_[k], order_[k + random.below(n - k)]);
      const int i = order_[k];
      sample_previous[k] = {x1_[i], y1_[i]};
      sample_current[k] = {x2_[i], y2_[i]};
    }
    const int count = five_point_essentials(sample_previous, sample_current, solutions);
    for (int s = 0; s < count; ++s) {
      const Matrix3 e =
          Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(solutions[s].data());
      int inliers = 0;
      const double cost = score(e, candidate_.data(), inliers, found ? best_cost : kNoLimit);
      if (found && cost >= best_cost) continue;
      found = true;
      best_cost = cost;
      best_count = inliers;
      best_e = e;
      std::copy(candidate_.begin(), candidate_.begin() + n, inlier_.begin());
      // Stop once a sample of all inliers has been drawn with the wanted confidence.
      const double all_inliers = std::pow(static_cast<double>(inliers) / n, 5);
      if (all_inliers >= 1.0) {
        iterations_needed = std::min(iterations_needed, iteration + 1);
      } else if (all_inliers > 0) {
        const double needed = std::log(1 - kRansacConfidence) / std::log(1 - all_inliers) + 1;
        if (needed < iterations_needed) iterations_needed = static_cast<int>(needed);
      }
    }
  }
  if (!found || best_count < 5) return result;

  // Linear refit on the inliers (eight-point, projected onto the essential matrices), kept when
  // its cost is lower; repeated while it improves.
  for (int round = 0; round < 2 && best_count >= 8; ++round) {
    Eigen::Matrix<double, 9, 9> normal = Eigen::Matrix<double, 9, 9>::Zero();
    for (int i = 0; i < n; ++i) {
      if (!inlier_[i]) continue;
      const auto row = epipolar_row(x1_[i], y1_[i], x2_[i], y2_[i]);
      normal.noalias() += row * row.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> solver(normal);
    if (solver.info() != Eigen::Success) break;
    const Eigen::Matrix<double, 9, 1> v = solver.eigenvectors().col(0);
    const Matrix3 e = project_to_essential(
        Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data()));
    if (!e.allFinite()) break;
    int inliers = 0;
    const double cost = score(e, candidate_.data(), inliers, best_cost);
    if (cost >= best_cost) break;
    best_cost = cost;
    best_count = inliers;
    best_e = e;
    std::copy(candidate_.begin(), candidate_.begin() + n, inlier_.begin());
  }
  result.inliers = best_count;

  // The four decompositions (R, +-t): the one that puts the inliers in front of both cameras.
  Matrix3 u, v;
  if (!essential_decomposition(best_e, u, v)) return result;
  Matrix3 w;
  w << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  const std::array<Matrix3, 2> rotations{u * w * v.transpose(), u * w.transpose() * v.transpose()};
  Matrix3 rotation = rotations[0];
  Vector3 translation = u.col(2);
  int best_front = -1;
  for (const Matrix3& r : rotations) {
    for (const double sign : {1.0, -1.0}) {
      const Vector3 t = sign * u.col(2);
      int front = 0;
      for (int i = 0; i < n; ++i) {
        double d1 = 0, d2 = 0;
        if (inlier_[i] && triangulate_depths(r, t, x1_[i], y1_[i], x2_[i], y2_[i], d1, d2) &&
            d1 > 0 && d2 > 0) {
          ++front;
        }
      }
      if (front > best_front) {
        best_front = front;
        rotation = r;
        translation = t;
      }
    }
  }
  // Refined on the image error; the inliers are those of the refined motion.
  refine_motion(x1_.data(), y1_.data(), x2_.data(), y2_.data(), inlier_.data(), n, rotation,
                translation);
  best_e = skew(translation) * rotation;
  score(best_e, inlier_.data(), best_count, kNoLimit);
  result.inliers = best_count;
  best_front = 0;
  for (int i = 0; i < n; ++i) {
    double d1 = 0, d2 = 0;
    if (inlier_[i] &&
        triangulate_depths(rotation, translation, x1_[i], y1_[i], x2_[i], y2_[i], d1, d2) &&
        d1 > 0 && d2 > 0) {
      ++best_front;
    }
  }
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c)
      result.rotation[r * 3 + c] = rotation(r, c);
    result.translation[r] = translation(r);
  }

  // Rotation alone (Procrustes on the inliers' rays): when it explains the image motion to within
  // essential_min_parallax_px, the translation's direction is not determined by the image.
  Matrix3 correlation = Matrix3::Zero();
  for (int i = 0; i < n; ++i) {
    if (!inlier_[i]) continue;
    correlation.noalias() += Vector3(x2_[i], y2_[i], 1).normalized() *
                             Vector3(x1_[i], y1_[i], 1).normalized().transpose();
  }
  const Eigen::JacobiSVD<Matrix3> svd(correlation, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Matrix3 fix = Matrix3::Identity();
  fix(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1 : 1;
  const Matrix3 rotation_only = svd.matrixU() * fix * svd.matrixV().transpose();
  int m = 0;
  for (int i = 0; i < n; ++i) {
    if (!inlier_[i]) continue;
    const Vector3 p = rotation_only * Vector3(x1_[i], y1_[i], 1);
    residual_[m++] = p(2) > 0 ? focal_ * std::hypot(p(0) / p(2) - x2_[i], p(1) / p(2) - y2_[i])
                              : std::numeric_limits<double>::infinity();
  }
  std::nth_element(residual_.begin(), residual_.begin() + m / 2, residual_.begin() + m);
  const double parallax_px = residual_[m / 2];

  // Cheirality must hold for nearly all inliers: with noise and no parallax, depths take either
  // sign and the decomposition is a guess.
  result.valid = best_count >= o.min_inliers && 4 * best_front >= 3 * best_count &&
                 parallax_px >= o.essential_min_parallax_px;
  if (!result.valid) return result;

  // Relative scale: the points followed from the previous frame, at depth follow_depth_ (units
  // of the previous |t|) in it; their depth from this pair is in units of this |t|.
  int ratios = 0;
  for (std::size_t k = 0; k < previous_follow; ++k) {
    if (!std::isfinite(followed[k][0]) || !std::isfinite(followed[k][1])) continue;
    const auto a = normalise(follow_[k][0], follow_[k][1]);
    const auto b = normalise(followed[k][0], followed[k][1]);
    if (!(sampson_squared(best_e, a[0], a[1], b[0], b[1]) < threshold_squared)) continue;
    double d1 = 0, d2 = 0;
    if (!triangulate_depths(rotation, translation, a[0], a[1], b[0], b[1], d1, d2) || !(d1 > 0) ||
        !(d2 > 0)) {
      continue;
    }
    residual_[ratios++] = follow_depth_[k] / d1;
  }
  if (ratios >= 5) {
    std::nth_element(residual_.begin(), residual_.begin() + ratios / 2, residual_.begin() + ratios);
    result.relative_scale = residual_[ratios / 2];
  }

  // New points to follow: inliers in front of both cameras, spread over the list.
  int front = 0;
  for (int i = 0; i < n; ++i) {
    double d1 = 0, d2 = 0;
    if (inlier_[i] &&
        triangulate_depths(rotation, translation, x1_[i], y1_[i], x2_[i], y2_[i], d1, d2) &&
        d1 > 0 && d2 > 0) {
      order_[front] = i;
      residual_[front] = d2;
      ++front;
    }
  }
  const int wanted = std::min(front, static_cast<int>(follow_.size()));
  for (int k = 0; k < wanted; ++k) {
    const int j = static_cast<int>(static_cast<long long>(k) * front / wanted);
    follow_[k] = {tracks[order_[j]].u, tracks[order_[j]].v};
    follow_depth_[k] = residual_[j];
  }
  follow_count_ = static_cast<std::size_t>(wanted);
  return result;
}

}  // namespace laserline::pipeline
