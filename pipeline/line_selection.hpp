#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace laserline::pipeline {

// How the one point of each epipolar line is chosen among its candidates (paper II: one true match
// per epipolar line). Every candidate passed the SNR threshold (paper III-E); among them the laser
// is the one that adds the most light within its width (band-pass amplitude, not SNR: an edge on
// a flat surface has a high SNR from little light), it forms one curve across the lines,
// continuous except where the depth jumps, and it stays where it was in the previous frame while
// texture moves with the scene. So the choice maximises, over all ways of picking at most one
// candidate per line,
//   sum of (amplitude in dB - threshold, at most amplitude_cap_db, + previous_bonus_db where the
//           previous frame chose a point within previous_tolerance_px on that line, else
//           previous_other_bonus_db where it had another candidate there)
//   - (jump beyond jump_free_px per line step) * jump_cost_db_per_px - skipped lines * gap_cost_db
//   - restart_cost_db for every new piece of curve, plus the jump cost from where the path it
//     continues ended (at most jump_cost_cap_db more; or none, a path of its own),
// by dynamic programming along the lines (as industrial profile sensors trace their line). A piece
// of curve apart from the rest is kept only when its points earn its restarts and jumps. Then a
// piece whose points are on average faint_piece_db fainter than those of the piece with the most
// evidence (the largest sum of amplitudes above the threshold, uncapped, and bonuses) is dropped:
// beyond the ends of the line (a fan narrower than the image, an object on a turntable) texture
// and noise still form curves, much fainter than the laser where the line is exposed for.
struct LineSelectionOptions {
  bool enabled = true;  // false: the strongest candidate of each line
  // The laser line is one curve; a new piece (after a jump of the depth, or elsewhere) must earn
  // this much (about eight points' worth at amplitude_cap_db) to be kept: isolated texture and
  // glints rarely do.
  double restart_cost_db = 50.0;
  // A candidate's amplitude counts up to this far above the threshold: beyond it the candidate is
  // surely light, and whether it is the laser's is for the curve's continuity to say. (A texture
  // ridge in daylight can be brighter than the laser where it crosses a bright, nearly clipped
  // patch: counted in full, a piece of it outweighs the line's continuity.)
  double amplitude_cap_db = 6.0;
  double jump_free_px = 2.0;
  double jump_cost_db_per_px = 2.0;
  // What a new piece's jump from where the line was last seen costs at most (three restarts: with
  // its own restart, 34 lines at the amplitude cap). A piece of texture between two parts of the
  // line pays it twice, going and coming back, so a long texture edge beside a stretch where the
  // line is faint does not draw the path away; a depth jump that holds to the end of the image pays
  // it once.
  double jump_cost_cap_db = 150.0;
  double gap_cost_db = 1.0;
  int max_gap = 8;  // lines a piece of curve can skip (a dark patch, an occlusion)
  // The previous frame's chosen point earns the bonus in full; its other candidates a half: when
  // the camera holds still, texture stays as well, and only the line's own history tells them
  // apart (a new piece of line, not chosen before, still gains from staying). No bonus where the
  // frame's candidates are (median of each line's brightest) faint_piece_db brighter than the
  // previous frame's choice (median): that frame had no line to choose.
  double previous_bonus_db = 6.0;
  double previous_other_bonus_db = 3.0;
  double previous_tolerance_px = 2.5;
  // How much fainter (mean amplitude, dB) than the piece with the most evidence a piece may be
  // and be kept; 0: every piece kept. The line's own brightness varies with the surface's albedo
  // along it (a factor 2 either way on textured walls); 12 dB is a factor 4.
  double faint_piece_db = 12.0;

  // Throws OptionError (pipeline/options.hpp) naming the first field outside what the pipeline
  // supports.
  void validate() const;
};

// A candidate of one epipolar line: its position along the line (original pixels), SNR and
// amplitude (20 log10 of the band-pass, grey levels).
struct LineCandidate {
  float position = 0;
  float snr_db = 0;
  float amplitude_db = 0;
};

// The dynamic programming of LineSelectionOptions. reset() allocates; select() does not.
// Thread context: one thread at a time per instance.
class LineSelector {
 public:
  explicit LineSelector(const LineSelectionOptions& options = {});

  const LineSelectionOptions& options() const { return options_; }
  // `lines` epipolar lines of at most `per_line` candidates each; forgets the previous frame.
  void reset(int lines, int per_line);
  // candidates[line * per_line + i] for i < counts[line], each line's sorted by position; writes
  // chosen[line] = the index of its chosen candidate, or -1. threshold_db: the SNR a candidate
  // needed (its amplitude is at least that, in grey levels: the noise is at least 1). Remembers
  // the candidates and the choice as the previous frame's.
  void select(std::span<const LineCandidate> candidates, std::span<const std::uint8_t> counts,
              float threshold_db, std::span<int> chosen);
  // Forgets the previous frame (e.g. after a frame without points of its own).
  void forget();

 private:
  // The end of a path (its total, its last candidate's position and index) from which a new piece
  // may start: the ends no other end outdoes for every later candidate, at most kPathEnds.
  struct PathEnd {
    float score;
    float position;
    std::int32_t at;
  };
  static constexpr std::size_t kPathEnds = 16;
  // Offers `end` (above 0 and within jump_cost_cap_db of running_best) to ends_[0, end_count).
  void add_path_end(const PathEnd& end, float running_best, int& end_count);
  // Drops from `chosen` the pieces faint_piece_db fainter than the one with the most evidence.
  void drop_faint_pieces(std::span<const LineCandidate> candidates, float threshold_db,
                         std::span<int> chosen) const;

  LineSelectionOptions options_;
  int lines_ = 0, per_line_ = 0;
  std::array<PathEnd, kPathEnds> ends_{};
  std::vector<float> score_;                // per candidate: the best total of a path ending there
  std::vector<float> position_;             // per candidate: its position (contiguous per line)
  std::vector<std::int32_t> from_;          // per candidate: its predecessor on that path, -1 none
  std::vector<float> column_best_;          // per line: the best total of a path ending on it
  std::vector<float> unary_;                // per candidate: its amplitude's part, bonus included
  std::vector<std::uint8_t> starts_piece_;  // per candidate: its best path starts a piece there
  std::vector<float> previous_;             // per line: the previous frame's candidates' positions
  std::vector<std::uint8_t> previous_count_;
  std::vector<float> previous_chosen_;  // per line: the previous frame's choice, NaN none
  float previous_chosen_db_ = 0;        // the median amplitude of its points, NaN none
  std::vector<float> line_brightest_;   // scratch: a value per line
  // The median over the lines with candidates of their brightest candidate's amplitude; the
  // median of the first `count` values of line_brightest_ (NaN for none; reorders them).
  float median_brightest(std::span<const LineCandidate> candidates,
                         std::span<const std::uint8_t> counts);
  float median_of(int count);
  // The line in hand, per candidate (in whole groups of lanes): its position, its best total
  // before its own amplitude, from where, its amplitude's part.
  std::vector<float> line_position_, line_best_, line_unary_, line_start_;
  std::vector<std::int32_t> line_from_;
};

}  // namespace laserline::pipeline
