// The simulator's colour frames: raw format and size, each channel's share of the ambient and
// laser light, independent channel noise, Bayer mosaics.
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

// ---- Colour ----------------------------------------------------------------------------------

// A scene with everything that lights it: textured surface, caustics, veiling light, backscatter,
// forward scatter and marine snow, below 8-bit saturation everywhere.
SimSceneOptions busy_options() {
  SimSceneOptions o = still_options();
  o.sway_m = 0.02;
  o.sway_deg = 0.5;
  o.tilt_y_deg = 10;
  o.laser_peak = 130;
  o.backscatter = 15;
  o.attenuation_per_m = 0.1;
  o.forward_scatter = 0.3;
  o.veiling = 0.25;
  o.caustic_peak = 3;
  o.snow_per_frame = 40;
  o.snow_brightness = 0.5;
  o.seed = 3;
  return o;
}

TEST(SimSceneColour, RawFormatAndSizeFollowTheColour) {
  SimSceneOptions o = still_options();
  const std::size_t pixels = 320u * 256u;
  const std::pair<SimColour, PixelLayout> cases[] = {
      {SimColour::kMono, PixelLayout::kMono},
      {SimColour::kRgb, PixelLayout::kRgb},
      {SimColour::kBayerRggb, PixelLayout::kBayerRggb},
      {SimColour::kBayerGrbg, PixelLayout::kBayerGrbg},
      {SimColour::kBayerGbrg, PixelLayout::kBayerGbrg},
      {SimColour::kBayerBggr, PixelLayout::kBayerBggr}};
  for (const auto& [colour, layout] : cases) {
    o.colour = colour;
    SimScene scene(o);
    EXPECT_EQ(scene.raw_format().layout, layout);
    EXPECT_EQ(scene.raw_format().bits, 8);
    EXPECT_EQ(scene.raw_bytes(), colour == SimColour::kRgb ? 3 * pixels : pixels);
    // The pipeline's frame stays mono8 whatever the camera delivers.
    EXPECT_EQ(scene.format().pixel_format, PixelFormat::kMono8);
    EXPECT_EQ(scene.format().bytes(), pixels);
    std::vector<std::uint8_t> short_buffer(scene.raw_bytes() - 1);
    EXPECT_THROW(scene.render(0, true, short_buffer), std::invalid_argument);
  }
  auto rejects = [](auto change) {
    SimSceneOptions bad = still_options();
    change(bad);
    EXPECT_THROW(SimScene{bad}, std::invalid_argument);
  };
  rejects([](SimSceneOptions& b) { b.laser_rgb[1] = -0.1; });
  rejects([](SimSceneOptions& b) { b.ambient_rgb[2] = std::nan(""); });
  rejects([](SimSceneOptions& b) { b.ambient_rgb[0] = 11; });
}

TEST(SimSceneColour, EachChannelIsTheMonoFramesAmbientAndLaserLightInItsShare) {
  // Mono frames give the two lights apart: the ambient light A alone (laser off) and the laser's
  // light L alone (ambient 0: the line, its halo, the glow and the snow). Noiseless, a channel
  // with factors a and l is round(a A + l L).
  SimSceneOptions o = busy_options();
  o.noise_sigma = 0;
  SimScene mono(o);
  SimSceneOptions no_ambient = o;
  no_ambient.ambient = 0;
  SimScene laser_light(no_ambient);
  const std::uint64_t seq = 7;
  const Image ambient_only = render(mono, seq, false);
  const Image laser_only_img = render(laser_light, seq, true);

  // Factors 0 and 1 make two channels the mono frames bit for bit; factors 1/2 the mono frame of
  // a scene at half the light (scaling by 2 is exact in floating point, only the order of the
  // sums differs: at most one grey level, rarely).
  o.colour = SimColour::kRgb;
  o.ambient_rgb = {1.0, 0.0, 0.5};
  o.laser_rgb = {0.0, 1.0, 0.5};
  SimScene rgb(o);
  const Image frame = render(rgb, seq, true);
  SimSceneOptions half = busy_options();
  half.noise_sigma = 0;
  half.ambient /= 2;
  half.laser_peak /= 2;
  half.backscatter /= 2;
  SimScene half_light(half);
  const Image half_frame = render(half_light, seq, true);
  ASSERT_EQ(frame.channels, 3);
  int differ = 0, lit = 0, worst = 0;
  for (int v = 0; v < frame.height; ++v) {
    for (int u = 0; u < frame.width; ++u) {
      ASSERT_EQ(frame.at(u, v, 0), ambient_only.at(u, v)) << u << ", " << v;
      ASSERT_EQ(frame.at(u, v, 1), laser_only_img.at(u, v)) << u << ", " << v;
      const int d = std::abs(frame.at(u, v, 2) - half_frame.at(u, v));
      worst = std::max(worst, d);
      differ += d != 0 ? 1 : 0;
      lit += laser_only_img.at(u, v) > 0 ? 1 : 0;
    }
  }
  std::printf("  blue = half the mono light: %d of %d pixels one level off\n", differ,
              frame.width * frame.height);
  EXPECT_LE(worst, 1);
  EXPECT_LT(differ, frame.width * frame.height / 100);
  EXPECT_GT(lit, 5000);  // line, halo, glow and snow were all in the comparison

  // Any factors: each channel is a A + l L to within the rounding of the three frames.
  o.ambient_rgb = {0.9, 0.7, 0.4};
  o.laser_rgb = {0.08, 1.0, 0.12};
  SimScene coloured(o);
  const Image c = render(coloured, seq, true);
  for (int v = 0; v < c.height; ++v) {
    for (int u = 0; u < c.width; ++u) {
      ASSERT_LT(ambient_only.at(u, v) + laser_only_img.at(u, v), 255);  // no clipping anywhere
      for (int ch = 0; ch < 3; ++ch) {
        const double a = o.ambient_rgb[ch], l = o.laser_rgb[ch];
        const double model = a * ambient_only.at(u, v) + l * laser_only_img.at(u, v);
        ASSERT_NEAR(c.at(u, v, ch), model, 0.5 + 0.5 * (a + l) + 1e-6)
            << u << ", " << v << " channel " << ch;
      }
    }
  }
}

TEST(SimSceneColour, ChannelNoiseIsIndependentWithTheRequestedSigma) {
  // A flat grey surface (albedo 1, ambient 100: no rounding of the light itself), white light:
  // every channel is 100 + its own noise. Each channel's deviation has variance sigma^2 + 1/12
  // (rounding); two channels' difference twice that; their correlation 0. Over n = 81920 pixels
  // a sample standard deviation is good to about 1 / sqrt(2 n) = 0.25 % and a correlation to
  // 1 / sqrt(n) = 0.0035: the tolerances are some 6 times those. The mean is good to
  // sigma / sqrt(n) = 0.01 (4 times that allowed); sigma is such that no noise sample (a multiple
  // of sigma / 16) lands on half a grey level, which rounding half up would bias by 1/32 level at
  // sigma = 3.
  SimSceneOptions o = still_options();
  o.colour = SimColour::kRgb;
  o.texture_contrast = 0;
  o.ambient = 100;
  o.noise_sigma = 2.93;
  o.ambient_rgb = {1, 1, 1};
  SimScene scene(o);
  const Image img = render(scene, 4, false);
  const double n = static_cast<double>(img.width) * img.height;
  std::array<double, 3> mean{}, var{};
  std::array<std::array<double, 3>, 3> cov{};
  for (int v = 0; v < img.height; ++v) {
    for (int u = 0; u < img.width; ++u) {
      for (int a = 0; a < 3; ++a) {
        const double da = img.at(u, v, a) - 100.0;
        mean[a] += da / n;
        for (int b = 0; b < 3; ++b)
          cov[a][b] += da * (img.at(u, v, b) - 100.0) / n;
      }
    }
  }
  const double expected = std::sqrt(o.noise_sigma * o.noise_sigma + 1.0 / 12);
  for (int a = 0; a < 3; ++a) {
    var[a] = cov[a][a] - mean[a] * mean[a];
    std::printf("  channel %d: mean %+.4f, sd %.4f (expected %.4f)\n", a, mean[a],
                std::sqrt(var[a]), expected);
    EXPECT_NEAR(mean[a], 0.0, 0.04) << "channel " << a;
    EXPECT_NEAR(std::sqrt(var[a]), expected, 0.05 * expected) << "channel " << a;
  }
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3;
    const double c = cov[a][b] - mean[a] * mean[b];
    const double difference = std::sqrt(var[a] + var[b] - 2 * c);
    std::printf("  channels %d and %d: correlation %.4f, sd of difference %.3f\n", a, b,
                c / std::sqrt(var[a] * var[b]), difference);
    EXPECT_NEAR(c / std::sqrt(var[a] * var[b]), 0.0, 0.02);
    EXPECT_NEAR(difference, std::sqrt(2.0) * expected, 0.05 * expected);
  }
}

TEST(SimSceneColour, BayerFramesCarryTheRgbFramesSampleOfEachPixelsColour) {
  // All four mosaics, named by their top-left 2x2 cell read row by row; the same options and seed
  // as an RGB frame, noise included: each pixel is that frame's sample of its own colour.
  SimSceneOptions o = busy_options();
  o.noise_sigma = 2;
  o.colour = SimColour::kRgb;
  SimScene rgb(o);
  const std::uint64_t seq = 12;
  const Image full = render(rgb, seq, true);
  const SimGroundTruth rgb_truth = truth_of(rgb, seq, true);
  const std::pair<SimColour, const char*> mosaics[] = {{SimColour::kBayerRggb, "RGGB"},
                                                       {SimColour::kBayerGrbg, "GRBG"},
                                                       {SimColour::kBayerGbrg, "GBRG"},
                                                       {SimColour::kBayerBggr, "BGGR"}};
  for (const auto& [colour, cell] : mosaics) {
    o.colour = colour;
    SimScene bayer(o);
    const Image mosaic = render(bayer, seq, true);
    ASSERT_EQ(mosaic.channels, 1);
    for (int v = 0; v < mosaic.height; ++v) {
      for (int u = 0; u < mosaic.width; ++u) {
        const char name = cell[(v % 2) * 2 + u % 2];
        const int channel = name == 'R' ? 0 : name == 'G' ? 1 : 2;
        ASSERT_EQ(mosaic.at(u, v), full.at(u, v, channel)) << cell << " at " << u << ", " << v;
      }
    }
    EXPECT_TRUE(same_truth(truth_of(bayer, seq, true), rgb_truth)) << cell;
  }
  // Nor does the truth depend on colour at all.
  o.colour = SimColour::kMono;
  o.laser_rgb = {1, 0.08, 0.03};
  SimScene mono(o);
  EXPECT_TRUE(same_truth(truth_of(mono, seq, true), rgb_truth));
  EXPECT_GT(finite_count(rgb_truth.position), 250);
}

}  // namespace
}  // namespace laserline::hal
