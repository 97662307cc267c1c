// Every simulated scenario against its exact ground truth (the figures laserline-evaluate prints
// and the README's table shows): what the default detector (`background`) and `backprojection`
// reach in each, and how they stand against `fir` and `maxvalue`.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <string>

#include "tools/evaluation.hpp"

namespace laserline::tools {
namespace {

// Scored once per scenario and detector (the whole table takes a few seconds per detector).
const Score& score(const std::string& scenario, const std::string& detector) {
  static std::map<std::pair<std::string, std::string>, Score> scores;
  const auto key = std::make_pair(scenario, detector);
  if (const auto found = scores.find(key); found != scores.end()) return found->second;
  for (const Scenario& s : standard_scenarios()) {
    if (s.name != scenario) continue;
    const Score result = evaluate(s, detector, {}, 2.0);
    std::printf("%-24s %-14s recall %6.2f%% precision %6.2f%% rms %.3f px bias %+.3f px\n",
                scenario.c_str(), detector.c_str(), 100 * result.recall(), 100 * result.precision(),
                result.rms(), result.bias());
    return scores.emplace(key, result).first->second;
  }
  ADD_FAILURE() << "no scenario " << scenario;
  return scores[key];
}

// Lower bounds of recall and precision, in percent.
struct Floor {
  const char* scenario;
  double recall, precision;
  // backprojection's recall and precision at most this many points below background's
  double backprojection_recall_loss = 2.0, backprojection_precision_loss = 0.2;
};

// The default detector. Daylight, dark and hover scenes reach 97 % recall, and every scene 99 %
// precision but hover-daylight (98.9 %: held still in daylight, a texture stripe beside a faint
// stretch of the line can be chosen, and nothing tells them apart but the line's history); turbid
// scenes come within 3 points of the best detector's recall (checked below).
constexpr Floor kBackground[] = {
    {"clean", 99.5, 99.9},
    {"ambient", 99.0, 99.3},
    {"ambient-alternate", 99.0, 99.3},
    {"pier", 97.0, 99.0},
    {"backscatter", 99.5, 99.5},
    {"clipped", 99.5, 99.5},
    {"dark", 99.5, 99.9},
    {"hover", 99.5, 99.9},
    {"hover-daylight", 97.5, 98.8},
    {"hover-daylight-alternate", 99.0, 99.3},
    {"static-rig", 98.0, 99.0},
    {"caustics", 99.0, 99.4},
    {"marine-snow", 99.5, 99.5},
    {"turbid-1", 99.5, 99.9},
    {"turbid-2", 99.3, 99.5},
    {"turbid-3", 98.3, 99.0},
    {"checkerboard", 97.3, 99.2},
    {"red-colour", 99.5, 99.5},
    {"red-bayer", 99.3, 99.5},
    {"beside", 99.5, 99.9},
    {"oblique", 99.5, 99.9},
    {"fan", 99.5, 99.9},
    {"fan-daylight", 99.5, 99.5},
    {"thin-sheet", 98.0, 99.5},
    {"bloom", 99.0, 99.5},
    // Below the aim of 97 % and 99 %: a line at a third of the daylight among fine sunlit growth
    // is not a ridge wherever the growth's own ridges cross it, and caustics five times the
    // ambient light cross it at every few columns and are chosen where they run along it. There
    // the validation also rejects stretches of line whose segments joined caustics or growth
    // (backprojection 4 points of recall below background, and under caustics, where the line
    // selection then takes caustics instead, 0.8 of precision).
    {"pier-sunlit", 89.5, 95.0, 4.5, 0.2},
    {"caustics-noon", 87.5, 90.0, 4.5, 1.0},
};

TEST(Scenarios, DefaultDetectorReachesItsFloorInEveryScene) {
  for (const Floor& f : kBackground) {
    const Score& s = score(f.scenario, "background");
    EXPECT_GE(100 * s.recall(), f.recall) << f.scenario;
    EXPECT_GE(100 * s.precision(), f.precision) << f.scenario;
  }
  EXPECT_LE(score("clean", "background").rms(), 0.05);  // sub-pixel on the clean scene
}

TEST(Scenarios, BackprojectionKeepsThePrecisionOfBackgroundOrBetter) {
  for (const Floor& f : kBackground) {
    const Score& b = score(f.scenario, "background");
    const Score& v = score(f.scenario, "backprojection");
    EXPECT_GE(v.precision(), b.precision() - f.backprojection_precision_loss / 100) << f.scenario;
    // It never rejects a point only because the scene gave it nothing to validate with: in
    // turbid water (and everywhere) it keeps recall within 2 points of background.
    EXPECT_GE(v.recall(), b.recall() - f.backprojection_recall_loss / 100) << f.scenario;
  }
  EXPECT_GE(score("pier", "backprojection").precision(), 0.99);
}

// A sheet whose projection is half a pixel wide: the line in the image is as wide as the pixels
// and the lens make it, and filters sized for the sheet alone (line_blur_px 0) lose a fifth of it.
TEST(Scenarios, ASheetThinnerThanAPixelIsSearchedAsWideAsTheBlur) {
  for (const Scenario& s : standard_scenarios()) {
    if (s.name != "thin-sheet") continue;
    pipeline::DetectorOptions sheet_only;
    sheet_only.frontend.line_blur_px = 0.0;
    const Score without = evaluate(s, "background", sheet_only, 2.0);
    const Score& with = score("thin-sheet", "background");
    std::printf("thin-sheet background: recall %.2f%% without the blur, %.2f%% with\n",
                100 * without.recall(), 100 * with.recall());
    EXPECT_LT(without.recall(), 0.9);
    EXPECT_GE(with.recall(), without.recall() + 0.1);
  }
}

// A line 6.5 times as wide as the model (a soft lens, a saturated core): an earlier frame is
// subtracted only once the scene moved by the line's own extent (moved by the model's width, the
// earlier line's glow took the near flank off: recall 95.2 %, precision 95.3 %, bias -0.51 px),
// and the band-pass peaks on the flanks of its clipped core, on the run or beside it, are taken
// without a ridge (asked for one, fir lost 2.3 % of the line).
TEST(Scenarios, ALineFarWiderThanTheModelIsNotSubtractedByItsOwnGlow) {
  const Score& b = score("bloom", "background");
  EXPECT_LE(std::abs(b.bias()), 0.05);
  EXPECT_LE(b.rms(), score("bloom", "fir").rms());
  EXPECT_GE(score("bloom", "fir").recall(), 0.995);
}

// Under dense bright texture (fine growth in sunlight, caustics at noon) more ridges than eight
// along a column outshine a faint line: kept by amplitude, the eight strongest left the line out
// of the candidates in a third to half of the columns `fir` missed.
TEST(Scenarios, AFaintLineAmongDenseBrightTextureStaysAmongTheCandidates) {
  for (const Scenario& s : standard_scenarios()) {
    if (s.name != "pier-sunlit" && s.name != "caustics-noon") continue;
    pipeline::DetectorOptions eight;
    eight.frontend.max_candidates_per_column = 8;
    const Score few = evaluate(s, "fir", eight, 2.0);
    const Score& many = score(s.name, "fir");
    std::printf("%s fir: recall %.2f%% with 8 candidates per column, %.2f%% with %d\n",
                s.name.c_str(), 100 * few.recall(), 100 * many.recall(),
                pipeline::FrontendOptions{}.max_candidates_per_column);
    EXPECT_GE(many.recall(), few.recall() + 0.08) << s.name;
    EXPECT_GE(many.precision(), few.precision()) << s.name;
  }
}

// Scored on another draw of the scenario (texture, relief, particles, noise, motion), as
// laserline-evaluate --seed does.
Score score_drawn(const std::string& scenario, const std::string& detector, std::uint64_t seed) {
  for (Scenario s : standard_scenarios()) {
    if (s.name != scenario) continue;
    s.scene.seed += seed;
    return evaluate(s, detector, {}, 2.0);
  }
  ADD_FAILURE() << "no scenario " << scenario;
  return {};
}

// The hard scenes on draws the floors above were not set on. On the pier, backprojection follows
// the line through the previous frames however it was split there (it lost 1.3 to 4.5 points of
// recall against background on these draws when a joined neighbour or a long line spanning many
// pieces crowded out its true match). Holding station in daylight, a still texture edge beside a
// faint stretch of the line does not draw the line selection away (mean precision 96.6 % when
// every still candidate earned the previous frame's bonus and a jump cost at most a restart).
TEST(Scenarios, HardScenesOnOtherDraws) {
  for (const std::uint64_t seed : {1, 2, 3, 4}) {
    const Score b = score_drawn("pier", "background", seed);
    const Score v = score_drawn("pier", "backprojection", seed);
    std::printf("pier seed %llu: recall background %.2f%%, backprojection %.2f%%\n",
                static_cast<unsigned long long>(seed), 100 * b.recall(), 100 * v.recall());
    EXPECT_GE(v.recall(), b.recall() - 0.015) << "pier seed " << seed;
  }
  double precision = 0;
  for (const std::uint64_t seed : {1, 2, 3, 4, 5}) {
    const Score h = score_drawn("hover-daylight", "background", seed);
    std::printf("hover-daylight seed %llu: recall %.2f%% precision %.2f%%\n",
                static_cast<unsigned long long>(seed), 100 * h.recall(), 100 * h.precision());
    precision += h.precision() / 5;
  }
  EXPECT_GE(precision, 0.98);
}

// A fan narrower than the image, moderate light: beyond the line's ends the texture's curves are
// long enough to earn their restarts, and only their faintness against the line tells them apart.
// fir (no background subtraction) keeps them all without the faint-piece rule.
TEST(Scenarios, CurvesBeyondTheLinesEndsAreDroppedForBeingFaint) {
  const Score& kept = score("fan", "fir");
  EXPECT_GE(kept.precision(), 0.99);
  EXPECT_GE(kept.recall(), 0.995);
  Scenario fan;
  for (const Scenario& s : standard_scenarios())
    if (s.name == "fan") fan = s;
  pipeline::DetectorOptions keep_all;
  keep_all.frontend.selection.faint_piece_db = 0.0;
  const Score all = evaluate(fan, "fir", keep_all, 2.0);
  std::printf("fan fir, every piece kept: recall %.2f%% precision %.2f%%\n", 100 * all.recall(),
              100 * all.precision());
  EXPECT_LT(all.precision(), 0.7);
  double precision = 0;
  for (const std::uint64_t seed : {1, 2, 3, 4, 5})
    precision += score_drawn("fan", "fir", seed).precision() / 5;
  EXPECT_GE(precision, 0.9);
}

// At 640x512 the texture's curves beyond the line's ends hop through gaps at the free jump per
// line and reached the line: one piece with it, never compared (fan: fir precision 82.5 %;
// fan-daylight: background 68.1 %). Resuming after a gap farther than the free jump splits them.
TEST(Scenarios, CurvesBeyondTheLinesEndsAreDroppedAtASmallerSize) {
  for (const Scenario& s : standard_scenarios(640, 512)) {
    if (s.name == "fan") {
      const Score fir = evaluate(s, "fir", {}, 2.0);
      std::printf("fan 640x512 fir: recall %.2f%% precision %.2f%%\n", 100 * fir.recall(),
                  100 * fir.precision());
      EXPECT_GE(fir.recall(), 0.995);
      EXPECT_GE(fir.precision(), 0.99);
    } else if (s.name == "fan-daylight") {
      const Score b = evaluate(s, "background", {}, 2.0);
      std::printf("fan-daylight 640x512 background: recall %.2f%% precision %.2f%%\n",
                  100 * b.recall(), 100 * b.precision());
      EXPECT_GE(b.recall(), 0.99);
      EXPECT_GE(b.precision(), 0.9);
    }
  }
}

// `background` is never worse than `fir` (it searches the frame as it is when no earlier frame
// helps), and in turbid water within 3 points of the best detector. Not met on caustics-noon's
// recall: caustics move with the sun, not with the scene, and subtracting an earlier frame takes
// the line away where that frame's caustics crossed it (there `background` has no candidate near
// the line, `fir` has); the threshold's hysteresis gives `fir` more of the line back than
// `background` (caustics-noon, seed 0: 92.5 % against 91.9 %; docs/extraction.md step 6).
TEST(Scenarios, BackgroundIsNeverWorseThanFir) {
  for (const Floor& f : kBackground) {
    const Score& b = score(f.scenario, "background");
    const Score& fir = score(f.scenario, "fir");
    const bool caustics_moving_apart = std::string(f.scenario) == "caustics-noon";
    EXPECT_GE(b.recall(), fir.recall() - (caustics_moving_apart ? 0.01 : 0.005)) << f.scenario;
    EXPECT_GE(b.precision(), fir.precision() - 0.005) << f.scenario;
  }
  for (const char* turbid : {"backscatter", "turbid-1", "turbid-2", "turbid-3"}) {
    double best = 0;
    for (const char* detector : {"maxvalue", "fir", "background", "backprojection"})
      best = std::max(best, score(turbid, detector).recall());
    EXPECT_GE(score(turbid, "background").recall(), best - 0.03) << turbid;
  }
}

// A camera that holds still in light has no earlier frame the scene moved away from: the newest
// one is subtracted less its own line where that takes away most of the texture beside the line;
// in the dark (noise alone, which subtraction only adds to) the frame is searched as it is. On
// draws the default floors were not set on. (On the static rig, objects moving past cost a
// quarter of a point of recall where they enter and leave.)
TEST(Scenarios, AStillCameraSubtractsThePreviousFrameLessItsOwnLine) {
  auto run = [](const std::string& name, std::uint64_t seed, bool remove_own_line,
                int& line_removed) {
    for (Scenario s : standard_scenarios()) {
      if (s.name != name) continue;
      s.scene.seed += seed;
      pipeline::DetectorOptions options;
      options.background.remove_own_line = remove_own_line;
      return evaluate(s, "background", options, 2.0, [&](const ScoredFrame& frame) {
        line_removed += frame.profile->background_line_removed() ? 1 : 0;
      });
    }
    ADD_FAILURE() << "no scenario " << name;
    return Score{};
  };
  for (const char* name : {"hover-daylight", "static-rig"}) {
    double recall_with = 0, recall_without = 0, precision_with = 0, precision_without = 0;
    int removed_with = 0, removed_without = 0, frames = 0;
    for (const std::uint64_t seed : {1, 2, 3, 4, 5}) {
      const Score with = run(name, seed, true, removed_with);
      const Score without = run(name, seed, false, removed_without);
      recall_with += with.recall() / 5;
      recall_without += without.recall() / 5;
      precision_with += with.precision() / 5;
      precision_without += without.precision() / 5;
      frames += with.frames;
    }
    std::printf(
        "%s, mean of 5 draws: recall %.2f%% / %.2f%%, precision %.2f%% / %.2f%% with / "
        "without the previous frame less its line (in %d of %d frames)\n",
        name, 100 * recall_with, 100 * recall_without, 100 * precision_with,
        100 * precision_without, removed_with, frames);
    EXPECT_GE(removed_with, frames * 9 / 10) << name;
    EXPECT_EQ(removed_without, 0) << name;
    EXPECT_GE(precision_with, precision_without - 0.001) << name;
    EXPECT_GE(recall_with, recall_without - 0.005) << name;
    // Texture in daylight as bright as the laser: 98.2 % without, 99.0 % with.
    if (std::string(name) == "hover-daylight") {
      EXPECT_GE(precision_with, precision_without + 0.004);
    }
  }
  int removed_in_the_dark = 0;
  run("dark", 1, true, removed_in_the_dark);
  EXPECT_EQ(removed_in_the_dark, 0);
}

}  // namespace
}  // namespace laserline::tools
