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

  // A new sequence (reset) or, with `next_frame`, the frame after the one selected before.
  std::vector<float> select(LineSelector& selector, bool next_frame = false) {
    if (!next_frame) selector.reset(kLines, kPerLine);
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
// before it, scanning the previous frame's candidates for each, then the faint pieces dropped.
// LineSelector::select() must choose exactly as this does, ties included.
class ReferenceSelector {
 public:
  ReferenceSelector(const LineSelectionOptions& options, int lines, int per_line)
      : o_(options),
        lines_(lines),
        k_(per_line),
        score_(static_cast<std::size_t>(lines * per_line)),
        unary_(static_cast<std::size_t>(lines * per_line)),
        from_(static_cast<std::size_t>(lines * per_line)),
        starts_piece_(static_cast<std::size_t>(lines * per_line)),
        column_best_(static_cast<std::size_t>(lines)),
        previous_(static_cast<std::size_t>(lines * per_line)),
        previous_count_(static_cast<std::size_t>(lines), 0),
        previous_chosen_(static_cast<std::size_t>(lines), std::numeric_limits<float>::quiet_NaN()) {
  }

  void select(std::span<const LineCandidate> candidates, std::span<const std::uint8_t> counts,
              float threshold_db, std::span<int> chosen) {
    const int k = k_;
    const auto restart = static_cast<float>(o_.restart_cost_db);
    const auto cap = static_cast<float>(o_.amplitude_cap_db);
    const auto free = static_cast<float>(o_.jump_free_px);
    const auto jump_cost = static_cast<float>(o_.jump_cost_db_per_px);
    const auto gap_cost = static_cast<float>(o_.gap_cost_db);
    const auto bonus = static_cast<float>(o_.previous_bonus_db);
    const auto other_bonus = static_cast<float>(o_.previous_other_bonus_db);
    const auto tolerance = static_cast<float>(o_.previous_tolerance_px);
    const auto jump_cap = static_cast<float>(o_.jump_cost_cap_db);
    std::fill(chosen.begin(), chosen.end(), -1);
    auto at = [](int i) { return static_cast<std::size_t>(i); };
    // No bonus where this frame's lines' brightest candidates are (median) faint_piece_db above
    // the previous frame's choice (median): it had no line to choose.
    std::vector<float> brightest, chosen_db;
    for (int line = 0; line < lines_; ++line) {
      float most = -std::numeric_limits<float>::infinity();
      for (int i = 0; i < counts[at(line)]; ++i)
        most = std::max(most, candidates[at(line * k + i)].amplitude_db);
      if (counts[at(line)] > 0) brightest.push_back(most);
    }
    auto median = [](std::vector<float> v) {
      if (v.empty()) return std::numeric_limits<float>::quiet_NaN();
      std::sort(v.begin(), v.end());
      return v[v.size() / 2];
    };
    const bool use_previous = !(o_.faint_piece_db > 0 && median(brightest) - previous_chosen_db_ >
                                                             static_cast<float>(o_.faint_piece_db));
    float running_best = 0.0f;
    int running_at = -1;
    ends_.clear();
    for (int line = 0; line < lines_; ++line) {
      const int n = counts[at(line)];
      for (int i = 0; i < n; ++i) {
        const LineCandidate& c = candidates[at(line * k + i)];
        float unary = std::min(c.amplitude_db - threshold_db, cap);
        if (!use_previous) {
          // no bonus this frame
        } else if (std::abs(c.position - previous_chosen_[at(line)]) <= tolerance) {
          unary += bonus;
        } else {
          for (int j = 0; j < previous_count_[at(line)]; ++j) {
            if (std::abs(c.position - previous_[at(line * k + j)]) <= tolerance) {
              unary += other_bonus;
              break;
            }
          }
        }
        // A new piece: after the best of the path ends kept (or none), paying its capped jump.
        float best = -restart;
        int from = -1;
        bool starts_piece = true;
        for (const End& end : ends_) {
          const float lines_between = static_cast<float>(line - end.at / k);
          const float jump = std::abs(c.position - end.position);
          const float total =
              end.score - restart -
              std::min(jump_cap, jump_cost * std::max(0.0f, jump - free * lines_between));
          if (total > best) {
            best = total;
            from = end.at;
          }
        }
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
            starts_piece = false;
            for (int j = 0; j < counts[at(before)]; ++j) {
              if (value(j) == best_here) {
                from = before * k + j;
                break;
              }
            }
          }
        }
        score_[at(line * k + i)] = unary + best;
        unary_[at(line * k + i)] = unary;
        from_[at(line * k + i)] = from;
        starts_piece_[at(line * k + i)] = starts_piece;
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
      // The line's candidates as path ends: kept unless an end kept outdoes them for every later
      // candidate; they drop the ends they outdo, and those too far below the best path's.
      for (int i = 0; i < n; ++i) {
        const End end{score_[at(line * k + i)], candidates[at(line * k + i)].position,
                      line * k + i};
        if (!(end.score > 0.0f) || end.score <= running_best - jump_cap) continue;
        bool outdone = false;
        for (const End& other : ends_) {
          if (other.score - end.score >=
              std::min(jump_cap, jump_cost * std::abs(end.position - other.position))) {
            outdone = true;
            break;
          }
        }
        if (outdone) continue;
        std::erase_if(ends_, [&](const End& other) {
          const float apart = std::abs(end.position - other.position);
          const float more_free = free * static_cast<float>(end.at / k - other.at / k);
          return end.score - other.score >= std::min(jump_cap, jump_cost * (apart + more_free)) ||
                 other.score <= running_best - jump_cap;
        });
        if (ends_.size() < kEnds) {
          ends_.push_back(end);
        } else {
          auto lowest =
              std::min_element(ends_.begin(), ends_.end(),
                               [](const End& a, const End& b) { return a.score < b.score; });
          if (lowest->score < end.score) *lowest = end;
        }
      }
    }
    for (int i = running_at; i >= 0; i = from_[at(i)])
      chosen[at(i / k)] = i % k;
    // The pieces of the path (first line, end line, evidence, mean amplitude), then those too
    // faint against the one with the most evidence dropped.
    struct Piece {
      int first, end;
      float evidence, amplitude_sum;
      int count;
    };
    std::vector<Piece> pieces;
    int last_line = 0;
    for (int line = 0; line < lines_; ++line) {
      const int c = chosen[at(line)];
      if (c < 0) continue;
      const float position = candidates[at(line * k + c)].position;
      const float last_position =
          pieces.empty() ? 0.0f : candidates[at(last_line * k + chosen[at(last_line)])].position;
      const bool jumped =
          !pieces.empty() && jump_cost * (std::abs(position - last_position) -
                                          free * static_cast<float>(line - last_line)) >=
                                 0.5f * restart;
      last_line = line;
      if (starts_piece_[at(line * k + c)] || jumped) {
        if (!pieces.empty()) pieces.back().end = line;
        pieces.push_back({line, lines_, 0.0f, 0.0f, 0});
      }
      const float above = candidates[at(line * k + c)].amplitude_db - threshold_db;
      pieces.back().evidence += unary_[at(line * k + c)] + std::max(0.0f, above - cap);
      pieces.back().amplitude_sum += candidates[at(line * k + c)].amplitude_db;
      ++pieces.back().count;
    }
    if (o_.faint_piece_db > 0 && !pieces.empty()) {
      const Piece* strongest = &pieces.front();
      for (const Piece& piece : pieces)
        if (piece.evidence > strongest->evidence) strongest = &piece;
      const float reference_db = strongest->amplitude_sum / static_cast<float>(strongest->count);
      for (const Piece& piece : pieces) {
        if (piece.amplitude_sum / static_cast<float>(piece.count) <
            reference_db - static_cast<float>(o_.faint_piece_db)) {
          for (int line = piece.first; line < piece.end; ++line)
            chosen[at(line)] = -1;
        }
      }
    }
    for (int line = 0; line < lines_; ++line)
      if (chosen[at(line)] >= 0)
        chosen_db.push_back(candidates[at(line * k + chosen[at(line)])].amplitude_db);
    previous_chosen_db_ = median(chosen_db);
    for (int line = 0; line < lines_; ++line) {
      const int c = chosen[at(line)];
      previous_chosen_[at(line)] =
          c >= 0 ? candidates[at(line * k + c)].position : std::numeric_limits<float>::quiet_NaN();
      previous_count_[at(line)] = counts[at(line)];
      for (int i = 0; i < counts[at(line)]; ++i)
        previous_[at(line * k + i)] = candidates[at(line * k + i)].position;
    }
  }

 private:
  LineSelectionOptions o_;
  int lines_, k_;
  std::vector<float> score_, unary_;
  std::vector<int> from_;
  std::vector<bool> starts_piece_;
  std::vector<float> column_best_;
  std::vector<float> previous_;
  std::vector<std::uint8_t> previous_count_;
  std::vector<float> previous_chosen_;
  float previous_chosen_db_ = std::numeric_limits<float>::quiet_NaN();
  struct End {
    float score, position;
    int at;
  };
  static constexpr std::size_t kEnds = 16;
  std::vector<End> ends_;
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

// The camera holds still: the line is too faint to be a candidate over lines 20..39 (it crosses
// bright patches), and a texture edge 300 px away runs there, as still as the line, frame after
// frame. The edge earns more than a restart, but not its jump going to it and coming back, and
// only the line's own history earns the full bonus: the path skips from one part of the line to
// the other.
TEST(LineSelection, AStillTextureEdgeBesideAFaintStretchOfTheLineIsNotChosen) {
  Lines lines;
  lines.piece(0, 19, 100.0f, 10.0f);
  lines.piece(20, 39, 400.0f, 10.0f);
  lines.piece(40, kLines - 1, 101.0f, 10.0f);
  LineSelector selector;
  for (int frame = 0; frame < 3; ++frame) {
    const std::vector<float> chosen = lines.select(selector, frame > 0);
    for (int line = 0; line < kLines; ++line) {
      EXPECT_EQ(chosen[line], line < 20   ? 100.0f
                              : line < 40 ? -1.0f
                                          : 101.0f)
          << "frame " << frame << " line " << line;
    }
  }

  // Jumps that cost at most one more restart, and every still candidate's bonus in full: from the
  // second frame on the edge earns as much as the line, and is taken.
  LineSelectionOptions cheap_jumps;
  cheap_jumps.jump_cost_cap_db = cheap_jumps.restart_cost_db;
  cheap_jumps.previous_other_bonus_db = cheap_jumps.previous_bonus_db;
  LineSelector drawn_away(cheap_jumps);
  for (int frame = 0; frame < 3; ++frame) {
    const std::vector<float> chosen = lines.select(drawn_away, frame > 0);
    if (frame > 0) {
      EXPECT_EQ(chosen[30], 400.0f) << "frame " << frame;
    }
  }
}

// The line's first frame after a frame without it (the laser off, or the line out of view) on a
// still scene: the texture chosen there stays where it was, but this frame's candidates are far
// brighter than what the previous frame chose, so the previous frame earns no bonus (which, with
// the line's amplitude counted only up to the cap, would let the texture outweigh the line).
TEST(LineSelection, TheLineAfterAFrameWithoutItIsChosenOverTheStillTexture) {
  Lines texture;  // a 5 dB texture curve over every line
  texture.piece(0, 29, 150.0f, 5.0f);
  texture.piece(30, kLines - 1, 151.0f, 5.0f);
  Lines with_line = texture;
  with_line.piece(0, kLines - 1, 100.0f, 30.0f);  // the line, 25 dB above the texture
  LineSelector selector;
  EXPECT_EQ(texture.select(selector)[0], 150.0f);
  const std::vector<float> chosen = with_line.select(selector, true);
  for (int line = 0; line < kLines; ++line)
    EXPECT_EQ(chosen[line], 100.0f) << "line " << line;

  // As bright as the line, the texture keeps the bonus: the previous frame's choice stays.
  Lines as_bright = texture;
  as_bright.piece(0, kLines - 1, 100.0f, 10.0f);
  LineSelector other;
  texture.select(other);
  EXPECT_EQ(as_bright.select(other, true)[0], 150.0f);
}

// A depth jump: the line goes on 300 px away. A side of the jump is kept when its points earn
// their restart and the jump (at most jump_cost_cap_db, 150): in the first frame 25 lines at the
// amplitude cap (6) do not, and the path keeps the longer side alone; from the next frame on, the
// laser stays where it was and the candidates there earn the previous frame's bonus (3 where not
// chosen) as well: 25 lines then do, 15 lines never.
TEST(LineSelection, APieceBeyondADepthJumpIsKeptWhenItEarnsTheJump) {
  for (const int first_beyond : {35, 45}) {
    Lines lines;
    lines.piece(0, first_beyond - 1, 100.0f, 10.0f);
    lines.piece(first_beyond, kLines - 1, 400.0f, 10.0f);
    LineSelector selector;
    for (int frame = 0; frame < 3; ++frame) {
      const std::vector<float> chosen = lines.select(selector, frame > 0);
      const bool kept = frame > 0 && first_beyond == 35;
      for (int line = 0; line < kLines; ++line) {
        EXPECT_EQ(chosen[line], line < first_beyond ? 100.0f
                                : kept              ? 400.0f
                                                    : -1.0f)
            << "from line " << first_beyond << ", frame " << frame << ", line " << line;
      }
    }
  }
}

// A laser fan narrower than the image: the line lies on lines 20..39 only. Beyond its ends texture
// forms curves 30 px from it, long enough to earn their restarts and jumps (20 points at the
// amplitude cap), 18 dB fainter than the line: they are dropped. A piece of the line itself beyond
// a depth jump, on a darker surface (8 dB fainter), is kept.
TEST(LineSelection, CurvesFarFainterThanTheLineBeyondItsEndsAreDropped) {
  Lines lines;
  lines.piece(0, 19, 130.0f, 12.0f);
  lines.piece(20, 39, 100.0f, 30.0f);
  lines.piece(40, kLines - 1, 70.0f, 12.0f);
  LineSelector selector;
  const std::vector<float> chosen = lines.select(selector);
  for (int line = 0; line < kLines; ++line)
    EXPECT_EQ(chosen[line], line >= 20 && line < 40 ? 100.0f : -1.0f) << line;

  LineSelectionOptions keep_all;
  keep_all.faint_piece_db = 0.0;
  LineSelector keeping(keep_all);
  const std::vector<float> kept = lines.select(keeping);
  EXPECT_EQ(kept[5], 130.0f);
  EXPECT_EQ(kept[30], 100.0f);
  EXPECT_EQ(kept[50], 70.0f);

  Lines depth_jump;
  depth_jump.piece(0, 29, 100.0f, 30.0f);
  depth_jump.piece(30, kLines - 1, 150.0f, 22.0f);
  const std::vector<float> both = depth_jump.select(selector);
  EXPECT_EQ(both[10], 100.0f);
  EXPECT_EQ(both[50], 150.0f);
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
  cases[1].faint_piece_db = 0.0;
  cases[2].faint_piece_db = 3.0;
  cases[2].max_gap = 0;
  cases[2].restart_cost_db = 4.0;
  cases[2].jump_cost_cap_db = 4.0;
  cases[2].previous_other_bonus_db = 0.0;
  cases[3].max_gap = 20;
  cases[3].jump_cost_db_per_px = 0.25;
  cases[3].previous_tolerance_px = 0.0;
  cases[3].previous_other_bonus_db = 6.0;
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
