// The simulator's water: forward scatter, veiling and backscatter of turbid water, caustics, and
// marine snow in the sheet.
// Each checks the renderer against a computation made here or in sim_scene_reference.hpp from the
// options as sim_scene.hpp documents them, never against the renderer's own intermediate numbers.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <stdexcept>
#include <utility>
#include <vector>

#include "hal/sim/sim_scene.hpp"
#include "sim_scene_reference.hpp"

namespace laserline::hal {
namespace {

using namespace sim_reference;

// ---- Turbid water ----------------------------------------------------------------------------

TEST(SimSceneTurbidity, ForwardScatterKeepsTheLinesEnergyAndCentreAndSpreadsItIntoTheHalo) {
  // The paper's mounting, a slanted line on a textured surface, sensor noise. The laser's light in
  // a column is the lit frame minus the dark one (the same frame number: the same noise, which
  // cancels); what is left of the rounding is, per pixel, round(x + L) - round(x) - L: zero mean,
  // |e| < 1, variance at most 1/4. Sums over the 2 * 45 + 1 rows around the line are good to
  // sqrt(91 / 4) per column, their mean over n columns to sqrt(91 / (4 n)).
  SimSceneOptions o = still_options();
  o.tilt_y_deg = 10;
  o.texture_contrast = 0.15;
  o.ambient = 20;
  o.laser_peak = 180;  // with the brightest texture and the noise, below 255
  o.noise_sigma = 2;
  SimScene clear(o);
  o.forward_scatter = 0.5;
  o.scatter_halo_px = 8;
  SimScene turbid(o);
  const std::uint64_t seq = 5;
  const SimGroundTruth truth = truth_of(clear, seq, true);
  ASSERT_TRUE(same_truth(truth, truth_of(turbid, seq, true)));  // the truth is the core's
  const Image clear_lit = render(clear, seq, true), clear_dark = render(clear, seq, false);
  const Image turbid_lit = render(turbid, seq, true), turbid_dark = render(turbid, seq, false);
  ASSERT_EQ(clear_dark.data, turbid_dark.data);

  constexpr int kHalfBand = 45;  // 5 halo sigmas and more
  const int width = clear_lit.width;
  double energy_clear = 0, energy_turbid = 0, centre_error = 0, centre_var = 0;
  double halo_inner = 0, halo_outer = 0, model_inner = 0, model_outer = 0;
  int columns = 0;
  for (int u = 0; u < width; ++u) {
    const double c = truth.position[u], sigma = truth.width_px[u];
    ASSERT_TRUE(std::isfinite(c));
    const int v0 = static_cast<int>(std::lround(c));
    ASSERT_GE(v0 - kHalfBand, 0);
    ASSERT_LT(v0 + kHalfBand, clear_lit.height);
    double e0 = 0, e1 = 0, moment = 0, spread = 0;
    for (int v = v0 - kHalfBand; v <= v0 + kHalfBand; ++v) {
      const double l0 = clear_lit.at(u, v) - clear_dark.at(u, v);
      const double l1 = turbid_lit.at(u, v) - turbid_dark.at(u, v);
      ASSERT_LT(turbid_lit.at(u, v), 255);
      ASSERT_LT(clear_lit.at(u, v), 255);
      e0 += l0;
      e1 += l1;
      moment += (v - c) * l1;
      spread += (v - c) * (v - c) / 4;
    }
    // Per column: the energies agree to 5 standard deviations of their difference.
    EXPECT_NEAR(e1, e0, 5 * std::sqrt(2 * (2 * kHalfBand + 1) / 4.0)) << "column " << u;
    energy_clear += e0;
    energy_turbid += e1;
    centre_error += moment / e1;
    centre_var += spread / (e1 * e1);
    // The halo: a Gaussian of sigma hypot(sigma, scatter_halo_px) holding forward_scatter of the
    // energy, whose peak follows from the clear line's energy (peak * sigma * sqrt(2 pi)). At 4
    // core sigmas and more the core has nothing left.
    const double halo_sigma = std::hypot(sigma, o.scatter_halo_px);
    const double halo_peak = o.forward_scatter * e0 / (halo_sigma * std::sqrt(2 * kPi));
    for (int v = v0 - kHalfBand; v <= v0 + kHalfBand; ++v) {
      const double d = std::abs(v - c);
      if (d < 4) continue;
      const double model = halo_peak * std::exp(-d * d / (2 * halo_sigma * halo_sigma));
      const double seen = turbid_lit.at(u, v) - turbid_dark.at(u, v);
      (d < 12 ? model_inner : model_outer) += model;
      (d < 12 ? halo_inner : halo_outer) += seen;
    }
    ++columns;
  }
  energy_clear /= columns;
  energy_turbid /= columns;
  centre_error /= columns;
  const double energy_sd = std::sqrt(2 * (2 * kHalfBand + 1) / 4.0 / columns);
  const double centre_sd = std::sqrt(centre_var) / columns;
  std::printf(
      "  line energy per column: %.2f clear, %.2f turbid (sd of the difference %.2f); centre "
      "error %+.4f px (sd %.4f); halo inner %.0f of %.0f, outer %.0f of %.0f\n",
      energy_clear, energy_turbid, energy_sd, centre_error, centre_sd, halo_inner, model_inner,
      halo_outer, model_outer);
  EXPECT_NEAR(energy_turbid, energy_clear, 4 * energy_sd);
  EXPECT_NEAR(centre_error, 0.0, 4 * centre_sd);
  // The halo is there, as wide as said: each of its two zones within 5 % (the sums are of
  // thousands of pixels, their rounding far below that; the core's estimate of the peak is good
  // to about 2 %).
  EXPECT_NEAR(halo_inner, model_inner, 0.05 * model_inner);
  EXPECT_NEAR(halo_outer, model_outer, 0.05 * model_outer);
  EXPECT_GT(model_outer, 0.2 * model_inner);
}

TEST(SimSceneTurbidity, VeilingLowersTheContrastByItsShareAndKeepsTheMean) {
  // Veiling light v: each pixel's ambient light A + (1 - v) (light - A), A the ambient light on
  // albedo 1: the texture's deviations from A shrink by 1 - v, and the mean stays while the
  // texture's mean albedo is 1. Noiseless: per pixel to within the rounding of both frames.
  SimSceneOptions o = still_options();
  o.noise_sigma = 0;
  o.ambient = 80;
  o.texture_contrast = 0.5;
  o.caustic_peak = 2;  // caustic light veils alike
  SimScene clear(o);
  o.veiling = 0.4;
  SimScene veiled(o);
  const std::uint64_t seq = 3;
  const Image a = render(clear, seq, false), b = render(veiled, seq, false);
  const double n = static_cast<double>(a.data.size());
  double mean_a = 0, mean_b = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    const double expected = o.ambient + (1 - o.veiling) * (a.data[i] - o.ambient);
    ASSERT_NEAR(b.data[i], expected, 0.5 + 0.5 * (1 - o.veiling) + 1e-9) << "pixel " << i;
    mean_a += a.data[i] / n;
    mean_b += b.data[i] / n;
  }
  double var_a = 0, var_b = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    var_a += (a.data[i] - mean_a) * (a.data[i] - mean_a) / n;
    var_b += (b.data[i] - mean_b) * (b.data[i] - mean_b) / n;
  }
  std::printf("  mean %.2f -> %.2f, sd %.2f -> %.2f (x %.3f)\n", mean_a, mean_b, std::sqrt(var_a),
              std::sqrt(var_b), std::sqrt(var_b / var_a));
  // Rounding adds variance 1/12 to each frame (which the texture's variance dwarfs).
  EXPECT_NEAR(std::sqrt(var_b / var_a), 1 - o.veiling, 0.01);
  EXPECT_NEAR(mean_b, mean_a, 0.02 * o.ambient);
  EXPECT_NEAR(mean_b - mean_a, o.veiling * (o.ambient - mean_a), 0.5);

  // The laser's light is not veiled: lit minus dark is the same in both waters.
  const Image la = render(clear, seq, true), lb = render(veiled, seq, true);
  int lit = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    if (la.data[i] == 255 || lb.data[i] == 255) continue;  // clipped
    const int line_a = la.data[i] - a.data[i], line_b = lb.data[i] - b.data[i];
    // Each difference is the line's light to within (-1, 1): they differ by at most 1.
    ASSERT_LE(std::abs(line_a - line_b), 1) << "pixel " << i;
    lit += line_a > 20 ? 1 : 0;
  }
  EXPECT_GT(lit, 320);
}

TEST(SimSceneTurbidity, BackscatterStaysOnTheCameraSideOfTheLineForEveryFamily) {
  // A pixel can glow only where its ray crosses the sheet before the surface: 0 < Z_sheet <
  // Z_surface, both computed here per pixel. Where that fails for the pixel and its eight
  // neighbours (the renderer decides per line, to within a pixel), the frame is the clear water's
  // bit for bit; on the camera's side it is brighter. Rows (the laser beside the camera) and the
  // oblique family, on a tilted surface (the columns: test_sim_scene.cpp).
  for (const bool oblique : {false, true}) {
    SCOPED_TRACE(oblique ? "oblique" : "rows");
    SimSceneOptions o = still_options();
    if (oblique) {
      o.calibration.laser.plane = turned_sheet(o.calibration.laser, -35 * kDegree);
    } else {
      o.calibration.laser.side = LaserSide::kRight;
    }
    o.tilt_x_deg = 15;
    o.tilt_y_deg = -12;
    o.attenuation_per_m = 0.2;
    SimScene clear(o);
    o.backscatter = 30;
    SimScene turbid(o);
    const std::uint64_t seq = 2;
    const Image a = render(clear, seq, true), b = render(turbid, seq, true);
    const CameraIntrinsics& cam = o.calibration.camera;
    const CameraPlane plane = base_plane_in_camera(o, clear.camera_pose(seq));
    auto near_side = [&](int u, int v) {
      const double p = sheet_inverse_depth(o.calibration, u, v);
      const double q = dot3(plane.n, ray_of(cam, u, v)) / plane.d;  // the surface's 1/Z
      return p > 0 && p > q;
    };
    int far = 0, near = 0;
    double brightening = 0;
    for (int v = 1; v + 1 < a.height; ++v) {
      for (int u = 1; u + 1 < a.width; ++u) {
        int near_count = 0;
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du)
            near_count += near_side(u + du, v + dv) ? 1 : 0;
        }
        if (near_count == 0) {
          ASSERT_EQ(a.at(u, v), b.at(u, v)) << "far side " << u << ", " << v;
          ++far;
        } else if (near_count == 9) {
          brightening += b.at(u, v) - a.at(u, v);
          ++near;
        }
      }
    }
    std::printf("  %d pixels on the far side unchanged; %d on the camera's side %.1f brighter\n",
                far, near, brightening / near);
    EXPECT_GT(far, 10000);
    EXPECT_GT(near, 10000);
    EXPECT_GT(brightening / near, 2.0);
    EXPECT_EQ(render(clear, seq, false).data, render(turbid, seq, false).data);
  }
}

// ---- Caustics ---------------------------------------------------------------------------------

// The mean light of frames 0, 30, ..., 210 without the laser (the mean of their means) and the
// brightest pixel among them.
std::pair<double, double> light_without_laser(SimScene& scene) {
  double mean = 0, brightest = 0;
  int frames = 0;
  for (std::uint64_t seq = 0; seq < 240; seq += 30) {
    const Image img = render(scene, seq, false);
    double sum = 0;
    for (std::uint8_t p : img.data) {
      sum += p;
      brightest = std::max(brightest, static_cast<double>(p));
    }
    mean += sum / static_cast<double>(img.data.size());
    ++frames;
  }
  return {mean / frames, brightest};
}

TEST(SimSceneCaustics, KeepTheMeanAmbientLightAndPeakAtCausticPeak) {
  // A flat grey surface (albedo 1), noiseless: each pixel is round(ambient * caustic light). Over
  // eight frames a second apart (the pattern drifts by 0.2 m, two cells, between them) and some
  // 100 cells in each, the mean light is the ambient light. How well: the curves hold about 3 %
  // of the light pattern's area, varying by about that much from cell to cell, so the mean of the
  // caustic light over N cells varies by about (peak - 1) * 0.03 / sqrt(N), under 1 % here for
  // N = 8 * 100; allowed 3 %. Not keeping the mean (the curves added on top) would add some 15 %.
  SimSceneOptions o = still_options();
  o.noise_sigma = 0;
  o.texture_contrast = 0;
  o.ambient = 40;
  o.caustic_peak = 6;
  o.caustic_scale_m = 0.1;
  SimScene scene(o);
  const auto [mean, brightest] = light_without_laser(scene);
  std::printf("  mean light %.2f of ambient %.0f; brightest %.0f = %.2f x the mean (peak %.0f)\n",
              mean, o.ambient, brightest, brightest / mean, o.caustic_peak);
  EXPECT_NEAR(mean, o.ambient, 0.03 * o.ambient);
  // The brightest light is caustic_peak times the ambient light (where the curves of the
  // pattern meet), never more but for rounding.
  EXPECT_LE(brightest, o.caustic_peak * o.ambient + 0.5);
  EXPECT_GE(brightest, 0.85 * o.caustic_peak * o.ambient);
}

TEST(SimSceneCaustics, KeepTheMeanUpToTheHighestPeakAllowed) {
  // The pattern's curves cover a few per cent of the surface: a caustic_peak beyond 1 / (that
  // share) cannot keep the mean with light between the curves that is >= 0; the options allow up
  // to 100. To see the caustic light f from 0 to 100 times the mean in 8 bit: ambient light A =
  // 4.9 half veiled, each pixel A / 2 (f + 1) (from 2.45 to 247.45), noise of sigma 0.6 dithering
  // the rounding (a pixel would be clipped below 0 at -2.95 levels, 4.9 sigma, about 5e-7 of them;
  // none reach 255). The mean of f is good to a few per cent over eight frames and some 800 cells
  // (see above).
  for (const double peak : {40.0, 100.0}) {
    SimSceneOptions o = still_options();
    o.noise_sigma = 0.6;
    o.texture_contrast = 0;
    o.ambient = 4.9;
    o.veiling = 0.5;
    o.caustic_peak = peak;
    o.caustic_scale_m = 0.1;
    const double half = o.ambient / 2;
    for (const std::uint64_t seed : {1u, 2u, 3u}) {
      o.seed = seed;
      SimScene scene(o);
      const auto [mean, brightest] = light_without_laser(scene);
      const double f_mean = (mean - half) / half, f_max = (brightest - half) / half;
      std::printf("  peak %.0f, seed %d: mean caustic light %.3f, brightest %.1f\n", peak,
                  static_cast<int>(seed), f_mean, f_max);
      EXPECT_NEAR(f_mean, 1.0, 0.04) << "peak " << peak << ", seed " << seed;
      EXPECT_LE(f_max, peak + 4.8 / half);  // the noise: at most 127 / 16 sigma
      // The thinner the curves, the rarer a pixel on the very crossing of two.
      EXPECT_GE(f_max, 0.7 * peak);
    }
  }
}

TEST(SimSceneCaustics, ThePatternDriftsOverTheStillTextureAndLeavesTheLineAlone) {
  // A still camera: the textured surface stays pixel for pixel while the caustics move over it.
  SimSceneOptions o = still_options();
  o.noise_sigma = 0;
  o.ambient = 40;
  o.texture_contrast = 0.5;
  SimScene plain(o);
  o.caustic_peak = 4;
  o.caustic_speed_m_s = 0.3;
  SimScene caustic(o);
  SimSceneOptions flat = o;
  flat.texture_contrast = 0;  // the caustic light alone, times the ambient light
  SimScene light(flat);
  const std::uint64_t a = 10, b = 13;  // 0.1 s: the pattern moves by some 3 cm
  const Image plain_a = render(plain, a, false), plain_b = render(plain, b, false);
  ASSERT_EQ(plain_a.data, plain_b.data);
  const Image light_a = render(light, a, false), light_b = render(light, b, false);
  const Image caustic_a = render(caustic, a, false), caustic_b = render(caustic, b, false);
  // The caustic light multiplies the texture where it is: round(A albedo f) against the rounded
  // round(A albedo) and round(A f) of the other two frames.
  for (const auto& [lit, texture_lit] : {std::pair{&light_a, &caustic_a}, {&light_b, &caustic_b}}) {
    for (std::size_t i = 0; i < plain_a.data.size(); ++i) {
      const double f = lit->data[i], p = plain_a.data[i];
      if (f == 255 || texture_lit->data[i] == 255) continue;
      ASSERT_NEAR(texture_lit->data[i], f * p / o.ambient,
                  0.5 + (0.5 * f + 0.5 * p + 0.25) / o.ambient + 1e-9)
          << "pixel " << i;
    }
  }
  // ... and moved between the frames.
  double moved = 0;
  for (std::size_t i = 0; i < light_a.data.size(); ++i)
    moved += std::abs(light_a.data[i] - light_b.data[i]);
  moved /= static_cast<double>(light_a.data.size());
  std::printf("  caustic light moved: mean |difference| %.2f grey levels in 0.1 s\n", moved);
  EXPECT_GT(moved, 2.0);

  // Where it is depends on speed * time alone: still at speed 0, the same at twice the speed and
  // half the time (bit for bit: scaling by 2 is exact).
  flat.caustic_speed_m_s = 0;
  SimScene still(flat);
  EXPECT_EQ(render(still, a, false).data, render(still, b, false).data);
  flat.caustic_speed_m_s = 2 * o.caustic_speed_m_s;
  SimScene fast(flat);
  EXPECT_EQ(render(fast, 7, false).data, render(light, 14, false).data);
  EXPECT_NE(render(fast, 7, false).data, render(light, 7, false).data);

  // The laser's light is not the ambient light: lit minus dark is the same with caustics.
  const Image plain_lit = render(plain, a, true), caustic_lit = render(caustic, a, true);
  for (std::size_t i = 0; i < plain_a.data.size(); ++i) {
    if (plain_lit.data[i] == 255 || caustic_lit.data[i] == 255) continue;
    ASSERT_LE(
        std::abs((caustic_lit.data[i] - caustic_a.data[i]) - (plain_lit.data[i] - plain_a.data[i])),
        1)
        << "pixel " << i;
  }
}

TEST(SimSceneCaustics, PeakOneIsNoCausticsWhateverTheOtherCausticOptions) {
  SimSceneOptions o = still_options();
  o.sway_m = 0.02;
  o.backscatter = 10;
  SimScene plain(o);
  o.caustic_peak = 1;
  o.caustic_scale_m = 0.37;
  o.caustic_speed_m_s = -3;
  SimScene none(o);
  EXPECT_EQ(render(plain, 17, true).data, render(none, 17, true).data);
  EXPECT_EQ(render(plain, 18, false).data, render(none, 18, false).data);
  auto rejects = [](auto change) {
    SimSceneOptions bad = still_options();
    change(bad);
    EXPECT_THROW(SimScene{bad}, std::invalid_argument);
  };
  rejects([](SimSceneOptions& b) { b.caustic_peak = 0.5; });
  rejects([](SimSceneOptions& b) { b.caustic_scale_m = 0; });
  rejects([](SimSceneOptions& b) { b.caustic_speed_m_s = std::nan(""); });
}

// ---- Marine snow -----------------------------------------------------------------------------

struct Spot {
  int u, v, peak;
};

// The local maxima of at least `threshold` in an image of added light (ties broken toward the
// first in row order).
std::vector<Spot> find_spots(const std::vector<int>& light, int width, int height, int threshold) {
  std::vector<Spot> spots;
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const int x = light[static_cast<std::size_t>(v) * width + u];
      if (x < threshold) continue;
      bool peak = true;
      for (int dv = -1; dv <= 1 && peak; ++dv) {
        for (int du = -1; du <= 1 && peak; ++du) {
          const int uu = u + du, vv = v + dv;
          if ((du == 0 && dv == 0) || uu < 0 || vv < 0 || uu >= width || vv >= height) continue;
          const int y = light[static_cast<std::size_t>(vv) * width + uu];
          const bool before = dv < 0 || (dv == 0 && du < 0);
          peak = before ? x > y : x >= y;
        }
      }
      if (peak) spots.push_back({u, v, x});
    }
  }
  return spots;
}

TEST(SimSceneSnow, SpotsLieInTheSheetInFrontOfTheSurfaceNewEachFrameAndOnlyWithTheLaser) {
  // The snow's light is the snowy frame minus the clear one (the same frame: the same noise).
  // Each spot's centre must see the sheet nearer than the surface along its ray (Z computed here
  // per pixel; within a pixel, the 3 x 3 around the brightest) and no nearer than
  // snow_min_depth_m; all the added light must belong to the spots.
  struct Mount {
    const char* name;
    LaserSide side;
    double turn_deg;  // the sheet turned about the optical axis (0: the side's own model)
  };
  for (const Mount& mount :
       {Mount{"above", LaserSide::kAbove, 0.0}, Mount{"right", LaserSide::kRight, 0.0},
        Mount{"turned", LaserSide::kAbove, 30.0}}) {
    SCOPED_TRACE(mount.name);
    SimSceneOptions o = still_options();
    o.calibration.laser.side = mount.side;
    if (mount.turn_deg != 0)
      o.calibration.laser.plane = turned_sheet(o.calibration.laser, mount.turn_deg * kDegree);
    o.tilt_x_deg = 8;
    o.tilt_y_deg = -10;
    o.texture_contrast = 0.3;
    o.laser_peak = 150;
    o.noise_sigma = 2;
    SimScene clear(o);
    o.snow_per_frame = 25;
    o.snow_size_px = 1.2;
    o.snow_brightness = 0.8;
    o.snow_min_depth_m = 0.5;  // the sheet is in the frame from 0.46 m on (paper's mounting)
    SimScene snowy(o);
    const CameraIntrinsics& cam = o.calibration.camera;
    const CameraPlane plane = base_plane_in_camera(o, clear.camera_pose(0));
    auto sheet_depth = [&](int u, int v) {
      const double p = sheet_inverse_depth(o.calibration, u, v);
      return p > 0 ? 1.0 / p : 1e300;
    };
    std::vector<std::vector<Spot>> frames;
    for (std::uint64_t seq : {4u, 5u}) {
      ASSERT_EQ(render(snowy, seq, false).data, render(clear, seq, false).data);
      ASSERT_TRUE(same_truth(truth_of(snowy, seq, true), truth_of(clear, seq, true)));
      const Image s = render(snowy, seq, true), c = render(clear, seq, true);
      std::vector<int> light(s.data.size());
      for (std::size_t i = 0; i < light.size(); ++i) {
        light[i] = s.data[i] - c.data[i];
        ASSERT_GE(light[i], 0) << "pixel " << i;  // light added, never taken
      }
      const std::vector<Spot> spots = find_spots(light, s.width, s.height, 8);
      double nearest = 1e300, farthest = 0;
      for (const Spot& spot : spots) {
        double lo = 1e300, hi = 0;
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du) {
            lo = std::min(lo, sheet_depth(spot.u + du, spot.v + dv));
            hi = std::max(hi, sheet_depth(spot.u + du, spot.v + dv));
          }
        }
        const double surface = plane.d / dot3(plane.n, ray_of(cam, spot.u, spot.v));
        EXPECT_LT(lo, surface) << "spot at " << spot.u << ", " << spot.v << " behind the surface";
        EXPECT_GE(hi, o.snow_min_depth_m) << "spot at " << spot.u << ", " << spot.v;
        EXPECT_LE(spot.peak, o.snow_brightness * o.laser_peak + 1);
        nearest = std::min(nearest, lo);
        farthest = std::max(farthest, hi / surface);
      }
      // All the added light is the spots' (Gaussians of sigma up to 1.4 snow_size_px, drawn to
      // 4 sigma), or a spot's hidden in the saturated line.
      const double reach = 4 * 1.4 * o.snow_size_px + 1;
      int stray = 0;
      for (int v = 0; v < s.height; ++v) {
        for (int u = 0; u < s.width; ++u) {
          if (light[static_cast<std::size_t>(v) * s.width + u] == 0) continue;
          bool near_spot = false;
          for (const Spot& spot : spots)
            near_spot = near_spot || std::hypot(u - spot.u, v - spot.v) <= reach;
          // A spot on the line can be hidden where the line saturates: its tails remain.
          for (int dv = -8; dv <= 8 && !near_spot; ++dv) {
            for (int du = -8; du <= 8 && !near_spot; ++du) {
              const int uu = u + du, vv = v + dv;
              near_spot = uu >= 0 && vv >= 0 && uu < s.width && vv < s.height &&
                          s.at(uu, vv) == 255 && std::hypot(du, dv) <= reach;
            }
          }
          stray += near_spot ? 0 : 1;
        }
      }
      EXPECT_EQ(stray, 0);
      std::printf("  %s, frame %d: %zu spots, sheet depths %.2f m to %.2f of the surface's\n",
                  mount.name, static_cast<int>(seq), spots.size(), nearest, farthest);
      // Two spots can merge into one; particles falling outside the frame are not drawn.
      EXPECT_LE(static_cast<int>(spots.size()), o.snow_per_frame);
      EXPECT_GE(static_cast<int>(spots.size()),
                mount.turn_deg == 0 ? o.snow_per_frame - 3 : o.snow_per_frame / 2);
      frames.push_back(spots);
    }
    // New snow each frame: hardly a spot in the same place.
    int same = 0;
    for (const Spot& a : frames[0]) {
      for (const Spot& b : frames[1])
        same += a.u == b.u && a.v == b.v ? 1 : 0;
    }
    EXPECT_LE(same, 2);
    // Deterministic per seed and frame, whatever was rendered before; another seed, other snow.
    SimScene again(o);
    EXPECT_EQ(render(again, 4, true).data, render(snowy, 4, true).data);
    (void)render(snowy, 9, true);
    EXPECT_EQ(render(snowy, 5, true).data, render(again, 5, true).data);
    o.seed = 77;
    SimScene other(o);
    o.snow_per_frame = 0;
    SimScene other_clear(o);
    EXPECT_NE(render(other, 4, true).data, render(other_clear, 4, true).data);
  }
}

}  // namespace
}  // namespace laserline::hal
