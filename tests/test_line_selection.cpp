// The line selection's dynamic programming (pipeline/line_selection.hpp) on hand-made candidates:
// one point per epipolar line, the strongest continuous curve, pieces that must earn their restart.
#include "pipeline/line_selection.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace laserline::pipeline {
namespace {

constexpr int kLines = 60;
constexpr int kPerLine = 4;

// Candidates per line, added piece by piece; select() returns each line's chosen position or -1.
class Lines {
 public:
  Lines() : candidates_(kLines * kPerLine), counts_(kLines, 0) {}

  void piece(int first, int last, float position, float amplitude_db) {
    for (int line = first; line <= last; ++line) {
      auto& n = counts_[static_cast<std::size_t>(line)];
      candidates_[static_cast<std::size_t>(line * kPerLine + n)] = {position, amplitude_db,
                                                                    amplitude_db};
      ++n;
    }
  }

  std::vector<float> select(LineSelector& selector) {
    selector.reset(kLines, kPerLine);
    std::vector<int> chosen(kLines, -1);
    selector.select(candidates_, counts_, 0.0f, chosen);
    std::vector<float> positions(kLines, -1.0f);
    for (int line = 0; line < kLines; ++line) {
      const int i = chosen[static_cast<std::size_t>(line)];
      if (i >= 0)
        positions[static_cast<std::size_t>(line)] =
            candidates_[static_cast<std::size_t>(line * kPerLine + i)].position;
    }
    return positions;
  }

 private:
  std::vector<LineCandidate> candidates_;
  std::vector<std::uint8_t> counts_;
};

TEST(LineSelection, FollowsTheContinuousCurveNotTheStrongestCandidate) {
  Lines lines;
  lines.piece(0, kLines - 1, 100.0f, 10.0f);
  lines.piece(30, 31, 300.0f, 30.0f);  // a glint stronger than the line, on two lines only
  LineSelector selector;
  const std::vector<float> chosen = lines.select(selector);
  for (int line = 0; line < kLines; ++line)
    EXPECT_EQ(chosen[line], 100.0f) << line;
}

// The line hidden over lines 20..31 (longer than max_gap), a texture edge far from it there: the
// edge earns more than one restart (12 points of the 6 dB cap), but a new piece far from where the
// line was seen pays the jump too, so the path waits for the line to come back.
TEST(LineSelection, ANewPieceFarFromTheLineMustEarnMoreThanOneRestart) {
  Lines lines;
  lines.piece(0, 19, 100.0f, 10.0f);
  lines.piece(20, 31, 400.0f, 10.0f);
  lines.piece(32, kLines - 1, 101.0f, 10.0f);
  LineSelector selector;
  const std::vector<float> chosen = lines.select(selector);
  for (int line = 0; line < 20; ++line)
    EXPECT_EQ(chosen[line], 100.0f) << line;
  for (int line = 20; line < 32; ++line)
    EXPECT_EQ(chosen[line], -1.0f) << line;
  for (int line = 32; line < kLines; ++line)
    EXPECT_EQ(chosen[line], 101.0f) << line;
}

// Daylight: a texture ridge 4 px from the line, far brighter than the line (which crosses a bright
// patch there), over lines 20..39. Beyond amplitude_cap_db both are surely light: the path stays
// on the continuous line instead of paying two small jumps for the ridge's brightness.
TEST(LineSelection, ABrightTextureRidgeDoesNotOutweighTheLinesContinuity) {
  Lines lines;
  lines.piece(0, kLines - 1, 100.0f, 8.0f);
  lines.piece(20, 39, 104.0f, 40.0f);
  LineSelector selector;
  const std::vector<float> chosen = lines.select(selector);
  for (int line = 0; line < kLines; ++line)
    EXPECT_EQ(chosen[line], 100.0f) << line;

  // Counted in full, the ridge's brightness wins: the cap is what keeps the line.
  LineSelectionOptions uncapped;
  uncapped.amplitude_cap_db = 1000.0;
  LineSelector counting_in_full(uncapped);
  EXPECT_EQ(lines.select(counting_in_full)[30], 104.0f);
}

// A depth jump: the line goes on 300 px away for 40 lines. That piece earns its restart and its
// jump (at most a second restart), so it is kept.
TEST(LineSelection, ALongPieceAfterADepthJumpIsKept) {
  Lines lines;
  lines.piece(0, 19, 100.0f, 10.0f);
  lines.piece(20, kLines - 1, 400.0f, 10.0f);
  LineSelector selector;
  const std::vector<float> chosen = lines.select(selector);
  for (int line = 0; line < 20; ++line)
    EXPECT_EQ(chosen[line], 100.0f) << line;
  for (int line = 20; line < kLines; ++line)
    EXPECT_EQ(chosen[line], 400.0f) << line;
}

TEST(LineSelection, WithoutSelectionEachLineKeepsItsStrongestCandidate) {
  Lines lines;
  lines.piece(0, kLines - 1, 100.0f, 10.0f);
  lines.piece(30, 31, 300.0f, 30.0f);
  LineSelectionOptions options;
  options.enabled = false;
  LineSelector selector(options);
  const std::vector<float> chosen = lines.select(selector);
  EXPECT_EQ(chosen[29], 100.0f);
  EXPECT_EQ(chosen[30], 300.0f);
  EXPECT_EQ(chosen[31], 300.0f);
}

TEST(LineSelection, NegativeCostsAreRefused) {
  LineSelectionOptions options;
  options.restart_cost_db = -1.0;
  EXPECT_THROW(LineSelector{options}, std::invalid_argument);
  LineSelectionOptions no_cap;
  no_cap.amplitude_cap_db = 0.0;
  EXPECT_THROW(LineSelector{no_cap}, std::invalid_argument);
}

}  // namespace
}  // namespace laserline::pipeline
