#pragma once

// The simulated scene's surface: its albedo texture (noise, hard-edged blobs, bright marks, a
// checkerboard), its relief, the caustic light on it and the sensor noise table. Internal to the
// simulator (hal/sim/); deterministic from the seed.

#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>
#include <vector>

#include "hal/sim/sim_scene.hpp"

namespace laserline::hal::sim {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kDeg = kPi / 180.0;
inline constexpr int kTextureLog2 = 10;  // 1024 x 1024 texels, wrapping
inline constexpr int kTextureSize = 1 << kTextureLog2;
// Stored with a copy of the first row and column after the last, so that the four texels of a
// bilinear sample are at i, i + 1, i + kTextureStride and i + kTextureStride + 1.
inline constexpr int kTextureStride = kTextureSize + 1;
inline constexpr int kFinestSpacing = 4;  // lattice spacing (texels) of the finest noise octave
inline constexpr std::size_t kNoiseTableSize = std::size_t{1} << 22;
inline constexpr float kNoiseTableScale = 16.0f;  // round(16 * N(0, 1)), clipped to int8
// The relief: a wrapping tile of heights on a square lattice, bilinearly interpolated, stored like
// the texture with a copy of the first row and column after the last.
inline constexpr int kReliefLog2 = 10;  // 1024 x 1024 lattice points
inline constexpr int kReliefSize = 1 << kReliefLog2;
inline constexpr int kReliefStride = kReliefSize + 1;
inline constexpr double kReliefCellM = 0.005;  // lattice spacing: the tile repeats every 5.12 m
// The caustic pattern: a wrapping tile like the texture's, of kCausticCells cells per side.
inline constexpr int kCausticSize = kTextureSize;
inline constexpr int kCausticCells = 8;

inline std::uint64_t mix64(std::uint64_t x) {
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

// Throws std::invalid_argument("SimScene: " + message) unless ok.
void require(bool ok, const std::string& message);
inline bool finite_nonneg(double x) {
  return std::isfinite(x) && x >= 0;
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

// Surface texture: multi-octave value noise plus hard-edged rectangles and discs, so that a
// corner detector finds features to track, and `marks_per_m2` bright marks (thin paint strokes
// and shells of albedo up to marks_albedo, with sharp edges). Returns the albedo tile.
std::vector<float> make_texture(const SimSceneOptions& o);
void validate_checkerboard(const SimSceneOptions& o);
// Paints the calibration checkerboard (if any) into the albedo tile.
void paint_checkerboard(std::vector<float>& albedo, const SimSceneOptions& o);

// The relief tile (heights in metres, see SimSceneOptions::relief_*), and its bilinear height at
// surface coordinates (x, y) in metres.
std::vector<float> make_relief(const SimSceneOptions& o);
double relief_at(const float* relief, double x, double y);

// The caustic pattern: a network of thin bright curves (where smooth noise crosses zero), values
// in [0, 1], wrapping every kCausticSize texels. `mean` receives its mean (about 0.03), at most
// 1 / caustic_peak: for a caustic_peak beyond 1 / (its mean) the curves are made thinner, so that
// the light between them need not be negative to keep the mean.
std::vector<float> make_caustics(std::uint64_t seed, double caustic_peak, float& mean);

// round(16 * N(0, 1)) by Box-Muller over our own uniform generator (std::normal_distribution is
// implementation-defined).
std::vector<std::int8_t> make_noise_table(std::uint64_t seed);

}  // namespace laserline::hal::sim
