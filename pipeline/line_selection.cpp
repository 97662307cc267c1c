#include "pipeline/line_selection.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace laserline::pipeline {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

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
  prefix_best_.assign(static_cast<std::size_t>(lines), 0.0f);
  column_best_.assign(static_cast<std::size_t>(lines), 0.0f);
  prefix_at_.assign(static_cast<std::size_t>(lines), -1);
  previous_.assign(candidates, kNaN);
  previous_count_.assign(static_cast<std::size_t>(lines), 0);
  has_previous_ = false;
}

void LineSelector::forget() {
  std::fill(previous_count_.begin(), previous_count_.end(), 0);
  has_previous_ = false;
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
  const auto tolerance = static_cast<float>(o.previous_tolerance_px);
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

  float running_best = 0.0f;  // the best total of any path so far (the empty path: 0)
  std::int32_t running_at = -1;
  for (int line = 0; line < lines_; ++line) {
    prefix_best_[static_cast<std::size_t>(line)] = running_best;
    prefix_at_[static_cast<std::size_t>(line)] = running_at;
    const int n = counts[static_cast<std::size_t>(line)];
    for (int i = 0; i < n; ++i) {
      position_[static_cast<std::size_t>(line * k + i)] =
          candidates[static_cast<std::size_t>(line * k + i)].position;
    }
    const float* previous = previous_.data() + static_cast<std::ptrdiff_t>(line) * k;
    const int previous_count = previous_count_[static_cast<std::size_t>(line)];
    for (int i = 0; i < n; ++i) {
      const std::int32_t at = line * k + i;
      const LineCandidate& c = candidates[static_cast<std::size_t>(at)];
      float unary = std::min(c.amplitude_db - threshold_db, cap);
      bool persistent = false;
      for (int j = 0; j < previous_count; ++j) {
        if (std::abs(c.position - previous[j]) <= tolerance) {
          persistent = true;
          break;
        }
      }
      if (persistent) unary += bonus;
      // A new piece of curve after the best path so far, or the continuation of a piece that
      // ended at most max_gap lines before. A new piece far from where that path ended pays the
      // jump cost too, up to a second restart: glints and texture edges start anywhere, the
      // laser resumes near where it was seen (beyond an occlusion, or after a depth jump).
      float best = running_best - restart;
      if (running_at >= 0) {
        const float lines_between = static_cast<float>(line - running_at / k);
        const float jump =
            std::abs(c.position - candidates[static_cast<std::size_t>(running_at)].position);
        best -= std::min(restart, jump_cost * std::max(0.0f, jump - free * lines_between));
      }
      std::int32_t from = running_at;
      for (int gap = 0; gap <= o.max_gap && line - 1 - gap >= 0; ++gap) {
        const int before = line - 1 - gap;
        const float skipped = gap_cost * static_cast<float>(gap);
        // (No candidate of that line can do better: the jump costs nothing at best.)
        if (column_best_[static_cast<std::size_t>(before)] - skipped <= best) continue;
        const int m = counts[static_cast<std::size_t>(before)];
        const float allowed = free * static_cast<float>(gap + 1);
        const float* prior_score = score_.data() + static_cast<std::ptrdiff_t>(before) * k;
        const float* prior_position = position_.data() + static_cast<std::ptrdiff_t>(before) * k;
        // The best prior first (a branch-free reduction), its index only when it improves.
        float best_here = -std::numeric_limits<float>::infinity();
        for (int j = 0; j < m; ++j) {
          const float jump = std::abs(c.position - prior_position[j]);
          best_here =
              std::max(best_here, prior_score[j] - jump_cost * std::max(0.0f, jump - allowed));
        }
        if (best_here - skipped > best) {
          best = best_here - skipped;
          for (int j = 0; j < m; ++j) {
            const float jump = std::abs(c.position - prior_position[j]);
            if (prior_score[j] - jump_cost * std::max(0.0f, jump - allowed) == best_here) {
              from = before * k + j;
              break;
            }
          }
        }
      }
      score_[static_cast<std::size_t>(at)] = unary + best;
      from_[static_cast<std::size_t>(at)] = from;
    }
    float column_best = -std::numeric_limits<float>::infinity();
    for (int i = 0; i < n; ++i) {
      const std::int32_t at = line * k + i;
      column_best = std::max(column_best, score_[static_cast<std::size_t>(at)]);
      if (score_[static_cast<std::size_t>(at)] > running_best) {
        running_best = score_[static_cast<std::size_t>(at)];
        running_at = at;
      }
    }
    column_best_[static_cast<std::size_t>(line)] = column_best;
  }
  // The best path, back from its end.
  for (std::int32_t at = running_at; at >= 0; at = from_[static_cast<std::size_t>(at)])
    chosen[static_cast<std::size_t>(at / k)] = at % k;
  has_previous_ = true;
  // Every candidate of this frame: the laser stays where it was, texture moves with the scene.
  for (int line = 0; line < lines_; ++line) {
    const int n = counts[static_cast<std::size_t>(line)];
    previous_count_[static_cast<std::size_t>(line)] = static_cast<std::uint8_t>(n);
    for (int i = 0; i < n; ++i) {
      previous_[static_cast<std::size_t>(line * k + i)] =
          candidates[static_cast<std::size_t>(line * k + i)].position;
    }
  }
}

}  // namespace laserline::pipeline
