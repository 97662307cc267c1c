#include "pipeline/line_selection.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "pipeline/kernels/kernels.hpp"

namespace laserline::pipeline {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// The scratch of the line in hand holds whole vectors of candidates (kernels::best_priors()).
std::size_t whole_lanes(int candidates) {
  constexpr int lanes = kernels::kSelectionLanes;
  return static_cast<std::size_t>((candidates + lanes - 1) / lanes * lanes);
}

}  // namespace

LineSelector::LineSelector(const LineSelectionOptions& options) : options_(options) {
  options.validate();
}

void LineSelector::reset(int lines, int per_line) {
  lines_ = lines;
  per_line_ = per_line;
  const auto candidates = static_cast<std::size_t>(lines) * static_cast<std::size_t>(per_line);
  score_.assign(candidates, 0.0f);
  position_.assign(candidates, 0.0f);
  from_.assign(candidates, -1);
  column_best_.assign(static_cast<std::size_t>(lines), 0.0f);
  unary_.assign(candidates, 0.0f);
  starts_piece_.assign(candidates, 0);
  previous_.assign(candidates, kNaN);
  previous_count_.assign(static_cast<std::size_t>(lines), 0);
  previous_chosen_.assign(static_cast<std::size_t>(lines), kNaN);
  previous_chosen_db_ = kNaN;
  line_brightest_.assign(static_cast<std::size_t>(lines), 0.0f);
  const std::size_t lanes = whole_lanes(per_line);
  line_position_.assign(lanes, 0.0f);
  line_best_.assign(lanes, 0.0f);
  line_from_.assign(lanes, -1);
  line_unary_.assign(lanes, 0.0f);
  line_start_.assign(lanes, 0.0f);
}

void LineSelector::forget() {
  std::fill(previous_count_.begin(), previous_count_.end(), 0);
  std::fill(previous_chosen_.begin(), previous_chosen_.end(), kNaN);
  previous_chosen_db_ = kNaN;
}

float LineSelector::median_of(int count) {
  if (count == 0) return kNaN;
  const auto first = line_brightest_.begin();
  const auto middle = first + count / 2;
  std::nth_element(first, middle, first + count);
  return *middle;
}

float LineSelector::median_brightest(std::span<const LineCandidate> candidates,
                                     std::span<const std::uint8_t> counts) {
  int count = 0;
  for (int line = 0; line < lines_; ++line) {
    const int n = counts[static_cast<std::size_t>(line)];
    if (n == 0) continue;
    const LineCandidate* c = candidates.data() + static_cast<std::ptrdiff_t>(line) * per_line_;
    float brightest = c[0].amplitude_db;
    for (int i = 1; i < n; ++i)
      brightest = std::max(brightest, c[i].amplitude_db);
    line_brightest_[static_cast<std::size_t>(count++)] = brightest;
  }
  return median_of(count);
}

void LineSelector::add_path_end(const PathEnd& end, float running_best, int& end_count) {
  const auto jump_cap = static_cast<float>(options_.jump_cost_cap_db);
  const auto jump_cost = static_cast<float>(options_.jump_cost_db_per_px);
  const auto free = static_cast<float>(options_.jump_free_px);
  // An earlier end e, which allows more free jump, is at least as good a start as this one for
  // every later candidate when it is above it by what the jump between them can cost; this one
  // is for e when it is above by that plus the free jump e has more (or by jump_cap).
  const int k = per_line_;
  int kept = 0;
  for (int e = 0; e < end_count; ++e) {
    const PathEnd& other = ends_[static_cast<std::size_t>(e)];
    const float apart = std::abs(end.position - other.position);
    if (other.score - end.score >= std::min(jump_cap, jump_cost * apart)) return;
    const float more_free = free * static_cast<float>(end.at / k - other.at / k);
    const bool dominated =
        end.score - other.score >= std::min(jump_cap, jump_cost * (apart + more_free));
    const bool useless = other.score <= running_best - jump_cap;
    if (!dominated && !useless) ends_[static_cast<std::size_t>(kept++)] = other;
  }
  end_count = kept;
  if (end_count < static_cast<int>(ends_.size())) {
    ends_[static_cast<std::size_t>(end_count++)] = end;
    return;
  }
  // Full (rare: ends far apart and close in score): the lowest goes.
  auto lowest =
      std::min_element(ends_.begin(), ends_.end(),
                       [](const PathEnd& a, const PathEnd& b) { return a.score < b.score; });
  if (lowest->score < end.score) *lowest = end;
}

void LineSelector::drop_faint_pieces(std::span<const LineCandidate> candidates, float threshold_db,
                                     std::span<int> chosen) const {
  // Two walks over the chosen points, line by line: the pieces' evidence and mean amplitude,
  // then the drop. A piece runs from a point that starts one, that a jump costing half a restart
  // or more reaches (a continuation across a depth jump, or onto texture beside the line's end),
  // or that resumes after skipped lines more than the free jump away (the line resumes beyond a
  // dark patch where it was; texture beyond its ends hops through gaps), to the point before the
  // next.
  const int k = per_line_;
  const auto cap = static_cast<float>(options_.amplitude_cap_db);
  const auto free = static_cast<float>(options_.jump_free_px);
  const auto jump_cost = static_cast<float>(options_.jump_cost_db_per_px);
  const auto restart = static_cast<float>(options_.restart_cost_db);
  float reference_db = 0.0f, most_evidence = -std::numeric_limits<float>::infinity();
  auto pieces = [&](auto&& on_piece) {
    int first = -1, count = 0, last_line = 0;
    float evidence = 0.0f, amplitude = 0.0f, last_position = 0.0f;
    for (int line = 0; line <= lines_; ++line) {
      const int c = line < lines_ ? chosen[static_cast<std::size_t>(line)] : -1;
      const auto at = static_cast<std::size_t>(line * k + c);
      if (line == lines_ ||
          (c >= 0 && (starts_piece_[at] ||
                      (count > 0 && line - last_line > 1 &&
                       std::abs(candidates[at].position - last_position) > free) ||
                      jump_cost * (std::abs(candidates[at].position - last_position) -
                                   free * static_cast<float>(line - last_line)) >=
                          0.5f * restart))) {
        if (count > 0) on_piece(first, line, evidence, amplitude / static_cast<float>(count));
        first = line;
        count = 0;
        evidence = amplitude = 0.0f;
      }
      if (c < 0) continue;
      last_line = line;
      last_position = candidates[at].position;
      // (The amplitude beyond the cap counts here: the line is the bright curve.)
      const float above = candidates[at].amplitude_db - threshold_db;
      evidence += unary_[at] + std::max(0.0f, above - cap);
      amplitude += candidates[at].amplitude_db;
      ++count;
    }
  };
  pieces([&](int, int, float evidence, float mean_db) {
    if (evidence > most_evidence) {
      most_evidence = evidence;
      reference_db = mean_db;
    }
  });
  const auto faint = static_cast<float>(options_.faint_piece_db);
  pieces([&](int first, int end, float, float mean_db) {
    if (mean_db >= reference_db - faint) return;
    std::fill(chosen.begin() + first, chosen.begin() + end, -1);
  });
}

void LineSelector::select(std::span<const LineCandidate> candidates,
                          std::span<const std::uint8_t> counts, float threshold_db,
                          std::span<int> chosen) {
  const LineSelectionOptions& o = options_;
  const int k = per_line_;
  const auto restart = static_cast<float>(o.restart_cost_db);
  const auto cap = static_cast<float>(o.amplitude_cap_db);
  const auto free = static_cast<float>(o.jump_free_px);
  const auto jump_cost = static_cast<float>(o.jump_cost_db_per_px);
  const auto gap_cost = static_cast<float>(o.gap_cost_db);
  const auto bonus = static_cast<float>(o.previous_bonus_db);
  const auto other_bonus = static_cast<float>(o.previous_other_bonus_db);
  const auto tolerance = static_cast<float>(o.previous_tolerance_px);
  const auto jump_cap = static_cast<float>(o.jump_cost_cap_db);
  std::fill(chosen.begin(), chosen.end(), -1);

  if (!o.enabled) {
    // The strongest candidate of each line.
    for (int line = 0; line < lines_; ++line) {
      const LineCandidate* c = candidates.data() + static_cast<std::ptrdiff_t>(line) * k;
      int best = -1;
      for (int i = 0; i < counts[static_cast<std::size_t>(line)]; ++i)
        if (best < 0 || c[i].snr_db > c[best].snr_db) best = i;
      chosen[static_cast<std::size_t>(line)] = best;
    }
    return;
  }

  // The previous frame's choice earns its bonus only where it may have been the line: where this
  // frame's candidates are far brighter, typically (median over the lines) faint_piece_db above
  // what it chose, the previous frame had no line to choose (the laser off, the line out of
  // view), and the still texture it chose would earn the bonus over the line (whose amplitude
  // counts only up to the cap).
  const float brightest_db = median_brightest(candidates, counts);
  const bool use_previous = !(o.faint_piece_db > 0 && brightest_db - previous_chosen_db_ >
                                                          static_cast<float>(o.faint_piece_db));
  float running_best = 0.0f;  // the best total of any path so far (the empty path: 0)
  std::int32_t running_at = -1;
  int end_count = 0;  // ends_: where a new piece may start from
  float* __restrict best = line_best_.data();
  std::int32_t* __restrict from = line_from_.data();
  float* __restrict unary = line_unary_.data();
  float* __restrict start = line_start_.data();
  for (int line = 0; line < lines_; ++line) {
    const int n = counts[static_cast<std::size_t>(line)];
    float* __restrict position = line_position_.data();
    for (int i = 0; i < n; ++i) {
      position[i] = candidates[static_cast<std::size_t>(line * k + i)].position;
      position_[static_cast<std::size_t>(line * k + i)] = position[i];
    }
    const float* previous = previous_.data() + static_cast<std::ptrdiff_t>(line) * k;
    const int previous_count = previous_count_[static_cast<std::size_t>(line)];
    // Both this line's and the previous frame's candidates are sorted by position: a previous one
    // too far below a candidate is too far below the candidates after it as well.
    int previous_first = 0;
    for (int i = 0; i < n; ++i) {
      const LineCandidate& c = candidates[static_cast<std::size_t>(line * k + i)];
      unary[i] = std::min(c.amplitude_db - threshold_db, cap);
      if (use_previous) {
        while (previous_first < previous_count && previous[previous_first] < c.position &&
               std::abs(c.position - previous[previous_first]) > tolerance) {
          ++previous_first;
        }
        bool persistent = false;
        for (int j = previous_first; j < previous_count; ++j) {
          if (std::abs(c.position - previous[j]) <= tolerance) {
            persistent = true;
            break;
          }
          if (previous[j] > c.position) break;  // and farther above from here on
        }
        if (std::abs(c.position - previous_chosen_[static_cast<std::size_t>(line)]) <= tolerance)
          unary[i] += bonus;
        else if (persistent)
          unary[i] += other_bonus;
      }
      // A new piece of curve, after the best path that ends on an earlier line (or none), or the
      // continuation of a piece that ended at most max_gap lines before. A new piece far from
      // where that path ended pays the jump too, up to jump_cost_cap_db: glints and texture edges
      // start anywhere, the laser resumes near where it was seen (beyond an occlusion, or after
      // a depth jump).
      best[i] = -restart;
      from[i] = -1;
      for (int e = 0; e < end_count; ++e) {
        const PathEnd& end = ends_[static_cast<std::size_t>(e)];
        const float lines_between = static_cast<float>(line - end.at / k);
        const float jump = std::abs(c.position - end.position);
        const float total =
            end.score - restart -
            std::min(jump_cap, jump_cost * std::max(0.0f, jump - free * lines_between));
        if (total > best[i]) {
          best[i] = total;
          from[i] = end.at;
        }
      }
      start[i] = best[i];
    }
    // The candidates of the line all at once against each line before it: a line before can only
    // improve a candidate whose best is below that line's best total less the gap's cost (the jump
    // costs nothing at best).
    const int gaps = std::min(o.max_gap, line - 1);
    if (n > 0 && gaps >= 0) {
      float least = best[0];
      for (int i = 1; i < n; ++i)
        least = std::min(least, best[i]);
      for (int gap = 0; gap <= gaps; ++gap) {
        const int before = line - 1 - gap;
        const float skipped = gap_cost * static_cast<float>(gap);
        if (column_best_[static_cast<std::size_t>(before)] - skipped <= least) continue;
        const kernels::PriorLine prior{position_.data() + static_cast<std::ptrdiff_t>(before) * k,
                                       score_.data() + static_cast<std::ptrdiff_t>(before) * k,
                                       counts[static_cast<std::size_t>(before)],
                                       free * static_cast<float>(gap + 1),
                                       jump_cost,
                                       skipped,
                                       before * k};
        kernels::best_priors(prior, n, best, from, position);
        least = best[0];
        for (int i = 1; i < n; ++i)
          least = std::min(least, best[i]);
      }
    }
    float column_best = -std::numeric_limits<float>::infinity();
    for (int i = 0; i < n; ++i) {
      const std::int32_t at = line * k + i;
      const float score = unary[i] + best[i];
      score_[static_cast<std::size_t>(at)] = score;
      from_[static_cast<std::size_t>(at)] = from[i];
      unary_[static_cast<std::size_t>(at)] = unary[i];
      // (A continuation only ever raises the best: unchanged, it is the new piece's.)
      starts_piece_[static_cast<std::size_t>(at)] = best[i] == start[i] ? 1 : 0;
      column_best = std::max(column_best, score);
      if (score > running_best) {
        running_best = score;
        running_at = at;
      }
    }
    // A new piece pays at most jump_cap to start after an end: an end that many below the best
    // path's (or not above the empty path's 0) never starts one. (Most candidates are.)
    for (int i = 0; i < n; ++i) {
      const float score = score_[static_cast<std::size_t>(line * k + i)];
      if (score > 0.0f && score > running_best - jump_cap)
        add_path_end({score, position[i], line * k + i}, running_best, end_count);
    }
    column_best_[static_cast<std::size_t>(line)] = column_best;
  }
  // The best path, back from its end.
  for (std::int32_t at = running_at; at >= 0; at = from_[static_cast<std::size_t>(at)])
    chosen[static_cast<std::size_t>(at / k)] = at % k;
  if (o.faint_piece_db > 0) drop_faint_pieces(candidates, threshold_db, chosen);
  // This frame's candidates, and its choice: the laser stays where it was, texture moves with
  // the scene (or stays too, when the camera holds still).
  int chosen_count = 0;
  for (int line = 0; line < lines_; ++line) {
    const int c = chosen[static_cast<std::size_t>(line)];
    if (c >= 0) {
      line_brightest_[static_cast<std::size_t>(chosen_count++)] =
          candidates[static_cast<std::size_t>(line * k + c)].amplitude_db;
    }
  }
  previous_chosen_db_ = median_of(chosen_count);
  for (int line = 0; line < lines_; ++line) {
    const int c = chosen[static_cast<std::size_t>(line)];
    previous_chosen_[static_cast<std::size_t>(line)] =
        c >= 0 ? candidates[static_cast<std::size_t>(line * k + c)].position : kNaN;
    const int n = counts[static_cast<std::size_t>(line)];
    previous_count_[static_cast<std::size_t>(line)] = static_cast<std::uint8_t>(n);
    for (int i = 0; i < n; ++i) {
      previous_[static_cast<std::size_t>(line * k + i)] =
          candidates[static_cast<std::size_t>(line * k + i)].position;
    }
  }
}

}  // namespace laserline::pipeline
