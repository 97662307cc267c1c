// The line selection's dynamic programming (pipeline/line_selection.hpp) on hand-made candidates:
// one point per epipolar line, the strongest continuous curve, pieces that must earn their restart.
#include "pipeline/line_selection.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <span>
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

// The selection as first written: every candidate against every candidate of the max_gap lines
// before it, scanning the previous frame's candidates for each. LineSelector::select() must choose
// exactly as this does, ties included.
class ReferenceSelector {
 public:
  ReferenceSelector(const LineSelectionOptions& options, int lines, int per_line)
      : o_(options),
        lines_(lines),
        k_(per_line),
        score_(static_cast<std::size_t>(lines * per_line)),
        from_(static_cast<std::size_t>(lines * per_line)),
        column_best_(static_cast<std::size_t>(lines)),
        previous_(static_cast<std::size_t>(lines * per_line)),
        previous_count_(static_cast<std::size_t>(lines), 0) {}

  void select(std::span<const LineCandidate> candidates, std::span<const std::uint8_t> counts,
              float threshold_db, std::span<int> chosen) {
    const int k = k_;
    const auto restart = static_cast<float>(o_.restart_cost_db);
    const auto cap = static_cast<float>(o_.amplitude_cap_db);
    const auto free = static_cast<float>(o_.jump_free_px);
    const auto jump_cost = static_cast<float>(o_.jump_cost_db_per_px);
    const auto gap_cost = static_cast<float>(o_.gap_cost_db);
    const auto bonus = static_cast<float>(o_.previous_bonus_db);
    const auto tolerance = static_cast<float>(o_.previous_tolerance_px);
    std::fill(chosen.begin(), chosen.end(), -1);
    auto at = [](int i) { return static_cast<std::size_t>(i); };
    float running_best = 0.0f;
    int running_at = -1;
    for (int line = 0; line < lines_; ++line) {
      const int n = counts[at(line)];
      for (int i = 0; i < n; ++i) {
        const LineCandidate& c = candidates[at(line * k + i)];
        float unary = std::min(c.amplitude_db - threshold_db, cap);
        for (int j = 0; j < previous_count_[at(line)]; ++j) {
          if (std::abs(c.position - previous_[at(line * k + j)]) <= tolerance) {
            unary += bonus;
            break;
          }
        }
        float best = running_best - restart;
        if (running_at >= 0) {
          const float lines_between = static_cast<float>(line - running_at / k);
          const float jump = std::abs(c.position - candidates[at(running_at)].position);
          best -= std::min(restart, jump_cost * std::max(0.0f, jump - free * lines_between));
        }
        int from = running_at;
        for (int gap = 0; gap <= o_.max_gap && line - 1 - gap >= 0; ++gap) {
          const int before = line - 1 - gap;
          const float skipped = gap_cost * static_cast<float>(gap);
          if (column_best_[at(before)] - skipped <= best) continue;
          const float allowed = free * static_cast<float>(gap + 1);
          auto value = [&](int j) {
            const float jump = std::abs(c.position - candidates[at(before * k + j)].position);
            return score_[at(before * k + j)] - jump_cost * std::max(0.0f, jump - allowed);
          };
          // The best prior's total, then the first prior that has it.
          float best_here = -std::numeric_limits<float>::infinity();
          for (int j = 0; j < counts[at(before)]; ++j)
            best_here = std::max(best_here, value(j));
          if (best_here - skipped > best) {
            best = best_here - skipped;
            for (int j = 0; j < counts[at(before)]; ++j) {
              if (value(j) == best_here) {
                from = before * k + j;
                break;
              }
            }
          }
        }
        score_[at(line * k + i)] = unary + best;
        from_[at(line * k + i)] = from;
      }
      column_best_[at(line)] = -std::numeric_limits<float>::infinity();
      for (int i = 0; i < n; ++i) {
        const float score = score_[at(line * k + i)];
        column_best_[at(line)] = std::max(column_best_[at(line)], score);
        if (score > running_best) {
          running_best = score;
          running_at = line * k + i;
        }
      }
    }
    for (int i = running_at; i >= 0; i = from_[at(i)])
      chosen[at(i / k)] = i % k;
    for (int line = 0; line < lines_; ++line) {
      previous_count_[at(line)] = counts[at(line)];
      for (int i = 0; i < counts[at(line)]; ++i)
        previous_[at(line * k + i)] = candidates[at(line * k + i)].position;
    }
  }

 private:
  LineSelectionOptions o_;
  int lines_, k_;
  std::vector<float> score_;
  std::vector<int> from_;
  std::vector<float> column_best_;
  std::vector<float> previous_;
  std::vector<std::uint8_t> previous_count_;
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

// Frames of random candidates (a line wandering among texture, many lines full) on positions and
// amplitudes of a coarse grid, so that totals tie often, and options that make them tie more: the
// selector chooses what the reference does in every frame.
TEST(LineSelection, ChoosesAsTheReferenceDoesTiesIncluded) {
  constexpr int kManyLines = 700, kFull = 8, kFrames = 6;
  std::mt19937 random(18);
  std::vector<LineSelectionOptions> cases(4);
  cases[1].gap_cost_db = 0.0;
  cases[1].jump_free_px = 0.0;
  cases[2].max_gap = 0;
  cases[2].restart_cost_db = 4.0;
  cases[3].max_gap = 20;
  cases[3].jump_cost_db_per_px = 0.25;
  cases[3].previous_tolerance_px = 0.0;
  for (std::size_t o = 0; o < cases.size(); ++o) {
    for (const int per_line : {1, 3, kFull}) {
      LineSelector selector(cases[o]);
      selector.reset(kManyLines, per_line);
      ReferenceSelector reference(cases[o], kManyLines, per_line);
      std::vector<LineCandidate> candidates(static_cast<std::size_t>(kManyLines * per_line));
      std::vector<std::uint8_t> counts(kManyLines);
      std::vector<int> chosen(kManyLines), expected(kManyLines);
      float line_at = 100.0f;
      for (int frame = 0; frame < kFrames; ++frame) {
        for (int line = 0; line < kManyLines; ++line) {
          line_at =
              std::clamp(line_at + 0.25f * static_cast<float>(random() % 9) - 1.0f, 0.0f, 200.0f);
          std::vector<float> positions;
          if (random() % 4 != 0) positions.push_back(line_at);
          const int texture = static_cast<int>(random() % (per_line + 2));
          for (int t = 0; t < texture; ++t)
            positions.push_back(0.5f * static_cast<float>(random() % 400));
          std::sort(positions.begin(), positions.end());
          const auto n = std::min<std::size_t>(positions.size(), per_line);
          counts[static_cast<std::size_t>(line)] = static_cast<std::uint8_t>(n);
          for (std::size_t i = 0; i < n; ++i) {
            const float amplitude = 3.0f + 0.5f * static_cast<float>(random() % 20);
            candidates[static_cast<std::size_t>(line * per_line) + i] = {positions[i], amplitude,
                                                                         amplitude};
          }
        }
        selector.select(candidates, counts, 3.0f, chosen);
        reference.select(candidates, counts, 3.0f, expected);
        ASSERT_EQ(chosen, expected)
            << "options " << o << ", " << per_line << " per line, frame " << frame;
      }
    }
  }
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
