// A frame's detection split in parts (pipeline/parts.hpp) gives the profile of one part to the bit:
// every detector, 1 to 4 parts, the parts run in order and in reverse, on simulator scenes of
// several kinds (scan, alternating laser, turbid water, clipped core, a laser beside the camera).
#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "hal/sim/sim_scene.hpp"
#include "pipeline/detector.hpp"
#include "pipeline/parts.hpp"
#include "tools/evaluation.hpp"

namespace {

using namespace laserline;

// The parts last to first: a part must not depend on another having run before it.
class ReversedParts final : public pipeline::PartRunner {
 public:
  explicit ReversedParts(int parts) : parts_(parts) {}
  int parts() const override { return parts_; }
  void run(pipeline::PartWork work) override {
    for (int part = parts_ - 1; part >= 0; --part)
      work(part);
  }

 private:
  int parts_;
};

struct Frames {
  tools::Scenario scenario;
  hal::FrameFormat format;
  std::vector<std::vector<std::uint8_t>> pixels;
  std::vector<bool> laser_on;
};

Frames render(const std::string& name, int width, int height, int count) {
  for (const tools::Scenario& s : tools::standard_scenarios(width, height)) {
    if (s.name != name) continue;
    Frames frames{s, {}, {}, {}};
    hal::SimScene scene(s.scene);
    frames.format = scene.format();
    for (int i = 0; i < count; ++i) {
      const auto sequence = static_cast<std::uint64_t>(s.first_frame + i);
      const bool on = !s.alternate || sequence % 2 == 0;
      frames.pixels.emplace_back(frames.format.bytes());
      scene.render(sequence, on, frames.pixels.back());
      frames.laser_on.push_back(on);
    }
    return frames;
  }
  ADD_FAILURE() << "no scenario " << name;
  return {};
}

// Every frame's profile from `detector` run with `runner`; frame i searched in regions[i] where
// given (set between frames, as the worker does).
std::vector<pipeline::Profile> detect_all(
    const Frames& frames, const std::string& detector_name, pipeline::PartRunner& runner,
    const std::vector<pipeline::DetectionRegion>& regions = {}) {
  pipeline::DetectorOptions options;
  options.geometry = daemon::scanner_geometry(frames.scenario.scene.calibration);
  const std::unique_ptr<pipeline::Detector> detector =
      pipeline::make_detector(detector_name, options);
  detector->use_parts(runner);
  const int width = frames.format.width, height = frames.format.height;
  detector->reset(width, height);
  std::vector<pipeline::Profile> profiles;
  for (std::size_t i = 0; i < frames.pixels.size(); ++i) {
    if (i < regions.size()) detector->set_region(regions[i]);
    profiles.emplace_back(detector->max_points(width, height));
    const pipeline::ImageView view{frames.pixels[i].data(), width, height, frames.format.stride};
    const auto sequence = static_cast<std::uint64_t>(frames.scenario.first_frame) + i;
    detector->detect(view, {sequence, frames.laser_on[i]}, profiles.back());
  }
  return profiles;
}

// Equal to the bit (NaN equal to NaN), the first difference described.
std::string difference(const pipeline::Profile& a, const pipeline::Profile& b) {
  if (a.size() != b.size()) {
    return std::to_string(a.size()) + " points vs " + std::to_string(b.size());
  }
  if (a.background_sequence() != b.background_sequence()) return "background frame differs";
  for (std::size_t k = 0; k < a.size(); ++k) {
    const pipeline::ProfilePoint& p = a.points()[k];
    const pipeline::ProfilePoint& q = b.points()[k];
    if (p.u != q.u || std::memcmp(&p.v, &q.v, sizeof p.v) != 0 ||
        std::memcmp(&p.snr_db, &q.snr_db, sizeof p.snr_db) != 0 || p.valid != q.valid ||
        p.segment != q.segment || std::memcmp(p.xyz.data(), q.xyz.data(), sizeof p.xyz) != 0) {
      return "point " + std::to_string(k) + ": u " + std::to_string(p.u) + " v " +
             std::to_string(p.v) + " valid " + std::to_string(p.valid) + " vs u " +
             std::to_string(q.u) + " v " + std::to_string(q.v) + " valid " +
             std::to_string(q.valid);
    }
  }
  return "";
}

void expect_same_in_parts(const Frames& frames) {
  for (const std::string& detector : pipeline::detector_names()) {
    pipeline::SequentialParts one(1);
    const std::vector<pipeline::Profile> reference = detect_all(frames, detector, one);
    std::size_t valid = 0;
    for (const pipeline::Profile& profile : reference)
      for (const pipeline::ProfilePoint& p : profile.points())
        valid += p.valid ? 1 : 0;
    EXPECT_GT(valid, 0u) << frames.scenario.name << " " << detector << ": no points to compare";
    for (int parts = 2; parts <= 4; ++parts) {
      pipeline::SequentialParts in_order(parts);
      ReversedParts reversed(parts);
      for (pipeline::PartRunner* runner : {static_cast<pipeline::PartRunner*>(&in_order),
                                           static_cast<pipeline::PartRunner*>(&reversed)}) {
        const std::vector<pipeline::Profile> split = detect_all(frames, detector, *runner);
        for (std::size_t i = 0; i < reference.size(); ++i) {
          EXPECT_EQ(difference(reference[i], split[i]), "")
              << frames.scenario.name << " " << detector << " frame " << i << ", " << parts
              << " parts" << (runner == &reversed ? " in reverse" : "");
        }
      }
    }
  }
}

TEST(Parts, EveryDetectorGivesTheSameProfilesInParts) {
  // 640 columns: three strips of the front end, so that four parts leave one without any.
  for (const char* scenario :
       {"ambient", "ambient-alternate", "pier", "backscatter", "clipped", "beside"}) {
    expect_same_in_parts(render(scenario, 640, 480, 5));
  }
  // Wider: five strips.
  expect_same_in_parts(render("ambient", 1280, 1024, 4));
}

// Within regions: the parts split the region's columns, some parts with none; the region changes
// between frames (a part's rings then hold columns another part made before).
TEST(Parts, EveryDetectorGivesTheSameProfilesInPartsWithinARegion) {
  const Frames frames = render("ambient", 1280, 1024, 6);
  const std::vector<pipeline::DetectionRegion> regions = {
      {300, 200, 700, 600}, {300, 200, 700, 600}, {517, 0, 90, 1024},
      {517, 0, 90, 1024},   {0, 450, 1280, 300},  {1100, 100, 180, 900}};
  for (const std::string& detector : pipeline::detector_names()) {
    pipeline::SequentialParts one(1);
    const std::vector<pipeline::Profile> reference = detect_all(frames, detector, one, regions);
    for (std::size_t i = 0; i < reference.size(); ++i) {
      const pipeline::DetectionRegion& r = regions[i];
      std::size_t valid = 0;
      for (const pipeline::ProfilePoint& p : reference[i].points()) {
        valid += p.valid ? 1 : 0;
        const auto [x, y] = reference[i].image_point(p);
        EXPECT_TRUE(r.contains(x, y))
            << detector << " frame " << i << ": (" << x << ", " << y << ") outside " << r.text();
      }
      // (The first frame of a background detector has no background yet.)
      if (i > 1) {
        EXPECT_GT(valid, 0u) << detector << " frame " << i << ": no points to compare";
      }
    }
    for (int parts : {2, 3}) {
      pipeline::SequentialParts in_order(parts);
      ReversedParts reversed(parts);
      for (pipeline::PartRunner* runner : {static_cast<pipeline::PartRunner*>(&in_order),
                                           static_cast<pipeline::PartRunner*>(&reversed)}) {
        const std::vector<pipeline::Profile> split = detect_all(frames, detector, *runner, regions);
        for (std::size_t i = 0; i < reference.size(); ++i) {
          EXPECT_EQ(difference(reference[i], split[i]), "")
              << detector << " frame " << i << " in " << regions[i].text() << ", " << parts
              << " parts" << (runner == &reversed ? " in reverse" : "");
        }
      }
    }
  }
}

TEST(Parts, PartRangesCoverTheItemsOnce) {
  for (int count : {0, 1, 3, 8, 191}) {
    for (int parts = 1; parts <= pipeline::kMaxParts; ++parts) {
      int next = 0;
      for (int part = 0; part < parts; ++part) {
        const auto [first, end] = pipeline::part_range(count, part, parts);
        EXPECT_EQ(first, next);
        EXPECT_LE(first, end);
        next = end;
      }
      EXPECT_EQ(next, count);
    }
  }
}

}  // namespace
