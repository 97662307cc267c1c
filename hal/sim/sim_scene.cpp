#include "hal/sim/sim_scene.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace laserline::hal {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr int kMaxImageSide = 16384;
constexpr int kTextureLog2 = 10;  // 1024 x 1024 texels, wrapping
constexpr int kTextureSize = 1 << kTextureLog2;
// Stored with a copy of the first row and column after the last, so that the four texels of a
// bilinear sample are at i, i + 1, i + kTextureStride and i + kTextureStride + 1.
constexpr int kTextureStride = kTextureSize + 1;
constexpr int kFinestSpacing = 4;  // lattice spacing (texels) of the finest noise octave
constexpr std::size_t kNoiseTableSize = std::size_t{1} << 22;
constexpr float kNoiseTableScale = 16.0f;  // table holds round(16 * N(0, 1)), clipped to int8
constexpr double kFwhmToSigma = 2.3548200450309493;
constexpr float kBandSigmas = 5.0f;  // the laser profile is evaluated within +-5 sigma
constexpr float kEdgeRows = 1.5f;    // truth is NaN when the centre is within 2 px of the border
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kNoGlow = 1e30f;  // inverse depth floor of the glow in columns without a line
// The relief: a wrapping tile of heights on a square lattice, bilinearly interpolated, stored like
// the texture with a copy of the first row and column after the last.
constexpr int kReliefLog2 = 10;  // 1024 x 1024 lattice points
constexpr int kReliefSize = 1 << kReliefLog2;
constexpr int kReliefStride = kReliefSize + 1;
constexpr double kReliefCellM = 0.005;  // lattice spacing: the tile repeats every 5.12 m
constexpr int kNewtonSteps = 3;         // per pixel, from the base plane onto the relief

using Vec3 = std::array<double, 3>;
using Mat3 = std::array<double, 9>;  // row-major

std::uint64_t mix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// xoshiro256**: our own generator so the frames are the same with every standard library.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) {
    for (auto& s : s_) {
      seed = mix64(seed);
      s = seed;
    }
  }
  std::uint64_t next() {
    const std::uint64_t result = std::rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = std::rotl(s_[3], 45);
    return result;
  }
  // Uniform in (0, 1].
  double uniform() { return static_cast<double>((next() >> 11) + 1) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }

 private:
  std::array<std::uint64_t, 4> s_{};
};

Vec3 mul_transposed(const Mat3& m, const Vec3& v) {
  return {m[0] * v[0] + m[3] * v[1] + m[6] * v[2], m[1] * v[0] + m[4] * v[1] + m[7] * v[2],
          m[2] * v[0] + m[5] * v[1] + m[8] * v[2]};
}

Mat3 mul(const Mat3& a, const Mat3& b) {
  Mat3 r{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      r[i * 3 + j] = a[i * 3] * b[j] + a[i * 3 + 1] * b[3 + j] + a[i * 3 + 2] * b[6 + j];
    }
  }
  return r;
}

double dot(const Vec3& a, const Vec3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

Mat3 rot_x(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {1, 0, 0, 0, c, -s, 0, s, c};
}
Mat3 rot_y(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c, 0, s, 0, 1, 0, -s, 0, c};
}
Mat3 rot_z(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c, -s, 0, s, c, 0, 0, 0, 1};
}

// Everything render() and ground_truth() need about one frame, in the camera frame.
struct FrameGeometry {
  bool surface = false;  // the surface plane is in front of the camera
  Vec3 n{};              // surface: n . X = d_surface, n pointing away from the camera
  double d_surface = 0;
  std::array<double, 9> h{};   // pixel (u, v, 1) -> (S, T, W); texel coordinates are S/W, T/W
  std::array<double, 4> lp{};  // laser sheet a X + b Y + c Z + e = 0
  double fx = 1, fy = 1, cx = 0, cy = 0;
  // For the relief: surface coordinates (metres) of a camera-frame point X are
  // x = e1 . X + c1, y = e2 . X + c2, height toward the camera d_surface - n . X.
  Vec3 e1{}, e2{};
  double c1 = 0, c2 = 0;
  double texel_m = 1;
};

struct ColumnLine {
  bool hit = false;
  double v = 0;  // row of the line centre
  double z = 0;  // depth of the lit surface point
  double s = 0;  // texel coordinates of the lit surface point (set on relief only)
  double t = 0;
};

// Where the sheet meets the surface along column u, in closed form: with X = Z (xn, yn, 1) the
// sheet gives Z (a xn + b yn + c) = -e and the surface Z (n . r) = D; eliminating Z is linear in
// yn.
ColumnLine solve_column(const FrameGeometry& g, double u) {
  ColumnLine out;
  if (!g.surface) return out;
  const auto& [a, b, c, e] = g.lp;
  const double xn = (u - g.cx) / g.fx;
  const double den = g.d_surface * b + e * g.n[1];
  if (std::abs(den) < 1e-12) return out;
  const double yn = -(e * (g.n[0] * xn + g.n[2]) + g.d_surface * (a * xn + c)) / den;
  const double nr = g.n[0] * xn + g.n[1] * yn + g.n[2];
  if (!(nr > 0)) return out;
  out.z = g.d_surface / nr;
  out.v = g.cy + g.fy * yn;
  out.hit = std::isfinite(out.v) && std::isfinite(out.z) && out.z > 0;
  return out;
}

// Bilinear sample of the wrapping albedo tile at texel coordinates (s, t), |s|, |t| < 2^31.
inline float sample_tile(const float* tex, float s, float t) {
  constexpr int kMask = kTextureSize - 1;
  int is = static_cast<int>(s);
  int it = static_cast<int>(t);
  is -= s < static_cast<float>(is) ? 1 : 0;  // floor without a libm call
  it -= t < static_cast<float>(it) ? 1 : 0;
  const float fs = s - static_cast<float>(is);
  const float ft = t - static_cast<float>(it);
  const float* p = tex + (it & kMask) * kTextureStride + (is & kMask);
  const float p00 = p[0], p01 = p[1], p10 = p[kTextureStride], p11 = p[kTextureStride + 1];
  const float top = p00 + fs * (p01 - p00);
  const float bottom = p10 + fs * (p11 - p10);
  return top + ft * (bottom - top);
}

// min and max without branches: GCC does not if-convert a select that feeds a float-to-int
// conversion (it might trap), which would stop the row kernels from vectorising. Exact enough
// where the two arguments are of similar magnitude or one is far smaller than the other.
inline float branchless_max(float a, float b) {
  return 0.5f * (a + b + std::abs(a - b));
}

// exp(x) for x <= 0 to about 2e-5 relative: the backscatter glow needs no more and must be cheap.
inline float fast_exp_neg(float x) {
  x = branchless_max(x, -80.0f);
  const float y = x * 1.44269504f;
  std::int32_t i = static_cast<std::int32_t>(y);
  i -= y < static_cast<float>(i) ? 1 : 0;  // floor
  const float f = y - static_cast<float>(i);
  // 2^f, Taylor series in f ln2 to sixth order.
  const float p =
      1.0f + f * (0.693147181f +
                  f * (0.240226507f +
                       f * (0.0555041087f +
                            f * (0.00961812911f + f * (0.00133335581f + f * 0.000154035304f)))));
  return p * std::bit_cast<float>(static_cast<std::uint32_t>(i + 127) << 23);
}

// The row kernels below work in blocks of kBlock pixels with a constant trip count and restrict
// pointers: that is what GCC's -O2 cost model needs to vectorise them.
constexpr int kBlock = 16;

// Ambient light on the textured surface for `count` pixels (a multiple of kBlock) of one row;
// texel coordinates are (s0 + u su, t0 + u tu) / (w0 + u wu), one division per pixel. Rays with
// w <= w_min miss the surface (or nearly so); w_min keeps |s|, |t| below 2^31 for the int
// conversion.
void ambient_row(const float* __restrict tex, float s0, float su, float t0, float tu, float w0,
                 float wu, float w_min, float ambient, int count, float* __restrict row) {
  constexpr int kMask = kTextureSize - 1;
  for (int u0 = 0; u0 < count; u0 += kBlock) {
    alignas(64) std::int32_t index[kBlock];
    alignas(64) float fs[kBlock], ft[kBlock], gain[kBlock];
    for (int k = 0; k < kBlock; ++k) {
      const float fu = static_cast<float>(u0 + k);
      const float w = w0 + fu * wu;
      const float inv = 1.0f / branchless_max(w, w_min);
      const float s = (s0 + fu * su) * inv, t = (t0 + fu * tu) * inv;
      std::int32_t is = static_cast<std::int32_t>(s), it = static_cast<std::int32_t>(t);
      is -= s < static_cast<float>(is) ? 1 : 0;  // floor without a libm call
      it -= t < static_cast<float>(it) ? 1 : 0;
      fs[k] = s - static_cast<float>(is);
      ft[k] = t - static_cast<float>(it);
      index[k] = (it & kMask) * kTextureStride + (is & kMask);
      gain[k] = w > w_min ? ambient : 0.0f;
    }
    for (int k = 0; k < kBlock; ++k) {
      const float* p = tex + index[k];
      const float p00 = p[0], p01 = p[1], p10 = p[kTextureStride], p11 = p[kTextureStride + 1];
      const float top = p00 + fs[k] * (p01 - p00);
      const float bottom = p10 + fs[k] * (p11 - p10);
      row[u0 + k] = gain[k] * (top + ft[k] * (bottom - top));
    }
  }
}

// One image row of the relieved surface: the base-plane hit of each pixel's ray as in
// ambient_row, then Newton steps on g(h) = relief(hit at height h) - h, where the hit at height h
// slides from the base-plane hit toward the camera's foot point (foot_s, foot_t): by h / d for
// a camera at height d. The slope limit keeps g' <= -(1 - slope tan(view angle)) < 0, so the root
// is unique and a few steps reach it to well under a millimetre.
struct ReliefRow {
  float s0, su, t0, tu, w0, wu, w_min;  // base-plane texel coordinates, as in ambient_row
  float foot_s, foot_t;                 // texel coordinates of the camera's foot point
  float inv_height;                     // 1 / camera height above the base plane (1/m)
  float texel_to_cell;                  // relief lattice cells per texel
  float relief_max;                     // m
  float ambient;
};

void relief_row(const float* __restrict tex, const float* __restrict relief, const ReliefRow& r,
                int count, float* __restrict row) {
  constexpr int kTexMask = kTextureSize - 1;
  constexpr int kCellMask = kReliefSize - 1;
  // Lanes of kBlock pixels step together, so that the gathers of one step are independent and
  // the arithmetic vectorises (one pixel's Newton steps alone would be a chain of latencies).
  for (int u0 = 0; u0 < count; u0 += kBlock) {
    alignas(64) float sb[kBlock], tb[kBlock], ks[kBlock], kt[kBlock], h[kBlock], gain[kBlock];
    alignas(64) float fs[kBlock], ft[kBlock];
    alignas(64) std::int32_t index[kBlock];
    for (int k = 0; k < kBlock; ++k) {
      const float fu = static_cast<float>(u0 + k);
      const float w = r.w0 + fu * r.wu;
      const float inv = 1.0f / branchless_max(w, r.w_min);
      sb[k] = (r.s0 + fu * r.su) * inv;
      tb[k] = (r.t0 + fu * r.tu) * inv;
      ks[k] = (r.foot_s - sb[k]) * r.inv_height;
      kt[k] = (r.foot_t - tb[k]) * r.inv_height;
      h[k] = 0.0f;
      gain[k] = w > r.w_min ? r.ambient : 0.0f;
    }
    for (int step = 0; step < kNewtonSteps; ++step) {
      for (int k = 0; k < kBlock; ++k) {
        const float gs = (sb[k] + h[k] * ks[k]) * r.texel_to_cell;
        const float gt = (tb[k] + h[k] * kt[k]) * r.texel_to_cell;
        std::int32_t is = static_cast<std::int32_t>(gs), it = static_cast<std::int32_t>(gt);
        is -= gs < static_cast<float>(is) ? 1 : 0;  // floor without a libm call
        it -= gt < static_cast<float>(it) ? 1 : 0;
        fs[k] = gs - static_cast<float>(is);
        ft[k] = gt - static_cast<float>(it);
        index[k] = (it & kCellMask) * kReliefStride + (is & kCellMask);
      }
      alignas(64) float c00[kBlock], c01[kBlock], c10[kBlock], c11[kBlock];
      for (int k = 0; k < kBlock; ++k) {
        const float* p = relief + index[k];
        c00[k] = p[0];
        c01[k] = p[1];
        c10[k] = p[kReliefStride];
        c11[k] = p[kReliefStride + 1];
      }
      for (int k = 0; k < kBlock; ++k) {
        const float p00 = c00[k], p01 = c01[k], p10 = c10[k], p11 = c11[k];
        const float top = p00 + fs[k] * (p01 - p00), bottom = p10 + fs[k] * (p11 - p10);
        const float height = top + ft[k] * (bottom - top);
        const float d_ds = (p01 - p00) + ft[k] * ((p11 - p10) - (p01 - p00));
        const float d_dt = bottom - top;
        // g' < 0 where the slope limit holds; the floor keeps grazing rays from dividing by ~0.
        const float slope = (d_ds * ks[k] + d_dt * kt[k]) * r.texel_to_cell - 1.0f;
        const float next = h[k] - (height - h[k]) / std::min(slope, -0.2f);
        h[k] = std::min(std::max(next, 0.0f), r.relief_max);
      }
    }
    for (int k = 0; k < kBlock; ++k) {
      const float s = sb[k] + h[k] * ks[k], t = tb[k] + h[k] * kt[k];
      std::int32_t is = static_cast<std::int32_t>(s), it = static_cast<std::int32_t>(t);
      is -= s < static_cast<float>(is) ? 1 : 0;
      it -= t < static_cast<float>(it) ? 1 : 0;
      fs[k] = s - static_cast<float>(is);
      ft[k] = t - static_cast<float>(it);
      index[k] = (it & kTexMask) * kTextureStride + (is & kTexMask);
    }
    for (int k = 0; k < kBlock; ++k) {
      const float* p = tex + index[k];
      const float p00 = p[0], p01 = p[1], p10 = p[kTextureStride], p11 = p[kTextureStride + 1];
      const float top = p00 + fs[k] * (p01 - p00);
      const float bottom = p10 + fs[k] * (p11 - p10);
      row[u0 + k] = gain[k] * (top + ft[k] * (bottom - top));
    }
  }
}

// Backscatter for `count` pixels (a multiple of kBlock) of one row. The ray of pixel u meets the
// sheet at inverse depth p = p0 + u pu; it glows where the sheet is in front of the lit surface
// point, 0 < 1/p < Z, i.e. p > glow_floor[u] = 1/Z (a huge value in columns without a line).
void glow_row(float p0, float pu, float attenuation, float backscatter,
              const float* __restrict glow_floor, int count, float* __restrict row) {
  for (int u0 = 0; u0 < count; u0 += kBlock) {
    for (int k = 0; k < kBlock; ++k) {
      const float p = p0 + static_cast<float>(u0 + k) * pu;
      const float lowest = glow_floor[u0 + k];
      const float inv = 1.0f / branchless_max(p, lowest);  // finite: lowest > 0
      const float q = lowest * inv;                        // Z_sheet / Z_surface, in (0, 1]
      // A select between invariants (not of the product) keeps the loop free of branches.
      const float strength = p > lowest ? backscatter : 0.0f;
      row[u0 + k] += strength * (fast_exp_neg(-attenuation * inv) * q * q);
    }
  }
}

// Adds sensor noise and quantises one row to 8 bit with rounding and clipping. Option limits keep
// |x| far below 2^31, so the conversion comes before the clipping (which then vectorises).
void quantise_row(const float* __restrict row, const std::int8_t* __restrict noise, float scale,
                  int width, std::uint8_t* __restrict out) {
  // (Not a lambda: GCC loses the restrict qualifiers through the closure.)
  int u = 0;
  for (; u + kBlock <= width; u += kBlock) {
    for (int k = 0; k < kBlock; ++k) {
      const float x = row[u + k] + scale * static_cast<float>(noise[u + k]);
      const auto level = static_cast<std::int32_t>(x + 0.5f);  // round half up (x < 0 -> <= 0)
      out[u + k] = static_cast<std::uint8_t>(std::min(std::max(level, 0), 255));
    }
  }
  for (; u < width; ++u) {
    const float x = row[u] + scale * static_cast<float>(noise[u]);
    const auto level = static_cast<std::int32_t>(x + 0.5f);
    out[u] = static_cast<std::uint8_t>(std::min(std::max(level, 0), 255));
  }
}

void require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument("SimScene: " + message);
}

bool finite_nonneg(double x) {
  return std::isfinite(x) && x >= 0;
}

void validate(const SimSceneOptions& o) {
  const CameraIntrinsics& cam = o.calibration.camera;
  require(cam.width >= 8 && cam.width <= kMaxImageSide && cam.height >= 8 &&
              cam.height <= kMaxImageSide,
          "image size must be between 8 and " + std::to_string(kMaxImageSide) + " pixels");
  require(std::isfinite(cam.fx) && cam.fx > 0 && std::isfinite(cam.fy) && cam.fy > 0,
          "fx and fy must be positive");
  require(std::isfinite(cam.cx) && std::isfinite(cam.cy), "cx and cy must be finite");
  require(!cam.has_distortion(), "the simulated camera has no lens distortion");
  const auto plane = o.calibration.laser.plane_coefficients();
  for (double k : plane)
    require(std::isfinite(k), "laser plane coefficients must be finite");
  require(plane[0] * plane[0] + plane[1] * plane[1] + plane[2] * plane[2] > 1e-18,
          "laser plane normal must not be zero");
  require(finite_nonneg(o.calibration.laser.sheet_width_m), "sheet_width_m must be >= 0");
  require(std::isfinite(o.frame_rate_hz) && o.frame_rate_hz > 0, "frame_rate_hz must be > 0");
  require(std::isfinite(o.distance_m) && o.distance_m > 0, "distance_m must be > 0");
  require(std::isfinite(o.tilt_x_deg) && std::abs(o.tilt_x_deg) < 89.0 &&
              std::isfinite(o.tilt_y_deg) && std::abs(o.tilt_y_deg) < 89.0,
          "tilt_x_deg and tilt_y_deg must be within (-89, 89)");
  require(std::isfinite(o.texture_scale_m) && o.texture_scale_m > 0, "texture_scale_m must be > 0");
  require(finite_nonneg(o.texture_contrast) && o.texture_contrast <= 100,
          "texture_contrast must be within [0, 100]");
  require(finite_nonneg(o.ambient) && finite_nonneg(o.laser_peak) && finite_nonneg(o.blur_px) &&
              finite_nonneg(o.noise_sigma) && finite_nonneg(o.backscatter) &&
              finite_nonneg(o.attenuation_per_m),
          "ambient, laser_peak, blur_px, noise_sigma, backscatter, attenuation_per_m must be >= 0");
  // Grey levels far beyond 8 bit make no sense, and the limits keep the float-to-int conversion
  // of a pixel in range.
  require(o.ambient <= 1e4 && o.laser_peak <= 1e4 && o.backscatter <= 1e4 && o.noise_sigma <= 1e3,
          "ambient, laser_peak and backscatter must be <= 1e4, noise_sigma <= 1e3");
  require(finite_nonneg(o.sway_m) && finite_nonneg(o.sway_deg), "sway_m and sway_deg must be >= 0");
  require(std::isfinite(o.sway_period_s) && o.sway_period_s > 0, "sway_period_s must be > 0");
  require(finite_nonneg(o.scan_rate_deg_s) && o.scan_rate_deg_s <= 1000,
          "scan_rate_deg_s must be within [0, 1000]");
  require(finite_nonneg(o.scan_amplitude_deg) && o.scan_amplitude_deg <= 45,
          "scan_amplitude_deg must be within [0, 45]");
  require(finite_nonneg(o.relief_height_m) && o.relief_height_m <= 0.5 * o.distance_m,
          "relief_height_m must be within [0, distance_m / 2]");
  require(finite_nonneg(o.relief_min_height_m) &&
              (o.relief_height_m == 0 || o.relief_min_height_m <= o.relief_height_m),
          "relief_min_height_m must be within [0, relief_height_m]");
  require(finite_nonneg(o.relief_per_m2) && o.relief_per_m2 <= 100,
          "relief_per_m2 must be within [0, 100]");
  require(
      std::isfinite(o.relief_max_slope) && o.relief_max_slope >= 0.05 && o.relief_max_slope <= 1.0,
      "relief_max_slope must be within [0.05, 1]");
  // The widest feature (a pile 1.28 m long plus two flanks of 1.4 (pi / 2) height / slope)
  // must fit in the relief tile with room to spare.
  require(o.relief_height_m <= 0.72 * o.relief_max_slope,
          "relief_height_m / relief_max_slope must be <= 0.72 m (features must fit the 5.12 m "
          "relief tile)");
  require(std::isfinite(o.vehicle_speed_m_s) && std::abs(o.vehicle_speed_m_s) <= 10,
          "vehicle_speed_m_s must be within [-10, 10]");
}

// Shoulder of a relief feature at distance x beyond its top: 1 on the top, falling to 0 over
// `width` along half a cosine (smooth, with no tail). Its steepest slope is (pi / 2) / width.
double shoulder(double x, double width) {
  if (x <= 0) return 1.0;
  if (x >= width) return 0.0;
  return 0.5 * (1.0 + std::cos(kPi * x / width));
}

// The relief tile: round bumps (a cosine dome), flat-topped posts (a disc with a shoulder) and
// elongated piles (a capsule with a shoulder), combined by their maximum so that no flank is
// steeper than the steepest feature's. Heights in metres at the lattice points.
std::vector<float> make_relief(const SimSceneOptions& o) {
  const int n = kReliefSize;
  const double period = n * kReliefCellM;
  std::vector<double> height(static_cast<std::size_t>(n) * n, 0.0);
  Rng rng(o.seed ^ 0x72656c6965663031ULL);
  const auto count = static_cast<int>(std::lround(o.relief_per_m2 * period * period));
  for (int k = 0; k < count; ++k) {
    const double cx = rng.uniform(0.0, period), cy = rng.uniform(0.0, period);
    const double amplitude = rng.uniform(o.relief_min_height_m, o.relief_height_m);
    const double width = amplitude * 0.5 * kPi / o.relief_max_slope * rng.uniform(1.0, 1.4);
    const double kind = rng.uniform();
    double half_length = 0, top = 0;  // capsule: a segment of 2 half_length, top half-width
    if (kind < 0.4) {
      // A round bump.
    } else if (kind < 0.65) {
      top = rng.uniform(0.02, 0.10);  // a post
    } else {
      half_length = rng.uniform(0.15, 0.6);  // a pile lying along the surface
      top = rng.uniform(0.0, 0.04);
    }
    const double angle = rng.uniform(0.0, kPi);
    const double dx = std::cos(angle), dy = std::sin(angle);
    const double reach = std::min(half_length + top + width, 0.45 * period);
    const int i0 = static_cast<int>(std::floor((cx - reach) / kReliefCellM));
    const int i1 = static_cast<int>(std::ceil((cx + reach) / kReliefCellM));
    const int j0 = static_cast<int>(std::floor((cy - reach) / kReliefCellM));
    const int j1 = static_cast<int>(std::ceil((cy + reach) / kReliefCellM));
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        const double px = i * kReliefCellM - cx, py = j * kReliefCellM - cy;
        const double along = std::clamp(px * dx + py * dy, -half_length, half_length);
        const double ex = px - along * dx, ey = py - along * dy;
        const double h = amplitude * shoulder(std::sqrt(ex * ex + ey * ey) - top, width);
        double& cell = height[static_cast<std::size_t>(j & (n - 1)) * n + (i & (n - 1))];
        cell = std::max(cell, h);
      }
    }
  }
  std::vector<float> tile(static_cast<std::size_t>(kReliefStride) * kReliefStride);
  for (int y = 0; y < kReliefStride; ++y) {
    for (int x = 0; x < kReliefStride; ++x) {
      tile[static_cast<std::size_t>(y) * kReliefStride + x] =
          static_cast<float>(height[static_cast<std::size_t>(y & (n - 1)) * n + (x & (n - 1))]);
    }
  }
  return tile;
}

// Bilinear height of the relief tile at surface coordinates (x, y) in metres.
double relief_at(const float* relief, double x, double y) {
  const double gx = std::clamp(x / kReliefCellM, -1e9, 1e9);
  const double gy = std::clamp(y / kReliefCellM, -1e9, 1e9);
  const double fx0 = std::floor(gx), fy0 = std::floor(gy);
  const double fx = gx - fx0, fy = gy - fy0;
  const auto ix = static_cast<std::int64_t>(fx0) & (kReliefSize - 1);
  const auto iy = static_cast<std::int64_t>(fy0) & (kReliefSize - 1);
  const float* p = relief + iy * kReliefStride + ix;
  const double top = p[0] + fx * (p[1] - p[0]);
  const double bottom = p[kReliefStride] + fx * (p[kReliefStride + 1] - p[kReliefStride]);
  return top + fy * (bottom - top);
}

// Smooth value noise on a wrapping lattice of `spacing` texels, values in [-1, 1], added * amp.
void add_value_noise(std::vector<float>& dst, int spacing, float amp, Rng& rng) {
  const int n = kTextureSize;
  const int cells = n / spacing;
  std::vector<float> lattice(static_cast<std::size_t>(cells) * cells);
  for (float& x : lattice)
    x = static_cast<float>(rng.uniform(-1.0, 1.0));
  std::vector<float> weight(spacing);
  for (int i = 0; i < spacing; ++i) {
    const float f = static_cast<float>(i) / static_cast<float>(spacing);
    weight[i] = f * f * (3.0f - 2.0f * f);
  }
  for (int y = 0; y < n; ++y) {
    const int cy0 = y / spacing, cy1 = (cy0 + 1) % cells;
    const float wy = weight[y % spacing];
    const float* r0 = &lattice[static_cast<std::size_t>(cy0) * cells];
    const float* r1 = &lattice[static_cast<std::size_t>(cy1) * cells];
    float* out = &dst[static_cast<std::size_t>(y) * n];
    for (int x = 0; x < n; ++x) {
      const int cx0 = x / spacing, cx1 = (cx0 + 1) % cells;
      const float wx = weight[x % spacing];
      const float top = r0[cx0] + wx * (r0[cx1] - r0[cx0]);
      const float bottom = r1[cx0] + wx * (r1[cx1] - r1[cx0]);
      out[x] += amp * (top + wy * (bottom - top));
    }
  }
}

// Surface texture: multi-octave value noise plus hard-edged rectangles and discs, so that a
// corner detector finds features to track. Returns the albedo tile.
std::vector<float> make_texture(std::uint64_t seed, double contrast) {
  const int n = kTextureSize;
  Rng rng(seed ^ 0x7465787475726531ULL);
  std::vector<float> smooth(static_cast<std::size_t>(n) * n, 0.0f);
  float amp = 1.0f;
  for (int spacing = kFinestSpacing; spacing <= 128; spacing *= 2) {
    add_value_noise(smooth, spacing, amp, rng);
    amp *= 0.8f;
  }
  float peak = 1e-6f;
  for (float x : smooth)
    peak = std::max(peak, std::abs(x));

  std::vector<float> blobs(static_cast<std::size_t>(n) * n, 0.0f);
  const int count = 3500;
  for (int k = 0; k < count; ++k) {
    const int x0 = static_cast<int>(rng.uniform(0.0, n));
    const int y0 = static_cast<int>(rng.uniform(0.0, n));
    const double size_lo = kFinestSpacing, size_hi = 12.0 * kFinestSpacing;
    const int w = static_cast<int>(size_lo * std::pow(size_hi / size_lo, rng.uniform()));
    const int h = static_cast<int>(size_lo * std::pow(size_hi / size_lo, rng.uniform()));
    const float value =
        static_cast<float>((rng.uniform() < 0.5 ? -1.0 : 1.0) * rng.uniform(0.6, 1.0));
    const bool disc = rng.uniform() < 0.4;
    const int r2 = (w / 2) * (w / 2);
    for (int dy = 0; dy < (disc ? w : h); ++dy) {
      for (int dx = 0; dx < w; ++dx) {
        if (disc) {
          const int ox = dx - w / 2, oy = dy - w / 2;
          if (ox * ox + oy * oy > r2) continue;
        }
        const int x = (x0 + dx) & (n - 1), y = (y0 + dy) & (n - 1);
        blobs[static_cast<std::size_t>(y) * n + x] = value;
      }
    }
  }

  std::vector<float> albedo(static_cast<std::size_t>(kTextureStride) * kTextureStride);
  for (int y = 0; y < kTextureStride; ++y) {
    for (int x = 0; x < kTextureStride; ++x) {
      const std::size_t i = static_cast<std::size_t>(y & (n - 1)) * n + (x & (n - 1));
      const float noise = std::clamp(0.4f * smooth[i] / peak + blobs[i], -1.0f, 1.0f);
      albedo[static_cast<std::size_t>(y) * kTextureStride + x] =
          std::max(0.0f, 1.0f + static_cast<float>(contrast) * noise);
    }
  }
  return albedo;
}

void validate_checkerboard(const SimSceneOptions& o) {
  const SimSceneOptions::Checkerboard& board = o.checkerboard;
  require(board.columns >= 0 && board.rows >= 0, "checkerboard columns and rows must be >= 0");
  if (board.columns > 0 && board.rows > 0) {
    const double texel = o.texture_scale_m / kFinestSpacing;
    const double squares = board.square_m / texel;
    require(std::isfinite(squares) && squares >= 1 &&
                std::abs(squares - std::round(squares)) < 1e-6 * squares,
            "checkerboard square_m must be a whole number of texels (texture_scale_m / " +
                std::to_string(kFinestSpacing) + ")");
    // The board and its margin (one square each side) must fit in the half of the wrapping
    // texture tile around the surface point.
    const double reach = std::round(squares) * (std::max(board.columns, board.rows) + 3) / 2.0 +
                         std::max(std::abs(board.offset_x_m), std::abs(board.offset_y_m)) / texel;
    require(std::isfinite(reach) && reach <= kTextureSize / 2,
            "checkerboard with its margin and offset must lie within " +
                std::to_string(kTextureSize / 2) + " texels of the surface point");
    require(finite_nonneg(board.dark_albedo) && board.dark_albedo <= 1,
            "checkerboard dark_albedo must be within [0, 1]");
  }
}

// Paints the calibration checkerboard (if any) into the albedo tile. Texel i is the albedo at
// texture coordinate i (wrapping), and bilinear sampling puts an edge between texels i - 1 and i
// exactly at i - 1/2: the board's edges are laid on half-integers so its squares are exact.
void paint_checkerboard(std::vector<float>& albedo, const SimSceneOptions& o) {
  validate_checkerboard(o);
  const SimSceneOptions::Checkerboard& board = o.checkerboard;
  if (board.columns <= 0 || board.rows <= 0) return;
  const int square =
      static_cast<int>(std::lround(board.square_m * kFinestSpacing / o.texture_scale_m));
  const int squares_x = board.columns + 1, squares_y = board.rows + 1;
  // Board coordinate (in texels from the board's top-left edge) of texel 0's centre.
  const double texel = o.texture_scale_m / kFinestSpacing;
  const int origin_x =
      squares_x * square / 2 - static_cast<int>(std::lround(board.offset_x_m / texel));
  const int origin_y =
      squares_y * square / 2 - static_cast<int>(std::lround(board.offset_y_m / texel));
  const auto dark = static_cast<float>(board.dark_albedo);
  for (int y = 0; y < kTextureStride; ++y) {
    for (int x = 0; x < kTextureStride; ++x) {
      // The tile wraps: texel x stands for texture coordinate x or x - kTextureSize, whichever
      // is nearer 0 (the board lies within half a tile of it).
      const int sx = (x & (kTextureSize - 1)) < kTextureSize / 2
                         ? (x & (kTextureSize - 1))
                         : (x & (kTextureSize - 1)) - kTextureSize;
      const int sy = (y & (kTextureSize - 1)) < kTextureSize / 2
                         ? (y & (kTextureSize - 1))
                         : (y & (kTextureSize - 1)) - kTextureSize;
      // Texel centre in board coordinates is bx + 1/2: never on an edge (a multiple of square).
      const int bx = sx + origin_x, by = sy + origin_y;
      if (bx < -square || bx >= (squares_x + 1) * square || by < -square ||
          by >= (squares_y + 1) * square) {
        continue;  // outside board and margin: the texture stays
      }
      float value = 1.0f;  // margin
      if (bx >= 0 && bx < squares_x * square && by >= 0 && by < squares_y * square) {
        value = (bx / square + by / square) % 2 == 0 ? dark : 1.0f;
      }
      albedo[static_cast<std::size_t>(y) * kTextureStride + x] = value;
    }
  }
}

// round(16 * N(0, 1)) by Box-Muller over our own uniform generator (std::normal_distribution is
// implementation-defined).
std::vector<std::int8_t> make_noise_table(std::uint64_t seed) {
  Rng rng(seed ^ 0x6e6f697365746162ULL);
  std::vector<std::int8_t> table(kNoiseTableSize);
  auto quantise = [](double z) {
    return static_cast<std::int8_t>(std::clamp(std::lround(z * kNoiseTableScale), -127L, 127L));
  };
  for (std::size_t i = 0; i + 1 < table.size(); i += 2) {
    const double r = std::sqrt(-2.0 * std::log(rng.uniform()));
    const double phi = 2.0 * kPi * rng.uniform();
    table[i] = quantise(r * std::cos(phi));
    table[i + 1] = quantise(r * std::sin(phi));
  }
  return table;
}

}  // namespace

struct SimScene::Pose {
  Mat3 r{};  // camera to world: X_world = r X_cam + t
  Vec3 t{};
};

namespace {

FrameGeometry make_geometry(const SimSceneOptions& o, const Mat3& r, const Vec3& t) {
  FrameGeometry g;
  const CameraIntrinsics& cam = o.calibration.camera;
  g.fx = cam.fx;
  g.fy = cam.fy;
  g.cx = cam.cx;
  g.cy = cam.cy;
  g.lp = o.calibration.laser.plane_coefficients();

  // The surface in the world: through p0, normal n_w toward the camera, texture axes e1, e2.
  const Mat3 basis = mul(rot_x(o.tilt_x_deg * kDeg), rot_y(o.tilt_y_deg * kDeg));
  const Vec3 e1{basis[0], basis[3], basis[6]};
  const Vec3 e2{basis[1], basis[4], basis[7]};
  const Vec3 n_w{-basis[2], -basis[5], -basis[8]};
  const Vec3 p0{0.0, 0.0, o.distance_m};

  // In the camera frame: n_c . X = D with n_c = -R^T n_w, D = n_w . T - n_w . p0 (> 0 in front).
  const Vec3 rn = mul_transposed(r, n_w);
  g.n = {-rn[0], -rn[1], -rn[2]};
  g.d_surface = dot(n_w, t) - dot(n_w, p0);
  g.surface = g.d_surface > 0;
  if (!g.surface) return g;

  // Texture coordinate s = e1 . (X_w - p0) = Z (R^T e1) . r + e1 . (T - p0) with Z = D / (n_c . r),
  // so s (n_c . r) is linear in the ray r: a homography, here in texels and pixel coordinates.
  const double texel = o.texture_scale_m / kFinestSpacing;
  const Vec3 tp{t[0] - p0[0], t[1] - p0[1], t[2] - p0[2]};
  const Vec3 re1 = mul_transposed(r, e1), re2 = mul_transposed(r, e2);
  const double c1 = dot(e1, tp), c2 = dot(e2, tp);
  g.e1 = re1;
  g.e2 = re2;
  g.c1 = c1;
  g.c2 = c2;
  g.texel_m = texel;
  const std::array<Vec3, 3> rows{Vec3{(g.d_surface * re1[0] + c1 * g.n[0]) / texel,
                                      (g.d_surface * re1[1] + c1 * g.n[1]) / texel,
                                      (g.d_surface * re1[2] + c1 * g.n[2]) / texel},
                                 Vec3{(g.d_surface * re2[0] + c2 * g.n[0]) / texel,
                                      (g.d_surface * re2[1] + c2 * g.n[1]) / texel,
                                      (g.d_surface * re2[2] + c2 * g.n[2]) / texel},
                                 g.n};
  for (int i = 0; i < 3; ++i) {
    const Vec3& m = rows[i];
    g.h[i * 3 + 0] = m[0] / g.fx;
    g.h[i * 3 + 1] = m[1] / g.fy;
    g.h[i * 3 + 2] = m[2] - m[0] * g.cx / g.fx - m[1] * g.cy / g.fy;
  }
  return g;
}

float albedo_at(const FrameGeometry& g, const float* tex, double u, double v) {
  const double s = g.h[0] * u + g.h[1] * v + g.h[2];
  const double t = g.h[3] * u + g.h[4] * v + g.h[5];
  const double w = g.h[6] * u + g.h[7] * v + g.h[8];
  if (!(w > 0)) return 0.0f;
  return sample_tile(tex, static_cast<float>(std::clamp(s / w, -1e7, 1e7)),
                     static_cast<float>(std::clamp(t / w, -1e7, 1e7)));
}

// Where the sheet meets the relieved surface along column u. The sheet's points in the column
// form a line P + l D (the sheet cut by the plane through the camera and the column); the relief
// lies between heights 0 and relief_max, so the crossing is within the stretch of that line
// between those heights. Walked from the top in steps of at most one lattice cell, then bisected
// to double precision: the bilinear surface is continuous, so the sign change brackets a root.
// The first crossing from the top is the lit one (the slope limit makes it the only one).
ColumnLine solve_column_relief(const FrameGeometry& g, const float* relief, double relief_max,
                               double u) {
  ColumnLine out;
  if (!g.surface) return out;
  const auto& [a, b, c, e] = g.lp;
  const double xn = (u - g.cx) / g.fx;
  const Vec3 n1{1.0, 0.0, -xn}, n2{a, b, c};
  const Vec3 dir{n1[1] * n2[2] - n1[2] * n2[1], n1[2] * n2[0] - n1[0] * n2[2],
                 n1[0] * n2[1] - n1[1] * n2[0]};
  // P = alpha n1 + beta n2 with n1 . P = 0 (in the column plane) and n2 . P = -e (on the sheet).
  const double g11 = dot(n1, n1), g12 = dot(n1, n2), g22 = dot(n2, n2);
  const double det = g11 * g22 - g12 * g12;
  if (!(det > 1e-18 * g11 * g22)) return out;
  const double alpha = e * g12 / det, beta = -e * g11 / det;
  const Vec3 p{alpha * n1[0] + beta * n2[0], alpha * n1[1] + beta * n2[1],
               alpha * n1[2] + beta * n2[2]};
  // Height above the base plane along the line: q0 - l qd.
  const double q0 = g.d_surface - dot(g.n, p), qd = dot(g.n, dir);
  if (!(std::abs(qd) > 1e-12)) return out;
  const double margin = 1e-3;
  const double l_top = (q0 - (relief_max + margin)) / qd, l_bottom = (q0 + margin) / qd;
  const double x0 = dot(g.e1, p) + g.c1, xd = dot(g.e1, dir);
  const double y0 = dot(g.e2, p) + g.c2, yd = dot(g.e2, dir);
  auto above = [&](double l) {
    return (q0 - l * qd) - relief_at(relief, x0 + l * xd, y0 + l * yd);
  };
  const double span = std::abs(l_bottom - l_top) * std::hypot(xd, yd);
  const int steps = static_cast<int>(std::clamp(std::ceil(span / kReliefCellM), 2.0, 100000.0));
  double lo = l_top, hi = l_bottom;  // above(lo) > 0 >= above(hi) once bracketed
  for (int k = 1; k <= steps; ++k) {
    const double l = l_top + (l_bottom - l_top) * k / steps;
    if (above(l) <= 0) {
      hi = l;
      break;
    }
    lo = l;
  }
  for (int k = 0; k < 200 && lo != hi; ++k) {
    const double mid = 0.5 * (lo + hi);
    if (mid == lo || mid == hi) break;
    (above(mid) > 0 ? lo : hi) = mid;
  }
  const double l = 0.5 * (lo + hi);
  const Vec3 x{p[0] + l * dir[0], p[1] + l * dir[1], p[2] + l * dir[2]};
  if (!(x[2] > 0)) return out;
  out.z = x[2];
  out.v = g.cy + g.fy * x[1] / x[2];
  out.s = (x0 + l * xd) / g.texel_m;
  out.t = (y0 + l * yd) / g.texel_m;
  out.hit =
      std::isfinite(out.v) && std::isfinite(out.z) && std::isfinite(out.s) && std::isfinite(out.t);
  return out;
}

// Where the sheet meets the surface in column u: on the relief when there is one.
ColumnLine column_line(const FrameGeometry& g, const std::vector<float>& relief, double relief_max,
                       int u) {
  if (relief.empty()) return solve_column(g, u);
  return solve_column_relief(g, relief.data(), relief_max, u);
}

double line_sigma(const SimSceneOptions& o, double z) {
  const double sheet =
      o.calibration.camera.fy * o.calibration.laser.sheet_width_m / z / kFwhmToSigma;
  return std::max(1e-3, std::sqrt(sheet * sheet + o.blur_px * o.blur_px));
}

}  // namespace

SimScene::SimScene(const SimSceneOptions& options) : options_(options) {
  validate(options_);
  const auto width = static_cast<std::size_t>(options_.calibration.camera.width);
  texture_size_ = kTextureSize;
  texture_ = make_texture(options_.seed, options_.texture_contrast);
  paint_checkerboard(texture_, options_);
  noise_ = make_noise_table(options_.seed);
  // One image row, then the per-column 1 / Z of the lit point (for the backscatter glow), each
  // padded to whole kernel blocks; the padding never glows.
  const std::size_t padded = (width + kBlock - 1) / kBlock * kBlock;
  row_buffer_.assign(2 * padded, kNoGlow);
  scratch_truth_.row.assign(width, kNaN);
  scratch_truth_.depth_m.assign(width, kNaN);
  scratch_truth_.width_px.assign(width, kNaN);
  line_gain_.assign(width, 0.0f);
  if (options_.relief_height_m > 0 && options_.relief_per_m2 > 0) relief_ = make_relief(options_);
}

FrameFormat SimScene::format() const {
  const CameraIntrinsics& cam = options_.calibration.camera;
  return FrameFormat{cam.width, cam.height, cam.width, PixelFormat::kMono8};
}

SimScene::Pose SimScene::pose_at(std::uint64_t sequence) const {
  const double time = static_cast<double>(sequence) / options_.frame_rate_hz;
  const double phase = 2.0 * kPi / options_.sway_period_s * time;
  // Sinusoids shifted to start at zero, so that the world frame is the camera frame at t = 0.
  auto wave = [](double x, double shift) { return std::sin(x + shift) - std::sin(shift); };
  Pose pose;
  pose.t = {options_.sway_m * wave(phase, 0.0), options_.sway_m * 0.6 * wave(1.3 * phase, 1.0),
            options_.sway_m * 0.4 * wave(0.7 * phase, 2.0)};
  if (options_.vehicle_speed_m_s != 0) {
    // Along the surface's x axis (see make_geometry), so the distance to the surface stays.
    const Mat3 basis = mul(rot_x(options_.tilt_x_deg * kDeg), rot_y(options_.tilt_y_deg * kDeg));
    const double travel = options_.vehicle_speed_m_s * time;
    for (int i = 0; i < 3; ++i)
      pose.t[i] += travel * basis[i * 3];
  }
  const double amp = options_.sway_deg * kDeg;
  double scan = 0.0;
  if (options_.scan_rate_deg_s > 0 && options_.scan_amplitude_deg > 0) {
    // Triangle wave: 0 -> +A -> -A -> 0 over a period of 4 A / rate.
    const double a = options_.scan_amplitude_deg;
    const double x = std::fmod(options_.scan_rate_deg_s * time + a, 4.0 * a);  // in [0, 4A)
    scan = (x < 2.0 * a ? x - a : 3.0 * a - x) * kDeg;
  }
  const double ax = amp * wave(0.9 * phase, 0.5) + scan;
  const double ay = amp * 0.7 * wave(1.1 * phase, 2.3);
  const double az = amp * 0.5 * wave(0.8 * phase, 4.1);
  pose.r = mul(rot_z(az), mul(rot_y(ay), rot_x(ax)));
  return pose;
}

SimCameraPose SimScene::camera_pose(std::uint64_t sequence) const {
  const Pose pose = pose_at(sequence);  // camera -> world
  SimCameraPose out;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j)
      out.rotation[i * 3 + j] = pose.r[j * 3 + i];
  }
  const Vec3 t = mul_transposed(pose.r, pose.t);
  out.translation = {-t[0], -t[1], -t[2]};
  return out;
}

double SimScene::relief_height(double x_m, double y_m) const {
  return relief_.empty() ? 0.0 : relief_at(relief_.data(), x_m, y_m);
}

std::array<double, 3> SimScene::surface_point(double x_m, double y_m) const {
  const Mat3 basis = mul(rot_x(options_.tilt_x_deg * kDeg), rot_y(options_.tilt_y_deg * kDeg));
  const double h = relief_height(x_m, y_m);
  // Axes e1, e2 are the basis' first two columns, the normal toward the camera minus the third.
  std::array<double, 3> out{};
  for (int i = 0; i < 3; ++i) {
    out[i] = x_m * basis[i * 3] + y_m * basis[i * 3 + 1] - h * basis[i * 3 + 2];
  }
  out[2] += options_.distance_m;
  return out;
}

void SimScene::render(std::uint64_t sequence, bool laser_on, std::span<std::uint8_t> dst) {
  const FrameFormat fmt = format();
  if (dst.size() < fmt.bytes()) throw std::invalid_argument("SimScene::render: buffer too small");
  const int width = fmt.width, height = fmt.height;
  const Pose pose = pose_at(sequence);
  const FrameGeometry g = make_geometry(options_, pose.r, pose.t);
  const float* tex = texture_.data();

  // row_buffer_: one image row, then 1 / Z of the lit point per column (the glow floor), each
  // padded to whole kernel blocks.
  const int padded = (width + kBlock - 1) / kBlock * kBlock;
  float* row = row_buffer_.data();
  float* glow_floor = row_buffer_.data() + padded;
  float* centre = scratch_truth_.row.data();
  float* sigma = scratch_truth_.width_px.data();
  float* depth = scratch_truth_.depth_m.data();
  float* gain = line_gain_.data();

  // Per column: the line centre, its width and brightness. Rows [band_lo, band_hi] hold all bands.
  float band_lo = std::numeric_limits<float>::infinity();
  float band_hi = -std::numeric_limits<float>::infinity();
  float min_floor = kNoGlow;
  const bool laser = laser_on && (options_.laser_peak > 0 || options_.backscatter > 0);
  for (int u = 0; u < width; ++u) {
    const ColumnLine line =
        laser ? column_line(g, relief_, options_.relief_height_m, u) : ColumnLine{};
    if (!line.hit) {
      centre[u] = sigma[u] = depth[u] = kNaN;
      gain[u] = 0.0f;
      glow_floor[u] = kNoGlow;
      continue;
    }
    centre[u] = static_cast<float>(line.v);
    sigma[u] = static_cast<float>(line_sigma(options_, line.z));
    depth[u] = static_cast<float>(line.z);
    glow_floor[u] = static_cast<float>(1.0 / line.z);
    const float albedo = relief_.empty()
                             ? albedo_at(g, tex, u, centre[u])
                             : sample_tile(tex, static_cast<float>(std::clamp(line.s, -1e7, 1e7)),
                                           static_cast<float>(std::clamp(line.t, -1e7, 1e7)));
    gain[u] = static_cast<float>(options_.laser_peak * albedo *
                                 std::exp(-2.0 * options_.attenuation_per_m * line.z));
    band_lo = std::min(band_lo, centre[u] - kBandSigmas * sigma[u]);
    band_hi = std::max(band_hi, centre[u] + kBandSigmas * sigma[u]);
    min_floor = std::min(min_floor, glow_floor[u]);
  }

  const std::uint64_t frame_hash = mix64(mix64(options_.seed) ^ mix64(sequence + 0x51ce5eedULL));
  const std::uint64_t offsets = kNoiseTableSize - static_cast<std::size_t>(width) + 1;
  const float noise_scale = static_cast<float>(options_.noise_sigma) / kNoiseTableScale;
  const float ambient = static_cast<float>(options_.ambient);
  const auto& [la, lb, lc, le] = g.lp;
  const bool glow = laser && options_.backscatter > 0 && le != 0.0;
  const float backscatter = static_cast<float>(options_.backscatter);
  const float attenuation = static_cast<float>(options_.attenuation_per_m);

  for (int v = 0; v < height; ++v) {
    const double dv = v;
    if (g.surface && ambient > 0) {
      const double s_row = g.h[1] * dv + g.h[2], t_row = g.h[4] * dv + g.h[5];
      // Texel coordinates stay below 1e7 in magnitude (|numerator| / w_min at either end).
      const double reach = std::max({std::abs(s_row), std::abs(s_row + g.h[0] * padded),
                                     std::abs(t_row), std::abs(t_row + g.h[3] * padded)});
      const float w_min = static_cast<float>(std::max(reach * 1e-7, 1e-30));
      // On the relief the hit slides from the base-plane hit toward the camera's foot point (by
      // at most all the way: the height below is floored at the relief's), so with this floor
      // lattice and texel coordinates stay below 1e6 or the foot's, whichever is larger.
      const double texel_to_cell = g.texel_m / kReliefCellM;
      const float relief_w_min =
          static_cast<float>(std::max(reach * std::max(1.0, texel_to_cell) * 1e-6, 1e-30));
      if (relief_.empty()) {
        ambient_row(tex, static_cast<float>(s_row), static_cast<float>(g.h[0]),
                    static_cast<float>(t_row), static_cast<float>(g.h[3]),
                    static_cast<float>(g.h[7] * dv + g.h[8]), static_cast<float>(g.h[6]), w_min,
                    ambient, padded, row);
      } else {
        const ReliefRow r{static_cast<float>(s_row),
                          static_cast<float>(g.h[0]),
                          static_cast<float>(t_row),
                          static_cast<float>(g.h[3]),
                          static_cast<float>(g.h[7] * dv + g.h[8]),
                          static_cast<float>(g.h[6]),
                          relief_w_min,
                          static_cast<float>(g.c1 / g.texel_m),
                          static_cast<float>(g.c2 / g.texel_m),
                          static_cast<float>(1.0 / std::max(g.d_surface, options_.relief_height_m)),
                          static_cast<float>(texel_to_cell),
                          static_cast<float>(options_.relief_height_m),
                          ambient};
        relief_row(tex, relief_.data(), r, padded, row);
      }
    } else {
      std::fill(row, row + padded, 0.0f);
    }

    // Inverse depth where the ray of (u, v) meets the sheet: -(a xn + b yn + c) / e. Rows where
    // it nowhere exceeds the glow floor have no glow.
    const double p_row = glow ? -(lb * (dv - g.cy) / g.fy + lc - la * g.cx / g.fx) / le : 0.0;
    if (glow && p_row + std::max(0.0, -la / g.fx / le * padded) > min_floor) {
      glow_row(static_cast<float>(p_row), static_cast<float>(-la / g.fx / le), attenuation,
               backscatter, glow_floor, padded, row);
    }

    // The laser line: a Gaussian across the line, point-sampled at pixel centres.
    const float fv = static_cast<float>(v);
    if (laser && fv >= band_lo && fv <= band_hi) {
      for (int u = 0; u < width; ++u) {
        const float d = fv - centre[u];
        const float reach = kBandSigmas * sigma[u];
        if (d >= -reach && d <= reach) {
          row[u] += gain[u] * std::exp(-d * d / (2.0f * sigma[u] * sigma[u]));
        }
      }
    }

    // Sensor noise from the table at a hashed offset per row.
    const std::uint64_t offset = mix64(frame_hash + static_cast<std::uint64_t>(v)) % offsets;
    quantise_row(row, noise_.data() + offset, noise_scale, width,
                 dst.data() + static_cast<std::size_t>(v) * fmt.stride);
  }
}

void SimScene::ground_truth(std::uint64_t sequence, bool laser_on, SimGroundTruth& truth) const {
  const int width = options_.calibration.camera.width;
  const float last_row = static_cast<float>(options_.calibration.camera.height - 1);
  truth.row.resize(static_cast<std::size_t>(width));
  truth.depth_m.resize(static_cast<std::size_t>(width));
  truth.width_px.resize(static_cast<std::size_t>(width));
  const Pose pose = pose_at(sequence);
  const FrameGeometry g = make_geometry(options_, pose.r, pose.t);
  const bool laser = laser_on && options_.laser_peak > 0;
  for (int u = 0; u < width; ++u) {
    const ColumnLine line =
        laser ? column_line(g, relief_, options_.relief_height_m, u) : ColumnLine{};
    // The same float the renderer centres the profile on.
    const float v = static_cast<float>(line.v);
    if (!line.hit || !(v >= kEdgeRows && v <= last_row - kEdgeRows)) {
      truth.row[u] = truth.depth_m[u] = truth.width_px[u] = kNaN;
      continue;
    }
    truth.row[u] = v;
    truth.depth_m[u] = static_cast<float>(line.z);
    truth.width_px[u] = static_cast<float>(line_sigma(options_, line.z));
  }
}

}  // namespace laserline::hal
