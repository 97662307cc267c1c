// The simulated scanner's plain scan: the rendered line, its ground truth and the camera's path.
// Over 600 lines: one unit (the simulator), on shared reference computations
// (sim_scene_reference.hpp).
#include "hal/sim/sim_scene.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <new>
#include <numbers>
#include <stdexcept>
#include <utility>
#include <vector>

#include "sim_scene_reference.hpp"

// Every allocation through the global operator new is counted, so that a test can check that a
// section of code allocates nothing (also under ASan, which intercepts the malloc underneath). The
// array and nothrow forms forward to this one. Not inlined, or GCC sees malloc paired with operator
// delete and free with operator new and warns.
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

// Timings mean nothing under a sanitizer.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || \
    __has_feature(memory_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

using namespace sim_reference;

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

// How far rounding to 8 bit can move the 3-point fit of column u (first order in the rounding
// errors of +-0.5 on each of the three samples): the only error the fit has on noiseless data.
double rounding_bound(const Image& img, int u, double sigma) {
  int best = 0;
  for (int v = 1; v < img.height; ++v) {
    if (img.at(u, v) > img.at(u, best)) best = v;
  }
  if (best == 0 || best == img.height - 1) return 0.0;  // no fit: let the caller's check fail
  const double a = img.at(u, best - 1), b = img.at(u, best), c = img.at(u, best + 1);
  const double s2 = sigma * sigma;
  // delta = (la - lc) / (2 (la - 2 lb + lc)) with la - 2 lb + lc = -1 / sigma^2 and |delta| <= 0.5.
  return s2 / 2 * (0.5 / a + 0.5 / c) + 0.5 * s2 * (0.5 / a + 1.0 / b + 0.5 / c) + 1e-3;
}

double mean_abs_diff(const Image& a, const Image& b) {
  double sum = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i)
    sum += std::abs(a.data[i] - b.data[i]);
  return sum / static_cast<double>(a.data.size());
}

// Checks the fitted peak against the truth in every column that has one; returns the columns used.
int expect_fit_matches_truth(const Image& img, const SimGroundTruth& truth, double tol) {
  int used = 0;
  double worst = 0;
  for (int u = 0; u < img.width; ++u) {
    if (!std::isfinite(truth.position[u])) continue;
    const double fit = gaussian_peak(img, u);
    EXPECT_NEAR(fit, truth.position[u], tol) << "column " << u;
    if (std::isfinite(fit)) worst = std::max(worst, std::abs(fit - truth.position[u]));
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
  rejects([](SimSceneOptions& o) { o.calibration.laser.plane = Eigen::Vector4d{0, 0, 0, 1}; });
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
  for (std::size_t u = 0; u < ta.position.size(); ++u) {
    EXPECT_TRUE(ta.position[u] == tb.position[u] ||
                (std::isnan(ta.position[u]) && std::isnan(tb.position[u])));
  }
}

TEST(SimScene, LaserOffHasNoTruthAndChangesOnlyTheLine) {
  SimSceneOptions o = small_options();
  o.tilt_y_deg = 20;  // a slanted line
  SimScene scene(o);
  const std::uint64_t seq = 9;
  const SimGroundTruth off = truth_of(scene, seq, false);
  EXPECT_EQ(finite_count(off.position), 0);
  EXPECT_EQ(finite_count(off.depth_m), 0);
  EXPECT_EQ(finite_count(off.width_px), 0);

  const SimGroundTruth on = truth_of(scene, seq, true);
  ASSERT_EQ(finite_count(on.position), o.calibration.camera.width);
  const Image lit = render(scene, seq, true), dark = render(scene, seq, false);
  int changed = 0;
  for (int u = 0; u < lit.width; ++u) {
    for (int v = 0; v < lit.height; ++v) {
      if (lit.at(u, v) == dark.at(u, v)) continue;
      ++changed;
      EXPECT_LE(std::abs(v - on.position[u]), 5 * on.width_px[u] + 0.5)
          << "pixel (" << u << ", " << v << ") changed away from the line";
    }
  }
  EXPECT_GT(changed, 3 * lit.width);  // and the line is there
}

// A fan of 24 degrees on a camera of 49 degrees across: the line lies on a middle stretch of the
// columns (its ends at 1.2 m about 0.25 m either side of the centre, some 74 px), no light beyond
// its ends, and a wider fan lights more.
TEST(SimScene, LaserFanLightsAMiddleStretchOfTheLineOnly) {
  SimSceneOptions o = small_options();
  o.laser_fan_deg = 24;
  SimScene scene(o);
  const std::uint64_t seq = 4;
  const SimGroundTruth truth = truth_of(scene, seq, true);
  const int width = o.calibration.camera.width;
  int first = -1, last = -1;
  for (int u = 0; u < width; ++u) {
    if (std::isnan(truth.position[static_cast<std::size_t>(u)])) continue;
    if (first < 0) first = u;
    last = u;
  }
  ASSERT_GE(first, 0);
  EXPECT_EQ(finite_count(truth.position), last - first + 1);  // one stretch
  EXPECT_NEAR(first, width / 2 - 74, 12);
  EXPECT_NEAR(last, width / 2 + 74, 12);
  const Image lit = render(scene, seq, true), dark = render(scene, seq, false);
  for (int u = 0; u < lit.width; ++u) {
    if (u >= first && u <= last) continue;
    for (int v = 0; v < lit.height; ++v)
      ASSERT_EQ(lit.at(u, v), dark.at(u, v))
          << "light beyond the fan at (" << u << ", " << v << ")";
  }
  o.laser_fan_deg = 36;
  SimScene wider(o);
  EXPECT_GT(finite_count(truth_of(wider, seq, true).position), last - first + 40);
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
  float moved = 0;
  for (std::size_t u = 0; u < truth.position.size(); ++u) {
    if (std::isfinite(truth.position[u]) && std::isfinite(at_start.position[u]))
      moved = std::max(moved, std::abs(truth.position[u] - at_start.position[u]));
  }
  EXPECT_GT(moved, 2.0f);
  EXPECT_GT(expect_fit_matches_truth(render(scene, seq, true), truth, 0.02), 200);

  // With a strongly textured surface the line brightness varies from column to column; the fit
  // stays within what rounding to 8 bit allows for that brightness.
  o.texture_contrast = 0.8;
  o.laser_peak = 130;
  SimScene textured(o);
  int used = 0;
  const SimGroundTruth t2 = truth_of(textured, seq, true);
  const Image img = render(textured, seq, true);
  for (int u = 0; u < img.width; ++u) {
    if (!std::isfinite(t2.position[u])) continue;
    const int v = static_cast<int>(std::lround(t2.position[u]));
    if (img.at(u, v) < 30 || img.at(u, v) == 255) continue;  // too dark to fit, or clipped
    EXPECT_NEAR(gaussian_peak(img, u), t2.position[u], rounding_bound(img, u, t2.width_px[u]))
        << "column " << u;
    ++used;
  }
  EXPECT_GT(used, 200);
}

TEST(SimScene, LineBrightnessFollowsTheSurfaceAlbedo) {
  // The line's peak is laser_peak times the albedo at the lit point, which the ambient image
  // shows at the same place: the two agree column by column.
  SimSceneOptions o = laser_only(small_options());
  o.texture_contrast = 0.6;
  o.laser_peak = 150;
  SimScene lit(o);
  o.laser_peak = 0;
  o.ambient = 150;
  SimScene ambient(o);
  const std::uint64_t seq = 21;
  const SimGroundTruth truth = truth_of(lit, seq, true);
  const Image line = render(lit, seq, true), surface = render(ambient, seq, false);
  std::vector<double> a, b;
  for (int u = 0; u < line.width; ++u) {
    const double v = truth.position[u];
    const int v0 = static_cast<int>(std::floor(v));
    const double f = v - v0;
    // The ambient albedo interpolated to the line centre; the line's peak from the fitted
    // Gaussian: ln peak = ln B + delta^2 / (2 sigma^2) at the brightest pixel.
    b.push_back((1 - f) * surface.at(u, v0) + f * surface.at(u, v0 + 1));
    int best = v0;
    if (line.at(u, v0 + 1) > line.at(u, best)) best = v0 + 1;
    const double d = best - v;
    a.push_back(line.at(u, best) * std::exp(d * d / (2 * truth.width_px[u] * truth.width_px[u])));
  }
  double ma = 0, mb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ma += a[i] / a.size();
    mb += b[i] / b.size();
  }
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  const double correlation = sab / std::sqrt(saa * sbb);
  std::printf("  correlation of line peak and surface albedo: %.3f\n", correlation);
  EXPECT_GT(correlation, 0.95);
  EXPECT_NEAR(ma, mb, 0.05 * mb);
}

TEST(SimScene, TruthIsNaNNearTheTopAndBottomBorder) {
  SimSceneOptions o = laser_only(small_options());
  o.sway_m = 0;
  o.sway_deg = 0;
  o.calibration.laser.angle_deg = 60;  // steep enough to reach the bottom rows
  const double t =
      std::tan(std::numbers::pi / 2 - o.calibration.laser.angle_deg * std::numbers::pi / 180);
  const double fy = o.calibration.camera.fy, cy = o.calibration.camera.cy;
  const int height = o.calibration.camera.height;
  // Places the line at `row` by choosing the distance: row = cy + fy (t - d / Z).
  auto truth_with_line_at = [&](double row) {
    SimSceneOptions placed = o;
    placed.distance_m = o.calibration.laser.baseline_m / (t - (row - cy) / fy);
    SimScene scene(placed);
    SimGroundTruth truth = truth_of(scene, 0, true);
    return std::pair{truth, render(scene, 0, true)};
  };
  for (double row : {0.2, 1.0, 1.4, height - 2.4, height - 1.3}) {
    const auto [truth, img] = truth_with_line_at(row);
    EXPECT_EQ(finite_count(truth.position), 0) << "line at row " << row;
    EXPECT_EQ(finite_count(truth.depth_m), 0);
    // The line is still drawn.
    const int nearest = static_cast<int>(std::lround(row));
    EXPECT_GT(img.at(10, nearest), 100) << "line at row " << row;
  }
  for (double row : {1.6, 2.5, height - 2.6}) {
    const auto [truth, img] = truth_with_line_at(row);
    EXPECT_EQ(finite_count(truth.position), o.calibration.camera.width) << "line at row " << row;
    EXPECT_NEAR(truth.position[10], row, 1e-3);
    EXPECT_NEAR(gaussian_peak(img, 10), truth.position[10], 0.02);
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
      EXPECT_NEAR(truth.position[u], expected, 1e-3) << "column " << u;
      EXPECT_NEAR(truth.depth_m[u], o.distance_m, 1e-5);
      const double sheet =
          fy * o.calibration.laser.sheet_width_m / o.distance_m / 2.3548200450309493;
      EXPECT_NEAR(truth.width_px[u], std::sqrt(sheet * sheet + o.blur_px * o.blur_px), 1e-5);
    }
  }

  // The same sheet given as a calibrated plane.
  SimSceneOptions calibrated = o;
  calibrated.calibration.laser.plane =
      Eigen::Vector4d{0.0, 1.0, -std::tan(std::numbers::pi / 2 - beta), d};
  SimScene scene(calibrated);
  const SimGroundTruth truth = truth_of(scene, 0, true);
  for (int u = 0; u < o.calibration.camera.width; ++u)
    EXPECT_NEAR(truth.position[u], expected, 1e-3);

  // Scaling the plane equation does not move the sheet.
  calibrated.calibration.laser.plane =
      Eigen::Vector4d{0.0, -3.0, 3.0 * std::tan(std::numbers::pi / 2 - beta), -3.0 * d};
  SimScene scaled(calibrated);
  EXPECT_NEAR(truth_of(scaled, 0, true).position[100], expected, 1e-3);

  // A surface turned about the y axis slants the line.
  o.tilt_y_deg = 20;
  SimScene tilted(o);
  const SimGroundTruth slant = truth_of(tilted, 0, true);
  ASSERT_TRUE(std::isfinite(slant.position.front()) && std::isfinite(slant.position.back()));
  EXPECT_GT(std::abs(slant.position.front() - slant.position.back()), 10.0f);
  for (int u = 1; u < o.calibration.camera.width; ++u) {
    EXPECT_NE(slant.position[u], slant.position[u - 1]);
  }
}

TEST(SimScene, TextureMovesWithTheSurface) {
  SimSceneOptions o = small_options();
  o.noise_sigma = 0;
  {
    SimScene swaying(o);
    // Consecutive frames differ (the camera moves by about 1 mm), frames 1/3 s apart a lot.
    const Image a = render(swaying, 10, false), b = render(swaying, 11, false);
    EXPECT_GT(mean_abs_diff(a, b), 0.1);
    EXPECT_GT(mean_abs_diff(a, render(swaying, 20, false)), 1.0);
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
  const int line = static_cast<int>(std::lround(truth.position[0]));
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
    const int v = static_cast<int>(std::lround(truth.position[u]));
    saturated += img.at(u, v) == 255 ? 1 : 0;
  }
  EXPECT_EQ(saturated, img.width);
}

// ---- Relief, vehicle motion and camera pose -------------------------------------------------

// A pier-like scene at small size: bumps and piles of 5-30 cm, the vehicle moving, the PTU
// scanning (the same field of view as the 1280 x 1024 scenarios).
SimSceneOptions relief_options() {
  SimSceneOptions o = small_options();
  o.tilt_y_deg = 8;
  o.scan_rate_deg_s = 10;
  o.relief_height_m = 0.30;
  o.relief_min_height_m = 0.05;
  o.relief_per_m2 = 1.0;
  o.relief_max_slope = 0.9;
  o.vehicle_speed_m_s = 0.4;
  o.seed = 5;
  return o;
}

// Where the ray of pixel (u, v) first meets the relieved surface, by brute force: marched in
// 1 mm steps through the slab the relief can occupy, then bisected. `base_plane` ignores the
// relief (what a homography assumes). Returns the world point, or NaNs when there is none.
Vec3 ray_hit(const SimScene& scene, const SimCameraPose& pose, double u, double v,
             bool base_plane = false) {
  const SimSceneOptions& o = scene.options();
  const CameraIntrinsics& cam = o.calibration.camera;
  const SurfaceFrame f = surface_frame(o);
  const Vec3 ray{(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0};
  auto point = [&](double z) { return to_world(pose, {z * ray[0], z * ray[1], z}); };
  auto local = [&](double z) {
    const Vec3 p = point(z);
    const Vec3 d{p[0] - f.origin[0], p[1] - f.origin[1], p[2] - f.origin[2]};
    return Vec3{dot3(f.e1, d), dot3(f.e2, d), dot3(f.normal, d)};
  };
  auto above = [&](double z) {
    const Vec3 l = local(z);
    return l[2] - (base_plane ? 0.0 : scene.relief_height(l[0], l[1]));
  };
  // Height above the base plane is affine in z.
  const double h0 = local(0.0)[2], h1 = local(1.0)[2];
  const double nan = std::nan("");
  if (!(h1 < h0)) return {nan, nan, nan};
  const double top = base_plane ? 0.01 : o.relief_height_m + 0.01;
  double lo = (h0 - top) / (h0 - h1), hi = (h0 + 0.01) / (h0 - h1);
  return point(first_zero(above, lo, hi, 0.001 / std::sqrt(dot3(ray, ray))));
}

TEST(SimSceneRelief, HeightsSlopesAndRepetitionAreAsConfigured) {
  SimSceneOptions o = relief_options();
  o.relief_max_slope = 0.8;
  SimScene scene(o);
  constexpr double kCell = 0.005, kPeriod = 5.12;
  double highest = 0, steepest = 0;
  int raised = 0, samples = 0;
  for (double y = 0; y < kPeriod; y += 4 * kCell) {
    for (double x = 0; x < kPeriod; x += 4 * kCell) {
      const double h = scene.relief_height(x, y);
      ASSERT_GE(h, 0.0);
      highest = std::max(highest, h);
      raised += h > 0.01 ? 1 : 0;
      ++samples;
      // Between neighbouring lattice points the rise is at most the slope limit.
      steepest = std::max({steepest, std::abs(scene.relief_height(x + kCell, y) - h) / kCell,
                           std::abs(scene.relief_height(x, y + kCell) - h) / kCell});
      ASSERT_NEAR(scene.relief_height(x + kPeriod, y - 2 * kPeriod), h, 1e-9);  // repeats
    }
  }
  const double fraction = static_cast<double>(raised) / samples;
  std::printf("  relief: highest %.3f m, steepest %.3f, %.0f%% of the surface above 1 cm\n",
              highest, steepest, 100 * fraction);
  EXPECT_LE(highest, o.relief_height_m + 1e-6);
  EXPECT_GT(highest, 0.25);
  EXPECT_LE(steepest, o.relief_max_slope + 1e-3);
  EXPECT_GT(steepest, 0.5 * o.relief_max_slope);
  EXPECT_GT(fraction, 0.15);
  EXPECT_LT(fraction, 0.8);

  // The surface point is the base-plane point raised along the normal toward the camera.
  o.tilt_x_deg = 0;
  o.tilt_y_deg = 0;
  SimScene straight(o);
  const Eigen::Vector3d p = straight.surface_point(0.3, -0.2);
  EXPECT_NEAR(p[0], 0.3, 1e-12);
  EXPECT_NEAR(p[1], -0.2, 1e-12);
  EXPECT_NEAR(p[2], o.distance_m - straight.relief_height(0.3, -0.2), 1e-12);

  // Seeded: the same seed gives the same relief, another seed another.
  SimScene again(o);
  o.seed = 6;
  SimScene other(o);
  int same = 0, differ = 0;
  for (double x = 0; x < kPeriod; x += 0.1) {
    same += again.relief_height(x, 1.0) == straight.relief_height(x, 1.0) ? 1 : 0;
    differ += other.relief_height(x, 1.0) != straight.relief_height(x, 1.0) ? 1 : 0;
  }
  EXPECT_EQ(same, 52);
  EXPECT_GT(differ, 10);
}

TEST(SimSceneRelief, ZeroReliefIsThePlaneWhateverTheOtherReliefOptions) {
  SimSceneOptions o = small_options();
  o.backscatter = 10;
  SimScene plane(o);
  o.relief_height_m = 0;
  o.relief_min_height_m = 0;
  o.relief_per_m2 = 7;
  o.relief_max_slope = 0.3;
  SimScene flat(o);
  EXPECT_EQ(render(plane, 12, true).data, render(flat, 12, true).data);
  EXPECT_EQ(flat.relief_height(0.1, 0.2), 0.0);
  const SimGroundTruth a = truth_of(plane, 12, true), b = truth_of(flat, 12, true);
  EXPECT_EQ(a.position, b.position);
  EXPECT_EQ(a.depth_m, b.depth_m);
}

TEST(SimSceneRelief, TruthOnTheReliefMatchesABruteForceSearchAlongTheCameraRays) {
  // Independent of the simulator's own solution (which walks the sheet in each column): here
  // every pixel's ray is marched to the surface, and the laser is where the hit crosses the sheet.
  const SimSceneOptions o = relief_options();
  SimScene scene(o);
  const std::uint64_t seq = 9;
  const SimGroundTruth truth = truth_of(scene, seq, true);
  const SimCameraPose pose = scene.camera_pose(seq);
  const auto sheet = o.calibration.laser.plane_coefficients();
  auto sheet_side = [&](int u, double v) {
    const Vec3 x = to_camera(pose, ray_hit(scene, pose, u, v));
    return sheet[0] * x[0] + sheet[1] * x[1] + sheet[2] * x[2] + sheet[3];
  };
  const SurfaceFrame f = surface_frame(o);
  int checked = 0, on_relief = 0;
  double worst_row = 0, worst_depth = 0;
  for (int u = 0; u < o.calibration.camera.width; u += 4) {
    if (!std::isfinite(truth.position[u])) continue;
    int crossings = 0;
    const double row = sheet_crossing_row(sheet_side, u, o.calibration.camera.height, crossings);
    ASSERT_EQ(crossings, 1) << "column " << u << ": the line must be seen once";
    const Vec3 world = ray_hit(scene, pose, u, row);
    const double depth = to_camera(pose, world)[2];
    EXPECT_NEAR(truth.position[u], row, 1e-3) << "column " << u;
    EXPECT_NEAR(truth.depth_m[u], depth, 1e-5) << "column " << u;
    worst_row = std::max(worst_row, std::abs(truth.position[u] - row));
    worst_depth = std::max(worst_depth, std::abs(truth.depth_m[u] - depth));
    const Vec3 d{world[0] - f.origin[0], world[1] - f.origin[1], world[2] - f.origin[2]};
    on_relief += dot3(f.normal, d) > 0.05 ? 1 : 0;
    ++checked;
  }
  std::printf("  %d columns, %d on relief above 5 cm: worst row %.2e px, depth %.2e m\n", checked,
              on_relief, worst_row, worst_depth);
  EXPECT_GT(checked, 70);
  EXPECT_GT(on_relief, checked / 5);  // the line does run over the relief

  // And the rendered line is where the truth says (noiseless, laser only).
  SimScene lit(laser_only(o));
  const Image img = render(lit, seq, true);
  const SimGroundTruth t2 = truth_of(lit, seq, true);
  int used = 0;
  for (int u = 0; u < img.width; ++u) {
    if (!std::isfinite(t2.position[u])) continue;
    EXPECT_NEAR(gaussian_peak(img, u), t2.position[u], 0.03) << "column " << u;
    ++used;
  }
  EXPECT_GT(used, 300);
}

TEST(SimSceneRelief, CameraPoseExplainsTheRenderedTextureWithParallax) {
  SimSceneOptions o = relief_options();
  o.noise_sigma = 0;
  o.ambient = 150;
  o.texture_contrast = 0.6;
  SimScene scene(o);

  // Frame 0 is the world frame.
  const SimCameraPose p0 = scene.camera_pose(0);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(p0.rotation(r, c), r == c ? 1.0 : 0.0, 1e-12);
  for (double t : p0.translation)
    EXPECT_NEAR(t, 0.0, 1e-12);

  // A point of frame a found again in frame b where the pose and the relief put it, not where
  // the base plane (a homography) would.
  const std::uint64_t a = 10, b = 14;
  const Image ia = render(scene, a, false), ib = render(scene, b, false);
  const SimCameraPose pa = scene.camera_pose(a), pb = scene.camera_pose(b);
  const SurfaceFrame f = surface_frame(o);
  const CameraIntrinsics& cam = o.calibration.camera;
  auto project = [&](const Vec3& world, double& u, double& v) {
    const Vec3 x = to_camera(pb, world);
    u = cam.cx + cam.fx * x[0] / x[2];
    v = cam.cy + cam.fy * x[1] / x[2];
    return u >= 1 && v >= 1 && u < ib.width - 2 && v < ib.height - 2;
  };
  auto sample = [&](double u, double v) {
    const int u0 = static_cast<int>(u), v0 = static_cast<int>(v);
    const double fu = u - u0, fv = v - v0;
    return (1 - fv) * ((1 - fu) * ib.at(u0, v0) + fu * ib.at(u0 + 1, v0)) +
           fv * ((1 - fu) * ib.at(u0, v0 + 1) + fu * ib.at(u0 + 1, v0 + 1));
  };
  double error_relief = 0, error_plane = 0, parallax = 0;
  int used = 0;
  for (int v = 8; v < ia.height - 8; v += 5) {
    for (int u = 8; u < ia.width - 8; u += 5) {
      const Vec3 hit = ray_hit(scene, pa, u, v);
      const Vec3 d{hit[0] - f.origin[0], hit[1] - f.origin[1], hit[2] - f.origin[2]};
      if (!(dot3(f.normal, d) > 0.05)) continue;  // on the relief only
      double ur, vr, up, vp;
      if (!project(hit, ur, vr) || !project(ray_hit(scene, pa, u, v, true), up, vp)) continue;
      error_relief += std::abs(ia.at(u, v) - sample(ur, vr));
      error_plane += std::abs(ia.at(u, v) - sample(up, vp));
      parallax += std::hypot(ur - up, vr - vp);
      ++used;
    }
  }
  ASSERT_GT(used, 200);
  error_relief /= used;
  error_plane /= used;
  parallax /= used;
  std::printf(
      "  %d points on the relief: parallax %.2f px; grey error %.2f (pose + relief) vs "
      "%.2f (base plane)\n",
      used, parallax, error_relief, error_plane);
  EXPECT_GT(parallax, 1.0);
  EXPECT_LT(error_relief, 4.0);  // bilinear sampling of frame b across hard texture edges
  EXPECT_LT(error_relief, 0.5 * error_plane);

  // Without sway and scan the vehicle alone moves the camera, along the surface's x axis.
  o.sway_m = 0;
  o.sway_deg = 0;
  o.scan_rate_deg_s = 0;
  SimScene cruising(o);
  const SimCameraPose later = cruising.camera_pose(30);  // 1 s
  const Vec3 centre = to_world(later, {0, 0, 0});
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(centre[i], o.vehicle_speed_m_s * f.e1[i], 1e-12);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(later.rotation(r, c), r == c ? 1.0 : 0.0, 1e-12);
}

TEST(SimSceneRelief, RejectsImpossibleReliefOptions) {
  auto rejects = [](auto change) {
    SimSceneOptions o = relief_options();
    change(o);
    EXPECT_THROW(SimScene{o}, std::invalid_argument);
  };
  rejects([](SimSceneOptions& o) { o.relief_height_m = -0.1; });
  rejects([](SimSceneOptions& o) { o.relief_height_m = 0.7; });  // over half the distance
  rejects([](SimSceneOptions& o) { o.relief_min_height_m = 0.4; });
  rejects([](SimSceneOptions& o) { o.relief_per_m2 = -1; });
  rejects([](SimSceneOptions& o) { o.relief_max_slope = 1.5; });
  rejects([](SimSceneOptions& o) { o.relief_max_slope = 0; });
  rejects([](SimSceneOptions& o) { o.relief_max_slope = 0.3; });  // 30 cm features too wide
  rejects([](SimSceneOptions& o) { o.vehicle_speed_m_s = std::nan(""); });
  EXPECT_NO_THROW(SimScene{relief_options()});
}

// Best and mean time of one render() over `frames` frames, in milliseconds.
std::pair<double, double> render_ms(SimScene& scene, std::vector<std::uint8_t>& buffer,
                                    int frames) {
  double best = 1e300, total = 0;
  for (int i = 0; i < frames; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    scene.render(static_cast<std::uint64_t>(i), i % 2 == 0, buffer);
    const auto t1 = std::chrono::steady_clock::now();
    const double ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    best = std::min(best, ms);
    total += ms;
  }
  return {best, total / frames};
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

  SimSceneOptions pier = o;
  pier.relief_height_m = 0.3;
  pier.vehicle_speed_m_s = 0.4;
  SimScene relief(pier);
  SimGroundTruth relief_truth;
  relief.ground_truth(0, true, relief_truth);

  // Colour (a Bayer mosaic and RGB), marine snow, caustics, turbid water, bright marks and the
  // oblique family of a turned sheet; the truth also along a family of the caller's.
  SimSceneOptions murky = o;
  murky.colour = SimColour::kBayerGrbg;
  murky.laser_rgb = {1.0, 0.08, 0.03};
  murky.ambient_rgb = {0.4, 0.8, 1.0};
  murky.snow_per_frame = 2000;
  murky.caustic_peak = 5;
  murky.forward_scatter = 0.3;
  murky.veiling = 0.2;
  murky.marks_per_m2 = 20;
  SimScene bayer(murky);
  murky.colour = SimColour::kRgb;
  murky.calibration.laser.plane = Eigen::Vector4d{-0.5, 0.866, -0.176, 0.25};
  SimScene rgb(murky);
  ASSERT_NE(rgb.lines().along[0], 0.0);  // oblique
  std::vector<std::uint8_t> colour_buffer(rgb.raw_bytes());
  SimGroundTruth rgb_truth, column_truth;
  rgb.ground_truth(0, true, rgb_truth);
  const SimLineFamily columns = SimLineFamily::columns(o.calibration.camera.width);
  rgb.ground_truth(0, true, columns, column_truth);

  const std::size_t before = g_allocations.load();
  bayer.render(5, true, colour_buffer);
  bayer.render(6, false, colour_buffer);
  rgb.render(7, true, colour_buffer);
  rgb.ground_truth(7, true, rgb_truth);
  rgb.ground_truth(7, true, columns, column_truth);
  relief.render(3, true, buffer);
  relief.ground_truth(3, true, relief_truth);
  scene.render(0, true, buffer);
  scene.render(1, false, buffer);
  scene.render(1000, true, buffer);
  scene.ground_truth(1000, true, truth);
  const std::size_t after = g_allocations.load();
  EXPECT_EQ(after - before, 0u) << "render() or ground_truth() allocated";
  // The colour frame is sane: its red channel (the red laser's) lit along the line and by snow.
  std::vector<std::uint8_t> dark(rgb.raw_bytes());
  rgb.render(7, false, dark);
  int lit = 0;
  for (std::size_t i = 0; i < dark.size(); i += 3)
    lit += colour_buffer[i] > dark[i] + 30 ? 1 : 0;
  EXPECT_GT(lit, 2000);

  // The frame is sane: a bright line where the truth says.
  const int u = 1024;
  ASSERT_TRUE(std::isfinite(truth.position[u]));
  const int v = static_cast<int>(std::lround(truth.position[u]));
  const double fit = gaussian_peak(Image{2048, 1536, 1, buffer}, u);
  EXPECT_NEAR(fit, truth.position[u], 1.0);
  EXPECT_GT(buffer[static_cast<std::size_t>(v) * 2048 + u], 120);

  if (!kSanitized) {
    const auto [best, mean] = render_ms(scene, buffer, 10);
    std::printf("  2048x1536 render: best %.1f ms, mean %.1f ms\n", best, mean);
    SimSceneOptions vga = o;
    vga.calibration = Calibration{};
    SimScene small(vga);
    std::vector<std::uint8_t> small_buffer(small.format().bytes());
    const auto [small_best, small_mean] = render_ms(small, small_buffer, 10);
    std::printf("  1280x1024 render: best %.1f ms, mean %.1f ms\n", small_best, small_mean);
    vga.relief_height_m = 0.3;
    vga.relief_max_slope = 0.9;
    vga.vehicle_speed_m_s = 0.4;
    SimScene small_relief(vga);
    const auto [relief_best, relief_mean] = render_ms(small_relief, small_buffer, 10);
    std::printf("  1280x1024 render with relief: best %.1f ms, mean %.1f ms\n", relief_best,
                relief_mean);
  }
}

TEST(SimScene, AllocationCounterWorks) {
  // Guards the test above against a counter that never counts.
  const std::size_t before = g_allocations.load();
  void* volatile p = ::operator new(64);
  ::operator delete(p);
  EXPECT_EQ(g_allocations.load() - before, 1u);
}

}  // namespace
}  // namespace laserline::hal
