// The simulated scene's renderer: each frame row by row (ambient light on the textured and
// relieved surface, caustics, backscatter, the laser line with its halo, marine snow, sensor
// noise), in vectorisable row kernels; mono or colour.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <span>

#include "hal/sim/sim_lines.hpp"
#include "hal/sim/sim_render.hpp"
#include "hal/sim/sim_scene.hpp"
#include "hal/sim/sim_surface.hpp"

namespace laserline::hal {

using namespace sim;

namespace {

constexpr float kBandSigmas = 5.0f;  // the laser profile is evaluated within +-5 sigma
constexpr int kNewtonSteps = 3;      // per pixel, from the base plane onto the relief

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
  // The objects (relief, and the texture on them) moved by this much along the surface's x axis.
  float shift_cells, shift_texels;
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
        const float gs = (sb[k] + h[k] * ks[k]) * r.texel_to_cell - r.shift_cells;
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
      const float moved = h[k] > 1e-4f ? r.shift_texels : 0.0f;  // on an object
      const float s = sb[k] + h[k] * ks[k] - moved, t = tb[k] + h[k] * kt[k];
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

// The caustic light on the surface: two drifting copies of the caustic tile at different scales
// (so the pattern changes as well as moves), as a factor on the ambient light.
struct CausticMap {
  float scale1, s1, t1, scale2, s2, t2;  // caustic texel = texel * scale + offset
  float base, gain;  // light = base + gain * pattern, the pattern's mean giving 1
};

// Multiplies `count` pixels (a multiple of kBlock) of ambient light by the caustic light at the
// base-plane point each sees (texel coordinates as in ambient_row).
void caustic_row(const float* __restrict caustic, float s0, float su, float t0, float tu, float w0,
                 float wu, float w_min, const CausticMap& m, int count, float* __restrict row) {
  for (int u0 = 0; u0 < count; u0 += kBlock) {
    for (int k = 0; k < kBlock; ++k) {
      const float fu = static_cast<float>(u0 + k);
      const float inv = 1.0f / branchless_max(w0 + fu * wu, w_min);
      const float s = (s0 + fu * su) * inv, t = (t0 + fu * tu) * inv;
      const float c = sample_tile(caustic, s * m.scale1 + m.s1, t * m.scale1 + m.t1) +
                      sample_tile(caustic, s * m.scale2 + m.s2, t * m.scale2 + m.t2);
      row[u0 + k] *= m.base + m.gain * 0.5f * c;
    }
  }
}

// The light of the line across it, at distance d from its centre (pixels along the epipolar
// line): the Gaussian core and, in turbid water, the forward-scattered halo of the same energy.
struct LineProfile {
  float core_gain, core_sigma, halo_gain, halo_sigma, reach;
};

LineProfile line_profile(float gain, float sigma, const SimSceneOptions& o) {
  const auto f = static_cast<float>(o.forward_scatter);
  const float halo_sigma = std::hypot(sigma, static_cast<float>(o.scatter_halo_px));
  LineProfile p{gain * (1.0f - f), sigma, gain * f * sigma / halo_sigma, halo_sigma,
                kBandSigmas * (f > 0 ? halo_sigma : sigma)};
  return p;
}

inline float line_light(float d, const LineProfile& p) {
  if (!(std::abs(d) <= p.reach)) return 0.0f;
  float light = p.core_gain * std::exp(-d * d / (2.0f * p.core_sigma * p.core_sigma));
  if (p.halo_gain > 0)
    light += p.halo_gain * std::exp(-d * d / (2.0f * p.halo_sigma * p.halo_sigma));
  return light;
}

}  // namespace

void SimScene::colour_row(int v, const float* ambient, const float* light,
                          std::uint64_t noise_offset, std::uint8_t* out) {
  const int width = options_.calibration.camera.width;
  const int padded = (width + kBlock - 1) / kBlock * kBlock;
  const float noise_scale = static_cast<float>(options_.noise_sigma) / kNoiseTableScale;
  float* channel = row_buffer_.data() + 3 * padded;
  const std::uint64_t offsets = kNoiseTableSize - static_cast<std::size_t>(width) + 1;
  for (int c = 0; c < 3; ++c) {
    const auto a = static_cast<float>(options_.ambient_rgb[static_cast<std::size_t>(c)]);
    const auto l = static_cast<float>(options_.laser_rgb[static_cast<std::size_t>(c)]);
    for (int u = 0; u < padded; ++u)
      channel[u] = a * ambient[u] + l * light[u];
    // Each channel its own noise: the row's offset moved on by a hash of the channel.
    const std::uint64_t offset =
        (noise_offset + mix64(static_cast<std::uint64_t>(c) + 1)) % offsets;
    quantise_row(channel, noise_.data() + offset, noise_scale, width,
                 channel_rows_.data() + static_cast<std::size_t>(c) * padded);
  }
  const std::uint8_t* r = channel_rows_.data();
  const std::uint8_t* g = r + padded;
  const std::uint8_t* b = g + padded;
  if (options_.colour == SimColour::kRgb) {
    for (int u = 0; u < width; ++u) {
      out[3 * u] = r[u];
      out[3 * u + 1] = g[u];
      out[3 * u + 2] = b[u];
    }
    return;
  }
  // A mosaic: each pixel its own colour's sample, the 2x2 cell read row by row.
  static constexpr std::array<std::array<int, 4>, 4> kCells{{
      {0, 1, 1, 2},  // RGGB
      {1, 0, 2, 1},  // GRBG
      {1, 2, 0, 1},  // GBRG
      {2, 1, 1, 0},  // BGGR
  }};
  const auto& cell = kCells[static_cast<std::size_t>(options_.colour) -
                            static_cast<std::size_t>(SimColour::kBayerRggb)];
  const std::uint8_t* rows[3] = {r, g, b};
  const int phase = (v & 1) * 2;
  for (int u = 0; u < width; ++u)
    out[u] = rows[cell[static_cast<std::size_t>(phase + (u & 1))]][u];
}
void SimScene::place_snow(std::uint64_t sequence) {
  snow_.clear();
  if (options_.snow_per_frame == 0 || options_.laser_peak <= 0) return;
  const CameraIntrinsics& cam = options_.calibration.camera;
  const Eigen::Vector4d plane = options_.calibration.laser.plane_coefficients();
  const double a = plane[0], b = plane[1], c = plane[2], e = plane[3];
  Rng rng(mix64(options_.seed ^ 0x736e6f7766616c6cULL) ^ mix64(sequence));
  const float* depth = scratch_truth_.depth_m.data();
  for (int i = 0; i < options_.snow_per_frame; ++i) {
    // A particle on a lit line, in the sheet somewhere between the nearest depth and the surface.
    int k = -1;
    for (int attempt = 0; attempt < 8 && k < 0; ++attempt) {
      const int pick = std::min(static_cast<int>(rng.uniform(0.0, lines_.count)), lines_.count - 1);
      if (std::isfinite(depth[pick])) k = pick;
    }
    if (k < 0 || e == 0) continue;
    const double far = depth[k] - 0.02;
    if (!(far > options_.snow_min_depth_m)) continue;
    const double z = rng.uniform(options_.snow_min_depth_m, far);
    // Along the line the sheet's inverse depth is affine in the position:
    // 1/Z = -(a xn + b yn + c) / e with xn = (x - cx) / fx, yn = (y - cy) / fy.
    const auto [x0, y0] = lines_.to_image(k, 0.0);
    const double base = a * (x0 - cam.cx) / cam.fx + b * (y0 - cam.cy) / cam.fy + c;
    const double rate = a * lines_.along[0] / cam.fx + b * lines_.along[1] / cam.fy;
    if (!(std::abs(rate) > 0)) continue;
    const double position = (-e / z - base) / rate;
    const auto [x, y] = lines_.to_image(k, position);
    if (!(x >= 0 && x <= cam.width - 1 && y >= 0 && y <= cam.height - 1)) continue;
    const double peak = options_.snow_brightness * options_.laser_peak * rng.uniform(0.3, 1.0) *
                        std::exp(-2.0 * options_.attenuation_per_m * z);
    snow_.push_back({static_cast<float>(x), static_cast<float>(y),
                     static_cast<float>(options_.snow_size_px * rng.uniform(0.6, 1.4)),
                     static_cast<float>(peak)});
  }
}

void SimScene::add_laser_row(int v, float* light) const {
  const int width = options_.calibration.camera.width;
  const float* centre = scratch_truth_.position.data();
  const float* sigma = scratch_truth_.width_px.data();
  const float* gain = line_gain_.data();
  const float fv = static_cast<float>(v);
  if (lines_.line_step[0] == 1.0 && lines_.along[1] == 1.0) {
    // Columns: the line's centre row in each.
    if (options_.forward_scatter == 0) {
      for (int u = 0; u < width; ++u) {
        const float d = fv - centre[u];
        const float reach = kBandSigmas * sigma[u];
        if (d >= -reach && d <= reach) {
          light[u] += gain[u] * std::exp(-d * d / (2.0f * sigma[u] * sigma[u]));
        }
      }
    } else {
      for (int u = 0; u < width; ++u) {
        if (std::isnan(centre[u])) continue;
        light[u] += line_light(fv - centre[u], line_profile(gain[u], sigma[u], options_));
      }
    }
  } else if (lines_.line_step[1] == 1.0 && lines_.along[0] == 1.0) {
    // Rows: row v is line v, the line's centre column in it.
    if (!std::isnan(centre[v])) {
      const LineProfile p = line_profile(gain[v], sigma[v], options_);
      const int lo = std::max(0, static_cast<int>(std::ceil(centre[v] - p.reach)));
      const int hi = std::min(width - 1, static_cast<int>(std::floor(centre[v] + p.reach)));
      for (int u = lo; u <= hi; ++u)
        light[u] += line_light(static_cast<float>(u) - centre[v], p);
    }
  } else {
    // At an angle: each pixel between two lines, the line's centre, width and brightness
    // interpolated between them (the nearer alone where the other is not lit).
    for (int u = 0; u < width; ++u) {
      const auto [line, position] = lines_.to_family(u, v);
      const int k0 = static_cast<int>(std::floor(line));
      const double t = line - k0;
      const bool lit0 = k0 >= 0 && k0 < lines_.count && !std::isnan(centre[k0]);
      const bool lit1 = k0 + 1 >= 0 && k0 + 1 < lines_.count && !std::isnan(centre[k0 + 1]);
      float c = 0, s = 0, g = 0;
      if (lit0 && lit1) {
        const auto w = static_cast<float>(t);
        c = centre[k0] + w * (centre[k0 + 1] - centre[k0]);
        s = sigma[k0] + w * (sigma[k0 + 1] - sigma[k0]);
        g = gain[k0] + w * (gain[k0 + 1] - gain[k0]);
      } else if (lit0 && t < 0.5) {
        c = centre[k0], s = sigma[k0], g = gain[k0];
      } else if (lit1 && t >= 0.5) {
        c = centre[k0 + 1], s = sigma[k0 + 1], g = gain[k0 + 1];
      } else {
        continue;
      }
      light[u] += line_light(static_cast<float>(position) - c, line_profile(g, s, options_));
    }
  }
  // Marine snow: round spots.
  for (const Particle& p : snow_) {
    const float reach = 4.0f * p.sigma;
    const float dy = fv - p.y;
    if (!(std::abs(dy) <= reach)) continue;
    const int lo = std::max(0, static_cast<int>(std::ceil(p.x - reach)));
    const int hi = std::min(width - 1, static_cast<int>(std::floor(p.x + reach)));
    const float inverse = 1.0f / (2.0f * p.sigma * p.sigma);
    for (int u = lo; u <= hi; ++u) {
      const float dx = static_cast<float>(u) - p.x;
      light[u] += p.peak * std::exp(-(dx * dx + dy * dy) * inverse);
    }
  }
}

void SimScene::render(std::uint64_t sequence, bool laser_on, std::span<std::uint8_t> dst) {
  const FrameFormat fmt = format();
  if (dst.size() < raw_bytes()) throw std::invalid_argument("SimScene::render: buffer too small");
  const int width = fmt.width, height = fmt.height;
  const bool colour = options_.colour != SimColour::kMono;
  const std::size_t raw_stride = raw_bytes() / static_cast<std::size_t>(height);
  const double time = static_cast<double>(sequence) / options_.frame_rate_hz;
  const Pose pose = pose_at(sequence);
  const FrameGeometry g = make_geometry(options_, pose.r, pose.t, options_.object_speed_m_s * time);
  const float* tex = texture_.data();

  // row_buffer_: one image row, then the glow floor of each of its pixels (the inverse depth of
  // the lit point of its line), each padded to whole kernel blocks.
  const int padded = (width + kBlock - 1) / kBlock * kBlock;
  float* row = row_buffer_.data();
  float* pixel_floor = row_buffer_.data() + padded;
  // The laser's light: in the row itself for mono frames (the same sums, in the same order, as
  // ever), apart from the ambient light for colour ones (the two are coloured differently).
  float* light = colour ? row_buffer_.data() + 2 * padded : row;
  float* centre = scratch_truth_.position.data();
  float* sigma = scratch_truth_.width_px.data();
  float* depth = scratch_truth_.depth_m.data();
  float* gain = line_gain_.data();
  float* glow_floor = glow_floor_.data();

  // Per line: the line centre, its width and brightness. Rows [band_lo, band_hi] hold all of it.
  float band_lo = std::numeric_limits<float>::infinity();
  float band_hi = -std::numeric_limits<float>::infinity();
  float min_floor = kNoGlow;
  const bool laser = laser_on && (options_.laser_peak > 0 || options_.backscatter > 0);
  const float* relief = relief_.empty() ? nullptr : relief_.data();
  const auto across = static_cast<float>(std::abs(lines_.along[1]));
  const auto between = static_cast<float>(std::abs(lines_.line_step[1]));
  for (int k = 0; k < lines_.count; ++k) {
    const LineHit line =
        laser ? solve_line(g, lines_, k, relief, options_.relief_height_m) : LineHit{};
    if (!line.hit) {
      centre[k] = sigma[k] = depth[k] = kNaN;
      gain[k] = 0.0f;
      glow_floor[k] = kNoGlow;
      continue;
    }
    centre[k] = static_cast<float>(line.position);
    sigma[k] = static_cast<float>(line_sigma(options_, lines_, line.z));
    depth[k] = static_cast<float>(line.z);
    glow_floor[k] = static_cast<float>(1.0 / line.z);
    const auto [x, y] = lines_.to_image(k, centre[k]);
    const float albedo = relief == nullptr
                             ? albedo_at(g, tex, x, y)
                             : sample_tile(tex, static_cast<float>(std::clamp(line.s, -1e7, 1e7)),
                                           static_cast<float>(std::clamp(line.t, -1e7, 1e7)));
    gain[k] = static_cast<float>(options_.laser_peak * albedo *
                                 std::exp(-2.0 * options_.attenuation_per_m * line.z));
    const float reach = line_profile(gain[k], sigma[k], options_).reach;
    band_lo = std::min(band_lo, static_cast<float>(y) - (reach * across + between));
    band_hi = std::max(band_hi, static_cast<float>(y) + (reach * across + between));
    min_floor = std::min(min_floor, glow_floor[k]);
  }
  place_snow(sequence);

  const std::uint64_t frame_hash = mix64(mix64(options_.seed) ^ mix64(sequence + 0x51ce5eedULL));
  const std::uint64_t offsets = kNoiseTableSize - static_cast<std::size_t>(width) + 1;
  const float noise_scale = static_cast<float>(options_.noise_sigma) / kNoiseTableScale;
  const float ambient = static_cast<float>(options_.ambient);
  const double la = g.lp[0], lb = g.lp[1], lc = g.lp[2], le = g.lp[3];
  const bool glow = laser && options_.backscatter > 0 && le != 0.0;
  const float backscatter = static_cast<float>(options_.backscatter);
  const float attenuation = static_cast<float>(options_.attenuation_per_m);
  const bool columns = lines_.line_step[0] == 1.0 && lines_.along[1] == 1.0;
  const bool rows = lines_.line_step[1] == 1.0 && lines_.along[0] == 1.0;
  // The caustics drift over the surface: two copies of the pattern, one at 0.77 times the scale of
  // the other, moving in different directions.
  CausticMap caustic{};
  if (!caustics_.empty()) {
    const double caustic_texel = options_.caustic_scale_m * kCausticCells / kCausticSize;
    const double scale = g.texel_m / caustic_texel;
    const double travel = options_.caustic_speed_m_s * time / caustic_texel;
    caustic = {static_cast<float>(scale),
               static_cast<float>(0.96 * travel),
               static_cast<float>(0.28 * travel),
               static_cast<float>(0.77 * scale),
               static_cast<float>(-0.35 * travel + 311.7),
               static_cast<float>(0.94 * travel + 157.3),
               0.0f,
               0.0f};
    // base + gain * mean = 1 and base + gain = caustic_peak: the curves' light, the mean kept.
    caustic.gain = static_cast<float>((options_.caustic_peak - 1.0) / (1.0 - caustic_mean_));
    // >= 0 but for float rounding when make_caustics() thinned the curves (base 0).
    caustic.base = std::max(0.0f, 1.0f - caustic.gain * caustic_mean_);
  }
  const float veil = static_cast<float>(options_.veiling);

  for (int v = 0; v < height; ++v) {
    const double dv = v;
    if (g.surface && ambient > 0) {
      const double s_row = g.h(0, 1) * dv + g.h(0, 2), t_row = g.h(1, 1) * dv + g.h(1, 2);
      // Texel coordinates stay below 1e7 in magnitude (|numerator| / w_min at either end).
      const double reach = std::max({std::abs(s_row), std::abs(s_row + g.h(0, 0) * padded),
                                     std::abs(t_row), std::abs(t_row + g.h(1, 0) * padded)});
      const float w_min = static_cast<float>(std::max(reach * 1e-7, 1e-30));
      // On the relief the hit slides from the base-plane hit toward the camera's foot point (by
      // at most all the way: the height below is floored at the relief's), so with this floor
      // lattice and texel coordinates stay below 1e6 or the foot's, whichever is larger.
      const double texel_to_cell = g.texel_m / kReliefCellM;
      const float relief_w_min =
          static_cast<float>(std::max(reach * std::max(1.0, texel_to_cell) * 1e-6, 1e-30));
      if (relief_.empty()) {
        ambient_row(tex, static_cast<float>(s_row), static_cast<float>(g.h(0, 0)),
                    static_cast<float>(t_row), static_cast<float>(g.h(1, 0)),
                    static_cast<float>(g.h(2, 1) * dv + g.h(2, 2)), static_cast<float>(g.h(2, 0)),
                    w_min, ambient, padded, row);
      } else {
        const ReliefRow r{static_cast<float>(s_row),
                          static_cast<float>(g.h(0, 0)),
                          static_cast<float>(t_row),
                          static_cast<float>(g.h(1, 0)),
                          static_cast<float>(g.h(2, 1) * dv + g.h(2, 2)),
                          static_cast<float>(g.h(2, 0)),
                          relief_w_min,
                          static_cast<float>(g.c1 / g.texel_m),
                          static_cast<float>(g.c2 / g.texel_m),
                          static_cast<float>(1.0 / std::max(g.d_surface, options_.relief_height_m)),
                          static_cast<float>(texel_to_cell),
                          static_cast<float>(options_.relief_height_m),
                          ambient,
                          static_cast<float>(g.object_shift_m / kReliefCellM),
                          static_cast<float>(g.object_shift_m / g.texel_m)};
        relief_row(tex, relief_.data(), r, padded, row);
      }
      if (!caustics_.empty()) {
        caustic_row(caustics_.data(), static_cast<float>(s_row), static_cast<float>(g.h(0, 0)),
                    static_cast<float>(t_row), static_cast<float>(g.h(1, 0)),
                    static_cast<float>(g.h(2, 1) * dv + g.h(2, 2)), static_cast<float>(g.h(2, 0)),
                    w_min, caustic, padded, row);
      }
    } else {
      std::fill(row, row + padded, 0.0f);
    }
    if (colour) std::fill(light, light + padded, 0.0f);
    if (veil > 0) {
      // Ambient light scattered by the water into a uniform glare, taken from the image's
      // contrast.
      for (int u = 0; u < padded; ++u)
        row[u] = (1.0f - veil) * row[u] + veil * ambient;
    }

    // Inverse depth where the ray of (u, v) meets the sheet: -(a xn + b yn + c) / e. Rows where
    // it nowhere exceeds the glow floor have no glow.
    const double p_row = glow ? -(lb * (dv - g.cy) / g.fy + lc - la * g.cx / g.fx) / le : 0.0;
    if (glow && p_row + std::max(0.0, -la / g.fx / le * padded) > min_floor) {
      const float* floor = glow_floor;  // columns: each pixel's line is its column
      if (!columns) {
        for (int u = 0; u < width; ++u) {
          const double line = rows ? static_cast<double>(v) : std::round(lines_.to_family(u, v)[0]);
          pixel_floor[u] = line >= 0 && line < lines_.count
                               ? glow_floor[static_cast<std::size_t>(line)]
                               : kNoGlow;
        }
        floor = pixel_floor;
      }
      glow_row(static_cast<float>(p_row), static_cast<float>(-la / g.fx / le), attenuation,
               backscatter, floor, padded, light);
    }

    // The laser line (and marine snow).
    const float fv = static_cast<float>(v);
    if (laser && ((fv >= band_lo && fv <= band_hi) || !snow_.empty())) add_laser_row(v, light);

    // Sensor noise from the table at a hashed offset per row.
    const std::uint64_t offset = mix64(frame_hash + static_cast<std::uint64_t>(v)) % offsets;
    std::uint8_t* out = dst.data() + static_cast<std::size_t>(v) * raw_stride;
    if (colour) {
      colour_row(v, row, light, offset, out);
    } else {
      quantise_row(row, noise_.data() + offset, noise_scale, width, out);
    }
  }
}

}  // namespace laserline::hal
