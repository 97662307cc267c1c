#include "hal/sim/sim_scene.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <new>
#include <numbers>
#include <stdexcept>
#include <vector>

// Every allocation through the global operator new is counted, so that a test can check that a
// section of code allocates nothing. The array and nothrow forms forward to this one. Not inlined,
// or GCC sees malloc paired with operator delete and free with operator new and warns.
namespace {
std::atomic<std::size_t> g_allocations{0};
}  // namespace

[[gnu::noinline]] void* operator new(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
[[gnu::noinline]] void operator delete(void* p) noexcept {
  std::free(p);
}
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}

namespace laserline::hal {
namespace {

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(memory_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

struct Image {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> data;
  std::uint8_t at(int u, int v) const { return data[static_cast<std::size_t>(v) * width + u]; }
};

Image render(SimScene& scene, std::uint64_t sequence, bool laser_on) {
  const FrameFormat f = scene.format();
  Image img{f.width, f.height, std::vector<std::uint8_t>(f.bytes())};
  scene.render(sequence, laser_on, img.data);
  return img;
}

SimGroundTruth truth_of(const SimScene& scene, std::uint64_t sequence, bool laser_on) {
  SimGroundTruth truth;
  scene.ground_truth(sequence, laser_on, truth);
  return truth;
}

// A small scene keeps the tests quick.
SimSceneOptions small_options() {
  SimSceneOptions o;
  o.calibration.camera.width = 320;
  o.calibration.camera.height = 256;
  o.calibration.camera.fx = o.calibration.camera.fy = 350;
  o.calibration.camera.cx = 159.5;
  o.calibration.camera.cy = 127.5;
  return o;
}

// Only the laser, noiseless: the profile is the exact Gaussian quantised to 8 bit.
SimSceneOptions laser_only(SimSceneOptions o) {
  o.noise_sigma = 0;
  o.texture_contrast = 0;
  o.ambient = 0;
  o.backscatter = 0;
  o.laser_peak = 200;
  return o;
}

// Sub-pixel row of the brightest pixel of column u by a 3-point Gaussian (ln-parabola) fit.
double gaussian_peak(const Image& img, int u) {
  int best = 0;
  for (int v = 1; v < img.height; ++v) {
    if (img.at(u, v) > img.at(u, best)) best = v;
  }
  if (best == 0 || best == img.height - 1) return std::nan("");
  const double a = img.at(u, best - 1), b = img.at(u, best), c = img.at(u, best + 1);
  if (a <= 0 || c <= 0) return std::nan("");
  const double la = std::log(a), lb = std::log(b), lc = std::log(c);
  return best + 0.5 * (la - lc) / (la - 2 * lb + lc);
}

double mean_abs_diff(const Image& a, const Image& b) {
  double sum = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i)
    sum += std::abs(a.data[i] - b.data[i]);
  return sum / static_cast<double>(a.data.size());
}

int finite_count(const std::vector<float>& v) {
  return static_cast<int>(
      std::count_if(v.begin(), v.end(), [](float x) { return std::isfinite(x); }));
}

// Checks the fitted peak against the truth in every column that has one; returns the columns used.
int expect_fit_matches_truth(const Image& img, const SimGroundTruth& truth, double tol) {
  int used = 0;
  double worst = 0;
  for (int u = 0; u < img.width; ++u) {
    if (!std::isfinite(truth.row[u])) continue;
    const double fit = gaussian_peak(img, u);
    EXPECT_NEAR(fit, truth.row[u], tol) << "column " << u;
    if (std::isfinite(fit)) worst = std::max(worst, std::abs(fit - truth.row[u]));
    ++used;
  }
  std::printf("  worst |fit - truth| over %d columns: %.4f px\n", used, worst);
  return used;
}

TEST(SimScene, FormatIsMono8WithStrideWidth) {
  SimScene scene(small_options());
  const FrameFormat f = scene.format();
  EXPECT_EQ(f.width, 320);
  EXPECT_EQ(f.height, 256);
  EXPECT_EQ(f.stride, 320);
  EXPECT_EQ(f.pixel_format, PixelFormat::kMono8);
  EXPECT_EQ(f.bytes(), 320u * 256u);
}

TEST(SimScene, RejectsImpossibleOptions) {
  auto rejects = [](auto change) {
    SimSceneOptions o = small_options();
    change(o);
    EXPECT_THROW(SimScene{o}, std::invalid_argument);
  };
  rejects([](SimSceneOptions& o) { o.frame_rate_hz = 0; });
  rejects([](SimSceneOptions& o) { o.frame_rate_hz = -30; });
  rejects([](SimSceneOptions& o) { o.calibration.camera.width = 16385; });
  rejects([](SimSceneOptions& o) { o.calibration.camera.height = 20000; });
  rejects([](SimSceneOptions& o) { o.calibration.camera.width = 0; });
  rejects([](SimSceneOptions& o) { o.calibration.camera.fx = 0; });
  rejects([](SimSceneOptions& o) { o.calibration.camera.distortion[0] = 0.1; });
  rejects([](SimSceneOptions& o) { o.distance_m = 0; });
  rejects([](SimSceneOptions& o) { o.texture_scale_m = 0; });
  rejects([](SimSceneOptions& o) { o.noise_sigma = -1; });
  rejects([](SimSceneOptions& o) { o.sway_period_s = 0; });
  rejects([](SimSceneOptions& o) { o.tilt_x_deg = 90; });
  rejects([](SimSceneOptions& o) {
    o.calibration.laser.plane = std::array<double, 4>{0, 0, 0, 1};
  });
  EXPECT_NO_THROW(SimScene{small_options()});
}

TEST(SimScene, DeterministicFromOptionsSequenceAndLaserState) {
  SimSceneOptions o = small_options();
  o.backscatter = 10;
  o.attenuation_per_m = 0.3;
  SimScene a(o), b(o);
  EXPECT_EQ(render(a, 7, true).data, render(b, 7, true).data);
  EXPECT_EQ(render(a, 7, false).data, render(b, 7, false).data);

  // No dependence on what was rendered before.
  SimScene fresh(o);
  const Image three_fresh = render(fresh, 3, true);
  (void)render(a, 5, true);
  EXPECT_EQ(render(a, 3, true).data, three_fresh.data);
  (void)render(a, 3, false);
  EXPECT_EQ(render(a, 3, true).data, three_fresh.data);

  // Different sequence numbers and different seeds give different frames.
  EXPECT_NE(render(a, 4, true).data, three_fresh.data);
  o.seed = 2;
  SimScene other_seed(o);
  EXPECT_NE(render(other_seed, 3, true).data, three_fresh.data);

  // The truth is equally reproducible.
  const SimGroundTruth ta = truth_of(a, 11, true), tb = truth_of(b, 11, true);
  for (std::size_t u = 0; u < ta.row.size(); ++u) {
    EXPECT_TRUE(ta.row[u] == tb.row[u] || (std::isnan(ta.row[u]) && std::isnan(tb.row[u])));
  }
}

TEST(SimScene, LaserOffHasNoTruthAndChangesOnlyTheLine) {
  SimSceneOptions o = small_options();
  o.tilt_y_deg = 20;  // a slanted line
  SimScene scene(o);
  const std::uint64_t seq = 9;
  const SimGroundTruth off = truth_of(scene, seq, false);
  EXPECT_EQ(finite_count(off.row), 0);
  EXPECT_EQ(finite_count(off.depth_m), 0);
  EXPECT_EQ(finite_count(off.width_px), 0);

  const SimGroundTruth on = truth_of(scene, seq, true);
  ASSERT_EQ(finite_count(on.row), o.calibration.camera.width);
  const Image lit = render(scene, seq, true), dark = render(scene, seq, false);
  int changed = 0;
  for (int u = 0; u < lit.width; ++u) {
    for (int v = 0; v < lit.height; ++v) {
      if (lit.at(u, v) == dark.at(u, v)) continue;
      ++changed;
      EXPECT_LE(std::abs(v - on.row[u]), 5 * on.width_px[u] + 0.5)
          << "pixel (" << u << ", " << v << ") changed away from the line";
    }
  }
  EXPECT_GT(changed, 3 * lit.width);  // and the line is there
}

TEST(SimScene, GroundTruthIsExactForAFlatSurface) {
  SimScene scene(laser_only(small_options()));
  const SimGroundTruth truth = truth_of(scene, 0, true);
  EXPECT_EQ(expect_fit_matches_truth(render(scene, 0, true), truth, 0.02), 320);
}

TEST(SimScene, GroundTruthIsExactWithTiltAndSway) {
  SimSceneOptions o = laser_only(small_options());
  o.tilt_x_deg = 15;
  o.tilt_y_deg = -25;
  o.sway_m = 0.05;
  o.sway_deg = 3;
  o.attenuation_per_m = 0.2;
  SimScene scene(o);
  const std::uint64_t seq = 37;  // 1.2 s in: the camera has moved and turned
  const SimGroundTruth truth = truth_of(scene, seq, true);
  const SimGroundTruth at_start = truth_of(scene, 0, true);
  EXPECT_GT(std::abs(truth.row[160] - at_start.row[160]), 2.0f);
  EXPECT_GT(expect_fit_matches_truth(render(scene, seq, true), truth, 0.02), 200);

  // With a strongly textured surface the line brightness varies but the fit does not care.
  o.texture_contrast = 0.8;
  o.laser_peak = 250;
  SimScene textured(o);
  int used = 0;
  const SimGroundTruth t2 = truth_of(textured, seq, true);
  const Image img = render(textured, seq, true);
  for (int u = 0; u < img.width; ++u) {
    // Dark surface points give too few grey levels for 0.02 px; skip them.
    if (!std::isfinite(t2.row[u]) || img.at(u, static_cast<int>(std::lround(t2.row[u]))) < 100)
      continue;
    EXPECT_NEAR(gaussian_peak(img, u), t2.row[u], 0.03) << "column " << u;
    ++used;
  }
  EXPECT_GT(used, 100);
}

TEST(SimScene, TruthIsNaNNearTheTopAndBottomBorder) {
  SimSceneOptions o = laser_only(small_options());
  o.tilt_x_deg = 60;  // strongly tilted: the line crosses rows quickly as the plane moves
  o.tilt_y_deg = 45;
  SimScene scene(o);
  const SimGroundTruth truth = truth_of(scene, 0, true);
  for (float v : truth.row) {
    if (std::isfinite(v)) {
      EXPECT_GE(v, 1.5f);
      EXPECT_LE(v, 256 - 2.5f);
    }
  }
}

TEST(SimScene, TruthMatchesTheTriangulationModel) {
  SimSceneOptions o = small_options();
  o.sway_m = 0;
  o.sway_deg = 0;
  o.distance_m = 1.5;
  const double beta = o.calibration.laser.angle_deg * std::numbers::pi / 180.0;
  const double d = o.calibration.laser.baseline_m;
  const double fy = o.calibration.camera.fy, cy = o.calibration.camera.cy;
  const double expected = cy + fy * (std::tan(std::numbers::pi / 2 - beta) - d / o.distance_m);

  for (std::uint64_t seq : {0u, 17u}) {
    SimScene scene(o);
    const SimGroundTruth truth = truth_of(scene, seq, true);
    for (int u = 0; u < o.calibration.camera.width; ++u) {
      EXPECT_NEAR(truth.row[u], expected, 1e-3) << "column " << u;
      EXPECT_NEAR(truth.depth_m[u], o.distance_m, 1e-5);
      const double sheet =
          fy * o.calibration.laser.sheet_width_m / o.distance_m / 2.3548200450309493;
      EXPECT_NEAR(truth.width_px[u], std::sqrt(sheet * sheet + o.blur_px * o.blur_px), 1e-5);
    }
  }

  // The same sheet given as a calibrated plane.
  SimSceneOptions calibrated = o;
  calibrated.calibration.laser.plane =
      std::array<double, 4>{0.0, 1.0, -std::tan(std::numbers::pi / 2 - beta), d};
  SimScene scene(calibrated);
  const SimGroundTruth truth = truth_of(scene, 0, true);
  for (int u = 0; u < o.calibration.camera.width; ++u)
    EXPECT_NEAR(truth.row[u], expected, 1e-3);

  // Scaling the plane equation does not move the sheet.
  calibrated.calibration.laser.plane =
      std::array<double, 4>{0.0, -3.0, 3.0 * std::tan(std::numbers::pi / 2 - beta), -3.0 * d};
  SimScene scaled(calibrated);
  EXPECT_NEAR(truth_of(scaled, 0, true).row[100], expected, 1e-3);

  // A surface turned about the y axis slants the line.
  o.tilt_y_deg = 20;
  SimScene tilted(o);
  const SimGroundTruth slant = truth_of(tilted, 0, true);
  ASSERT_TRUE(std::isfinite(slant.row.front()) && std::isfinite(slant.row.back()));
  EXPECT_GT(std::abs(slant.row.front() - slant.row.back()), 10.0f);
  for (int u = 1; u < o.calibration.camera.width; ++u) {
    EXPECT_NE(slant.row[u], slant.row[u - 1]);
  }
}

TEST(SimScene, TextureMovesWithTheSurface) {
  SimSceneOptions o = small_options();
  o.noise_sigma = 0;
  {
    SimScene swaying(o);
    const Image a = render(swaying, 10, false), b = render(swaying, 11, false);
    EXPECT_GT(mean_abs_diff(a, b), 1.0);
  }
  o.sway_m = 0;
  o.sway_deg = 0;
  {
    SimScene still(o);
    EXPECT_EQ(render(still, 10, false).data, render(still, 11, false).data);
  }
  o.noise_sigma = 2.0;
  {
    SimScene still(o);
    // Two independent N(0, sigma^2) samples differ by 2 sigma / sqrt(pi) on average.
    const double expected = 2.0 * o.noise_sigma / std::sqrt(std::numbers::pi);
    const double diff = mean_abs_diff(render(still, 10, false), render(still, 11, false));
    EXPECT_NEAR(diff, expected, 0.15 * expected);
  }
}

TEST(SimScene, TextureHasContrastAndNoiseHasTheRequestedSigma) {
  SimSceneOptions o = small_options();
  o.sway_m = 0;
  o.sway_deg = 0;
  o.noise_sigma = 0;
  SimScene clean(o);
  const Image img = render(clean, 0, false);
  double sum = 0, sum2 = 0;
  for (std::uint8_t p : img.data) {
    sum += p;
    sum2 += double(p) * p;
  }
  const double n = static_cast<double>(img.data.size());
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, o.ambient, 0.25 * o.ambient);
  EXPECT_GT(sd, 0.1 * o.ambient);

  // Noise alone on a flat grey surface: the pixel standard deviation is noise_sigma.
  o.texture_contrast = 0;
  o.ambient = 100;
  o.noise_sigma = 3;
  SimScene noisy(o);
  const Image grey = render(noisy, 4, false);
  sum = sum2 = 0;
  for (std::uint8_t p : grey.data) {
    sum += p - 100.0;
    sum2 += (p - 100.0) * (p - 100.0);
  }
  EXPECT_NEAR(sum / n, 0.0, 0.05);
  EXPECT_NEAR(std::sqrt(sum2 / n), std::sqrt(9.0 + 1.0 / 12.0), 0.1);
}

TEST(SimScene, BackscatterBrightensOnlyTheCameraSideOfTheLine) {
  SimSceneOptions o = small_options();
  o.sway_m = 0;
  o.sway_deg = 0;
  SimScene clear(o);
  o.backscatter = 30;
  o.attenuation_per_m = 0.2;
  SimScene turbid(o);
  const std::uint64_t seq = 3;
  const SimGroundTruth truth = truth_of(clear, seq, true);
  const int line = static_cast<int>(std::lround(truth.row[0]));
  const int margin = static_cast<int>(std::ceil(5 * truth.width_px[0])) + 1;
  ASSERT_GT(line - margin - 40, 0);
  ASSERT_LT(line + margin + 40, o.calibration.camera.height);

  const Image a = render(clear, seq, true), b = render(turbid, seq, true);
  auto band_mean = [](const Image& img, int v0, int v1) {
    double sum = 0;
    for (int v = v0; v < v1; ++v) {
      for (int u = 0; u < img.width; ++u)
        sum += img.at(u, v);
    }
    return sum / ((v1 - v0) * img.width);
  };
  // Above the line (nearer than the surface along the sheet): a glow growing toward the line.
  const double near_line = band_mean(b, line - margin - 10, line - margin) -
                           band_mean(a, line - margin - 10, line - margin);
  const double far_above = band_mean(b, line - margin - 40, line - margin - 30) -
                           band_mean(a, line - margin - 40, line - margin - 30);
  EXPECT_GT(near_line, 10.0);
  EXPECT_GT(far_above, 2.0);
  EXPECT_GT(near_line, far_above);
  // Below the line the sheet is behind the surface: nothing changes, bit for bit.
  for (int v = line + margin; v < a.height; ++v) {
    for (int u = 0; u < a.width; ++u)
      ASSERT_EQ(a.at(u, v), b.at(u, v)) << u << ", " << v;
  }
  // And without the laser there is no glow at all.
  EXPECT_EQ(render(clear, seq, false).data, render(turbid, seq, false).data);
}

TEST(SimScene, SaturatesAt255) {
  SimSceneOptions o = small_options();
  o.laser_peak = 400;
  o.texture_contrast = 0;
  SimScene scene(o);
  const Image img = render(scene, 2, true);
  const SimGroundTruth truth = truth_of(scene, 2, true);
  int saturated = 0;
  for (int u = 0; u < img.width; ++u) {
    const int v = static_cast<int>(std::lround(truth.row[u]));
    saturated += img.at(u, v) == 255 ? 1 : 0;
  }
  EXPECT_EQ(saturated, img.width);
}

double render_ms(SimScene& scene, std::vector<std::uint8_t>& buffer, int frames) {
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < frames; ++i)
    scene.render(static_cast<std::uint64_t>(i), i % 2 == 0, buffer);
  const auto t1 = std::chrono::steady_clock::now();
  return std::chrono::duration<double, std::milli>(t1 - t0).count() / frames;
}

TEST(SimScene, LargeFramesRenderWithoutHeapAllocation) {
  SimSceneOptions o;
  o.calibration.camera.width = 2048;
  o.calibration.camera.height = 1536;
  o.calibration.camera.fx = o.calibration.camera.fy = 2200;
  o.calibration.camera.cx = 1023.5;
  o.calibration.camera.cy = 767.5;
  o.backscatter = 8;
  o.attenuation_per_m = 0.1;
  SimScene scene(o);
  std::vector<std::uint8_t> buffer(scene.format().bytes());
  SimGroundTruth truth;
  scene.ground_truth(0, true, truth);  // the first call sizes the vectors

  const std::size_t before = g_allocations.load();
  scene.render(0, true, buffer);
  scene.render(1, false, buffer);
  scene.render(1000, true, buffer);
  scene.ground_truth(1000, true, truth);
  const std::size_t after = g_allocations.load();
  if (kSanitized) {
    std::printf("  (allocation count not checked under sanitizers)\n");
  } else {
    EXPECT_EQ(after - before, 0u) << "render() or ground_truth() allocated";
  }

  // The frame is sane: a line where the truth says, texture around it.
  const int u = 1024;
  ASSERT_TRUE(std::isfinite(truth.row[u]));
  const int v = static_cast<int>(std::lround(truth.row[u]));
  const double fit = gaussian_peak(Image{2048, 1536, buffer}, u);
  EXPECT_NEAR(fit, truth.row[u], 1.0);
  EXPECT_GT(buffer[static_cast<std::size_t>(v) * 2048 + u], 120);

  if (!kSanitized) {
    std::printf("  2048x1536 render: %.1f ms/frame\n", render_ms(scene, buffer, 10));
    SimSceneOptions vga = o;
    vga.calibration = Calibration{};
    SimScene small(vga);
    std::vector<std::uint8_t> small_buffer(small.format().bytes());
    std::printf("  1280x1024 render: %.1f ms/frame\n", render_ms(small, small_buffer, 10));
  }
}

TEST(SimScene, AllocationCounterWorks) {
  if (kSanitized) GTEST_SKIP() << "operator new replacement is not checked under sanitizers";
  // Guards the test above against a counter that never counts.
  const std::size_t before = g_allocations.load();
  void* volatile p = ::operator new(64);
  ::operator delete(p);
  EXPECT_EQ(g_allocations.load() - before, 1u);
}

}  // namespace
}  // namespace laserline::hal
