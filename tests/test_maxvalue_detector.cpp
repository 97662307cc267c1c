#include "pipeline/maxvalue_detector.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "pipeline/subpixel.hpp"

namespace laserline::pipeline {
namespace {

struct Image {
  int width, height;
  std::vector<std::uint8_t> pixels;
  Image(int w, int h, std::uint8_t fill = 0) : width(w), height(h), pixels(w * h, fill) {}
  std::uint8_t& at(int u, int v) { return pixels[v * width + u]; }
  ImageView view() const { return {pixels.data(), width, height, width}; }
};

// A Gaussian line centred at `centre(u)` with the given peak, point-sampled.
template <typename Centre>
Image gaussian_line(int w, int h, Centre centre, double sigma, double peak, std::uint8_t base) {
  Image img(w, h, base);
  for (int u = 0; u < w; ++u) {
    for (int v = 0; v < h; ++v) {
      const double d = v - centre(u);
      const double value = base + peak * std::exp(-d * d / (2 * sigma * sigma));
      img.at(u, v) = static_cast<std::uint8_t>(std::min(255.0, std::round(value)));
    }
  }
  return img;
}

TEST(GaussianOffset, ExactForASampledGaussian) {
  for (double true_offset : {-0.45, -0.2, 0.0, 0.13, 0.4}) {
    auto g = [&](double x) {
      return 200.0 * std::exp(-(x - true_offset) * (x - true_offset) / 4.0);
    };
    EXPECT_NEAR(gaussian_offset(g(-1), g(0), g(1)), true_offset, 1e-5);
  }
}

TEST(GaussianOffset, FlatOrValleyGivesZero) {
  EXPECT_EQ(gaussian_offset(10, 10, 10), 0.0f);
  EXPECT_EQ(gaussian_offset(20, 10, 20), 0.0f);
}

TEST(MaxValueDetector, FindsASubPixelLineInEveryColumn) {
  const int w = 64, h = 48;
  auto centre = [](int u) { return 20.0 + 0.07 * u; };
  Image img = gaussian_line(w, h, centre, 1.5, 200, 5);
  MaxValueDetector detector(40);
  detector.reset(w, h);
  Profile profile(detector.max_points(w, h));
  detector.detect(img.view(), {}, profile);
  ASSERT_EQ(profile.size(), static_cast<std::size_t>(w));
  double sum_sq = 0;
  for (const auto& p : profile.points()) {
    const double err = p.v - centre(p.u);
    sum_sq += err * err;
    EXPECT_LT(std::abs(err), 0.05) << "column " << p.u;
    EXPECT_GT(p.snr_db, 10.0f);
    EXPECT_EQ(p.segment, -1);
    EXPECT_TRUE(p.valid);
    EXPECT_TRUE(std::isnan(p.xyz[0]));
  }
  EXPECT_LT(std::sqrt(sum_sq / w), 0.02);
}

TEST(MaxValueDetector, IgnoresColumnsBelowThreshold) {
  Image img = gaussian_line(
      32, 32, [](int) { return 10.0; }, 1.2, 30, 0);
  for (int v = 0; v < 32; ++v)
    img.at(5, v) = 0;
  img.at(7, 20) = 100;  // one bright column
  MaxValueDetector detector(40);
  detector.reset(32, 32);
  Profile profile(32);
  detector.detect(img.view(), {}, profile);
  ASSERT_EQ(profile.size(), 1u);
  EXPECT_EQ(profile.points()[0].u, 7);
  EXPECT_FLOAT_EQ(profile.points()[0].v, 20.0f);
}

TEST(MaxValueDetector, SaturatedRunTakesItsCentre) {
  // A clipped core from row 10 to 14 inclusive: centre 12, whatever the asymmetric flanks say.
  Image img(4, 32, 10);
  for (int u = 0; u < 4; ++u) {
    for (int v = 10; v <= 14; ++v)
      img.at(u, v) = 255;
    img.at(u, 9) = 200;
    img.at(u, 15) = 120;
  }
  MaxValueDetector detector(40);
  detector.reset(4, 32);
  Profile profile(4);
  detector.detect(img.view(), {}, profile);
  ASSERT_EQ(profile.size(), 4u);
  for (const auto& p : profile.points())
    EXPECT_FLOAT_EQ(p.v, 12.0f);
}

TEST(MaxValueDetector, PeakOnTheBorderIsNotRefinedOutsideTheImage) {
  Image img(2, 8, 0);
  img.at(0, 0) = 200;
  img.at(0, 1) = 100;
  img.at(1, 7) = 200;
  img.at(1, 6) = 100;
  MaxValueDetector detector(40);
  detector.reset(2, 8);
  Profile profile(2);
  detector.detect(img.view(), {}, profile);
  ASSERT_EQ(profile.size(), 2u);
  EXPECT_FLOAT_EQ(profile.points()[0].v, 0.0f);
  EXPECT_FLOAT_EQ(profile.points()[1].v, 7.0f);
}

TEST(MaxValueDetector, FailsUnderAmbientLightBrighterThanTheLaser) {
  // The baseline's known weakness: a brighter texture blob wins the column.
  Image img = gaussian_line(
      16, 64, [](int) { return 40.0; }, 1.5, 120, 10);
  for (int u = 0; u < 16; ++u)
    img.at(u, 10) = 250;
  MaxValueDetector detector(40);
  detector.reset(16, 64);
  Profile profile(16);
  detector.detect(img.view(), {}, profile);
  ASSERT_EQ(profile.size(), 16u);
  for (const auto& p : profile.points())
    EXPECT_NEAR(p.v, 10.0f, 0.5f);
}

TEST(Profile, NeverGrowsBeyondItsCapacity) {
  Profile profile(2);
  EXPECT_TRUE(profile.add({}));
  EXPECT_TRUE(profile.add({}));
  EXPECT_FALSE(profile.add({}));
  EXPECT_TRUE(profile.overflowed());
  EXPECT_EQ(profile.size(), 2u);
  EXPECT_EQ(profile.capacity(), 2u);
  profile.clear();
  EXPECT_FALSE(profile.overflowed());
}

TEST(Profile, CopiesKeepTheirCapacity) {
  const Profile prototype(1000);
  const Profile copy(prototype);
  EXPECT_EQ(copy.capacity(), 1000u);
  Profile assigned;
  assigned = prototype;
  EXPECT_GE(assigned.capacity(), 1000u);
  std::vector<Profile> slots(3, prototype);
  for (const auto& slot : slots)
    EXPECT_EQ(slot.capacity(), 1000u);
}

TEST(DetectorRegistry, KnowsMaxValueAndRejectsUnknownNames) {
  EXPECT_NE(make_detector("maxvalue", {}), nullptr);
  EXPECT_EQ(make_detector("nonsense", {}), nullptr);
}

}  // namespace
}  // namespace laserline::pipeline
