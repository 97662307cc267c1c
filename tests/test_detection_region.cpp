// The detection region (DetectorOptions::roi, Detector::set_region()): no point or candidate
// outside it; inside it what the whole frame gives (the filters still read around it); bad
// regions refused naming the option; a change between frames allocates nothing. For the paper's
// mounting (epipolar lines along columns) and a projector beside the camera (along rows).
#include <gtest/gtest.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "allocation_counter.hpp"
#include "pipeline/detector.hpp"
#include "pipeline/frontend.hpp"
#include "pipeline/options.hpp"

namespace laserline::pipeline {
namespace {

// The paper's mounting on a 320 x 256 camera (the default sheet: lines along the columns).
ScannerGeometry columns_geometry() {
  ScannerGeometry g;
  g.width = 320;
  g.height = 256;
  g.fx = g.fy = 350;
  g.cx = 159.5;
  g.cy = 127.5;
  return g;
}

// The same camera turned a quarter: the projector beside it, the line running down the image
// and searched along rows (the transposed camera: fx and fy, cx and cy, the sheet's a and b
// swapped).
ScannerGeometry rows_geometry() {
  ScannerGeometry g = columns_geometry();
  std::swap(g.width, g.height);
  std::swap(g.fx, g.fy);
  std::swap(g.cx, g.cy);
  std::swap(g.laser_plane[0], g.laser_plane[1]);
  return g;
}

struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> pixels;
  ImageView view() const { return {pixels.data(), width, height, width}; }
  Image transposed() const {
    Image t{height, width, std::vector<std::uint8_t>(pixels.size())};
    for (int v = 0; v < height; ++v)
      for (int u = 0; u < width; ++u)
        t.pixels[static_cast<std::size_t>(u) * height + v] = pixels[v * width + u];
    return t;
  }
};

// Texture (ambient light on a wall), with the laser line at row 90 + 0.2 u when lit: a frame of
// the paper's mounting.
Image columns_frame(bool laser_on, int seed) {
  const ScannerGeometry g = columns_geometry();
  Image image{g.width, g.height, std::vector<std::uint8_t>(g.width * g.height)};
  std::uint32_t state = 12345u + static_cast<std::uint32_t>(seed);
  for (int v = 0; v < g.height; ++v) {
    for (int u = 0; u < g.width; ++u) {
      state = state * 1664525u + 1013904223u;
      double x = 70 + 40 * std::sin(u * 0.11) * std::cos(v * 0.07) + (state >> 29);
      if (laser_on) {
        const double d = v - (90.0 + 0.2 * u);
        x += 120 * std::exp(-d * d / 2.0);
      }
      image.pixels[v * g.width + u] =
          static_cast<std::uint8_t>(std::clamp(std::round(x), 0., 255.));
    }
  }
  return image;
}

// A profile's points in the frame's pixels.
struct FramePoint {
  double x, y;
  float snr_db;
  bool valid;
  bool operator==(const FramePoint&) const = default;
};

std::vector<FramePoint> frame_points(const Profile& profile) {
  std::vector<FramePoint> out;
  for (const ProfilePoint& p : profile.points()) {
    const auto [x, y] = profile.image_point(p);
    out.push_back({x, y, p.snr_db, p.valid});
  }
  return out;
}

// The points that lie in `region` (the pixel nearest them).
std::vector<FramePoint> inside(const std::vector<FramePoint>& points, const DetectionRegion& r) {
  std::vector<FramePoint> out;
  for (const FramePoint& p : points)
    if (r.contains(p.x, p.y)) out.push_back(p);
  return out;
}

// Each case: the frames, the geometry, and a region in the frame's pixels.
struct Mounting {
  const char* name;
  ScannerGeometry geometry;
  bool transpose;
  DetectionRegion region;
};

std::vector<Mounting> mountings() {
  // Columns 37 .. 286 cross the front-end's strip of columns at 256 and no warp block's edge;
  // rows 100 .. 139 hold the line over columns 50 .. 249.
  const DetectionRegion region{37, 100, 250, 40};
  return {{"columns", columns_geometry(), false, region},
          {"rows", rows_geometry(), true, {region.y, region.x, region.height, region.width}}};
}

// Frames 0 to 3 (the laser on, off, on, on: background subtracts frame 1 from frame 2) through
// `detector`; the profile of each.
std::vector<Profile> run(Detector& detector, bool transpose) {
  std::vector<Profile> profiles;
  const bool laser[] = {true, false, true, true};
  for (int i = 0; i < 4; ++i) {
    Image frame = columns_frame(laser[i], i);
    if (transpose) frame = frame.transposed();
    Profile out(detector.max_points(frame.width, frame.height));
    detector.detect(frame.view(), {static_cast<std::uint64_t>(i), laser[i]}, out);
    profiles.push_back(out);
  }
  return profiles;
}

TEST(DetectionRegion, EveryDetectorGivesPointsOnlyInsideAndThereThoseOfTheWholeFrame) {
  for (const Mounting& m : mountings()) {
    for (const std::string& name : detector_names()) {
      SCOPED_TRACE(std::string(m.name) + " " + name);
      DetectorOptions options;
      options.geometry = m.geometry;
      auto whole = make_detector(name, options);
      options.roi = m.region;
      auto limited = make_detector(name, options);
      whole->reset(m.geometry.width, m.geometry.height);
      limited->reset(m.geometry.width, m.geometry.height);
      EXPECT_EQ(limited->region(), m.region);
      EXPECT_EQ(whole->region(), (DetectionRegion{0, 0, m.geometry.width, m.geometry.height}));
      const std::vector<Profile> all = run(*whole, m.transpose);
      const std::vector<Profile> some = run(*limited, m.transpose);
      for (std::size_t i = 0; i < all.size(); ++i) {
        const std::vector<FramePoint> got = frame_points(some[i]);
        for (const FramePoint& p : got)
          EXPECT_TRUE(m.region.contains(p.x, p.y)) << "frame " << i << ": " << p.x << ", " << p.y;
        if (i == 1) continue;  // laser off: nothing either way
        int valid = 0;
        for (const FramePoint& p : got)
          valid += p.valid ? 1 : 0;
        EXPECT_GT(valid, 150) << "frame " << i;  // the line crosses 200 of the region's columns
        // Backprojection validates segments: one cut by the region's edge is a shorter one.
        if (name == "backprojection") continue;
        const std::vector<FramePoint> expected = inside(frame_points(all[i]), m.region);
        if (name == "maxvalue") {
          // Each column's brightest pixel among the rows searched: where the line leaves the
          // region, the texture's. Where it is inside, the line's; its SNR compares the peak with
          // the mean of the rows searched.
          for (const FramePoint& e : expected) {
            EXPECT_NE(std::find_if(got.begin(), got.end(),
                                   [&](const FramePoint& p) { return p.x == e.x && p.y == e.y; }),
                      got.end())
                << "frame " << i << ": " << e.x << ", " << e.y;
          }
          EXPECT_GT(expected.size(), 190u);
          continue;
        }
        // The line's choice among the candidates looks along the whole line: where it leaves the
        // region (a few pixels from its edges) that may differ. Elsewhere the same points.
        const DetectionRegion well_inside{m.region.x + 3, m.region.y + 3, m.region.width - 6,
                                          m.region.height - 6};
        std::size_t same = 0;
        for (const FramePoint& e : expected) {
          if (!e.valid || !well_inside.contains(e.x, e.y)) continue;
          EXPECT_NE(std::find(got.begin(), got.end(), e), got.end())
              << "frame " << i << ": " << e.x << ", " << e.y << " (" << e.snr_db << " dB)";
          ++same;
        }
        EXPECT_GT(same, 150u) << "frame " << i;
      }
    }
  }
}

// The front-end's candidates (all of them, before the line is chosen) in regions at the frame's
// edges, across strips and warp blocks, on a textured frame with many: inside, those of the whole
// frame to the bit (the band-pass, noise window and warp read around the region); outside, only
// those within the few rows the refinement of the chosen one can move it by (the line's choice
// takes them away), none in other columns.
TEST(DetectionRegion, FrontendCandidatesInsideAreThoseOfTheWholeFrame) {
  const ScannerGeometry g = columns_geometry();
  FrontendOptions options;
  options.max_candidates_per_column = 255;  // no column's strongest few depend on the rows
  const Image current = columns_frame(true, 7), background = columns_frame(false, 8);
  Homography h;  // a small roll and shift: warp blocks partly off the background at the edges
  h.h << 1, 0.004, 2.7, -0.004, 1, -3.2, 0, 0, 1;
  const DetectionRegion regions[] = {{37, 100, 250, 40}, {0, 0, 320, 256}, {300, 3, 20, 250},
                                     {5, 200, 64, 56},   {255, 97, 2, 3},  {0, 0, 1, 1},
                                     {31, 60, 195, 150}, {100, 0, 120, 30}};
  for (const bool subtract : {false, true}) {
    Frontend frontend(g, options);
    frontend.reset(g.width, g.height);
    auto collect = [&](const DetectionRegion& region) {
      frontend.set_region(region);
      if (subtract) {
        frontend.set_frame_minus_background(current.view(), background.view(), h);
      } else {
        frontend.set_frame(current.view());
      }
      Profile out(frontend.max_points(g.width));
      frontend.collect_candidates(out);
      return frame_points(out);
    };
    const std::vector<FramePoint> all = collect({});
    ASSERT_GT(all.size(), 2u * g.width) << "textured: many candidates";
    std::size_t compared = 0;
    for (const DetectionRegion& region : regions) {
      SCOPED_TRACE((subtract ? "minus background, region " : "region ") + region.text());
      const std::vector<FramePoint> got = collect(region);
      const std::vector<FramePoint> expected = inside(all, region);
      EXPECT_EQ(inside(got, region), expected);
      const DetectionRegion near{region.x, region.y - 8, region.width, region.height + 16};
      EXPECT_EQ(inside(got, near), got);
      compared += expected.size();
    }
    EXPECT_GT(compared, all.size() / 2);
    EXPECT_EQ(collect({}), all) << "the whole frame again";
  }
}

// Epipolar lines at an angle: the detectors search a rotation of the frame, the region's bounds
// there; what comes out lies in the region of the frame. (A textured frame without a line: the
// candidates of every detector but maxvalue's bright pixels.)
TEST(DetectionRegion, ObliqueSearchKeepsOnlyPointsInsideTheFrameRegion) {
  ScannerGeometry g = columns_geometry();
  const double turn = 30 * 3.14159265358979 / 180;  // the sheet turned about the optical axis
  const double b = g.laser_plane[1];
  g.laser_plane[0] = b * std::sin(turn);
  g.laser_plane[1] = b * std::cos(turn);
  const Image frame = columns_frame(false, 5);
  const DetectionRegion region{60, 40, 150, 120};
  for (const std::string& name : detector_names()) {
    SCOPED_TRACE(name);
    DetectorOptions options;
    options.geometry = g;
    options.roi = region;
    auto detector = make_detector(name, options);
    detector->reset(g.width, g.height);
    Profile out(detector->max_points(g.width, g.height));
    std::size_t found = 0;
    for (std::uint64_t i = 0; i < 3; ++i) {
      detector->detect(frame.view(), {i, true}, out);
      ASSERT_EQ(out.axes().axis, SearchAxis::kOblique);
      for (const FramePoint& p : frame_points(out)) {
        EXPECT_TRUE(region.contains(p.x, p.y)) << p.x << ", " << p.y;
        ++found;
      }
    }
    EXPECT_GT(found, 10u);
  }
}

TEST(DetectionRegion, OutsideTheFrameOrEmptyIsRefusedNamingTheOption) {
  auto problem_of = [](const DetectionRegion& region) -> std::string {
    try {
      region.validate(320, 256);
    } catch (const OptionError& e) {
      EXPECT_EQ(e.field(), "roi");
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(problem_of({}), "") << "the whole frame";
  EXPECT_EQ(problem_of({0, 0, 320, 256}), "");
  EXPECT_EQ(problem_of({319, 255, 1, 1}), "");
  EXPECT_EQ(problem_of({-1, 0, 10, 10}), "roi x and y must be at least 0, got [-1, 0, 10, 10]");
  EXPECT_EQ(problem_of({0, 0, 0, 10}),
            "roi width and height must be at least 1 pixel, got [0, 0, 0, 10]");
  EXPECT_EQ(problem_of({5, 5, 0, 0}),
            "roi width and height must be at least 1 pixel, got [5, 5, 0, 0]");
  EXPECT_EQ(problem_of({300, 0, 21, 10}), "roi [300, 0, 21, 10] reaches beyond the 320x256 frame");
  EXPECT_EQ(problem_of({1, 0, INT_MAX, 10}),
            "roi [1, 0, 2147483647, 10] reaches beyond the 320x256 frame");
  DetectorOptions options;
  options.geometry = columns_geometry();
  options.roi = {0, 200, 10, 57};
  for (const std::string& name : detector_names()) {
    try {
      make_detector(name, options);
      ADD_FAILURE() << name << " took a region beyond the frame";
    } catch (const OptionError& e) {
      EXPECT_EQ(e.field(), "roi") << name;
    }
  }
}

TEST(DetectionRegion, ChangesBetweenFramesWithoutAllocating) {
  ASSERT_TRUE(testing::allocation_counter_works());
  const ScannerGeometry g = columns_geometry();
  const Image lit = columns_frame(true, 1), dark = columns_frame(false, 2);
  DetectorOptions options;
  options.geometry = g;
  for (const std::string& name : detector_names()) {
    auto detector = make_detector(name, options);
    detector->reset(g.width, g.height);
    Profile out(detector->max_points(g.width, g.height));
    detector->detect(lit.view(), {0, true}, out);
    testing::start_counting_allocations();
    const DetectionRegion regions[] = {{37, 100, 250, 40}, {0, 0, 320, 256}, {}, {10, 90, 30, 30}};
    std::uint64_t sequence = 1;
    for (const DetectionRegion& region : regions) {
      detector->set_region(region);
      detector->detect(dark.view(), {sequence++, false}, out);
      detector->detect(lit.view(), {sequence++, true}, out);
    }
    const testing::Allocations counted = testing::stop_counting_allocations();
    EXPECT_EQ(counted.count, 0) << name << " allocated " << counted.bytes << " bytes";
    EXPECT_EQ(detector->region(), (DetectionRegion{10, 90, 30, 30})) << name;
    for (const ProfilePoint& p : out.points()) {
      const auto [x, y] = out.image_point(p);
      EXPECT_TRUE(detector->region().contains(x, y)) << name << ": " << x << ", " << y;
    }
  }
}

}  // namespace
}  // namespace laserline::pipeline
