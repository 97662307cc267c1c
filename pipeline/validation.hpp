#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "pipeline/geometry.hpp"
#include "pipeline/image_view.hpp"
#include "pipeline/motion.hpp"
#include "pipeline/profile.hpp"

namespace laserline::pipeline {

// How a segment of frame n is associated with the segments of frames n-1 and n-2 (paper IV-C, and
// the alternative its conclusion proposes).
enum class SegmentAssociation {
  // Paper IV-C: chain codes of segments whose bounding boxes are close are cross-correlated; the
  // peak gives the column offset between them (the point association).
  chain_code,
  // Paper VI: the segment's bounding box in the ORIGINAL image is tracked into the previous frame
  // (the texture under it, which is static scene); the segment found where the box went is its
  // predecessor, the tracked shift the point association.
  image_features,
};

// Paper Section IV-B to IV-D.
struct ValidationOptions {
  SegmentAssociation association = SegmentAssociation::chain_code;
  // IV-B: candidates at most this far apart (pixels) are neighbours in one segment; segments with
  // fewer candidates are noise (the paper's 5 and 5).
  double max_neighbour_gap_px = 5.0;
  int min_segment_points = 5;
  // IV-C: segments are compared when their bounding boxes are at most this far apart (pixels),
  // shifted along the line by at most max_column_offset columns, overlapping by a quarter of the
  // shorter one (and min_segment_points - 1 steps) at least; a match needs min_correlation there.
  double max_box_distance_px = 32.0;
  int max_column_offset = 24;
  double min_correlation = 0.6;
  // image_features: the box is tracked within this many pixels of where the frame-to-frame
  // homography puts it, over a patch of at most patch_columns x patch_rows pixels around its
  // centre.
  int feature_search_px = 6;
  int patch_columns = 48;
  int patch_rows = 24;
  // IV-D: a segment whose candidates, triangulated from frames n-2 and n-1 and back-projected into
  // frame n, land within this distance (pixels, median over its points) of where it was tracked to
  // is static scene: background.
  double background_px = 2.0;
  // A point triangulated farther than this many camera baselines (|t| of frames n-2 -> n-1) has no
  // measurable parallax: that is what a laser line, which moves with the camera, looks like under
  // translation. Such points are not static scene. 1000 baselines: 1.4 px of parallax at f = 1400.
  double max_depth_baselines = 1000.0;
  // chain_code: segments not tracked over the three frames are rejected too (else they keep the
  // front-end's verdict): texture artefacts of the background subtraction come and go, the laser
  // line lasts. (image_features follows the texture, not the laser: untracked segments are kept.)
  bool require_track = true;
  // chain_code, with require_track: a tracked segment that moves more than this per frame across
  // the line (rows, median over its points) is not the laser line, which moves with the camera: its
  // image moves across the line only as the depth along the sheet changes. 0: no such test.
  double max_laser_motion_px = 4.0;

  // Throws OptionError (pipeline/options.hpp) naming the first field outside what the pipeline
  // supports.
  void validate() const;
};

// The camera motion between two consecutive frames, as the validation needs it:
// X_current = R * X_previous + t in camera coordinates, |t| = 1 (direction only), and the length
// of t relative to the previous frame pair's (NaN when unknown).
struct PairMotion {
  bool valid = false;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double relative_scale = std::numeric_limits<double>::quiet_NaN();
};

// An association of a segment with one of the previous frame (IV-C).
struct SegmentMatch {
  int previous = -1;        // index of the segment in the previous frame
  float column_offset = 0;  // its column = this column - column_offset
  float row_offset = 0;     // image_features: the texture's row shift (its row = row - offset)
  float score = 0;          // support, higher is better: correlation times columns (chain_code),
                            // share of the points that agree (image_features)
};

// One laser-line segment of a frame (IV-B): candidates linked along the line, one per column.
struct LineSegment {
  static constexpr int kMaxMatches = 8;
  int first = 0, count = 0;  // its points: SegmentedFrame::points[first, first + count)
  int u_min = 0, u_max = 0;  // bounding box
  float v_min = 0, v_max = 0;
  int code_first = 0;  // rows (u_max - u_min + 1 values) and chain code (one fewer)
  // The best associations with segments of the previous frame, best first (a segment split
  // differently in the two frames has several: a long stretch of the line may span four or five
  // pieces of it there, besides texture that fits somewhere along it).
  std::array<SegmentMatch, kMaxMatches> matches{};
  int match_count = 0;
  bool background = false;  // IV-D verdict
  bool tested = false;      // tracked over three frames and triangulable
  float residual_px = std::numeric_limits<float>::quiet_NaN();      // median back-projection error
  float image_motion_px = std::numeric_limits<float>::quiet_NaN();  // median motion per frame
};

struct SegmentPoint {
  int u = 0;
  float v = 0;
  int profile_index = 0;  // index of the candidate in the profile it came from
};

// The segments of one frame. Capacity fixed by reset(); filling it does not allocate.
struct SegmentedFrame {
  std::vector<SegmentPoint> points;   // grouped by segment, each by increasing column
  std::vector<LineSegment> segments;  // by first column (u_min), as segment_candidates() makes
  // Per segment, from code_first: its row at every column of its box (linear between candidates)
  // and its chain code, the row step from each column to the next.
  std::vector<float> rows;
  std::vector<float> chain_code;

  void reset(std::size_t max_points, double max_gap_px);
  void clear();
  // Row of segment s at column u (within its box).
  float row_at(const LineSegment& s, int u) const {
    return rows[static_cast<std::size_t>(s.code_first + (u - s.u_min))];
  }
};

// Working memory of segment_candidates(), sized for a number of candidates.
struct SegmentationScratch {
  std::vector<int> order, next;                // per candidate
  std::vector<int> head, tail, count, active;  // per segment being built
  std::vector<int> active_u;                   // per active segment: where it ends
  std::vector<float> active_v;
  void reset(std::size_t max_points);
};

// IV-B: links the candidates of `profile` into segments (gap at most max_neighbour_gap_px, at
// least min_segment_points; one candidate per column, the nearest) with their chain codes.
// Candidates beyond the capacity given to out.reset() are left out.
void segment_candidates(const Profile& profile, const ValidationOptions& options,
                        SegmentedFrame& out, SegmentationScratch& scratch);

// Keeps `m` among the best kMaxMatches of `s` (one per previous segment), best first.
void add_match(LineSegment& s, const SegmentMatch& m);

// IV-C: the best matches of segment `s` of `current` among the segments of `previous` by
// cross-correlation of chain codes (s.matches).
void match_by_chain_code(const SegmentedFrame& previous, const SegmentedFrame& current,
                         LineSegment& s, const ValidationOptions& options);

// IV-D for one point: triangulates x0 (frame n-2) and x1 (frame n-1), raw pixels (the lens
// distortion of `camera` is removed from their rays and applied to x2), with `first`
// (n-2 -> n-1; midpoint of the two rays) and back-projects it into frame n with `second` (n-1 -> n,
// its translation scaled by its relative_scale) as x2. `ray_gap_px` is how far the triangulated
// point projects from x0 and x1 (the larger): rays that do not meet. False when the point cannot
// be static scene: behind a camera, or beyond max_depth_baselines (no parallax).
bool back_project(const ScannerGeometry& camera, const PairMotion& first, const PairMotion& second,
                  const std::array<double, 2>& x0, const std::array<double, 2>& x1,
                  double max_depth_baselines, std::array<double, 2>& x2, double& ray_gap_px);

// Paper IV-B to IV-D over a stream of frames: segments the candidates of frame n, associates them
// with those of n-1 (which were associated with n-2), triangulates each segment tracked over the
// three frames, back-projects it into frame n and marks the points of segments consistent with the
// static scene as not valid (background). Points of short segments (noise) are not valid either,
// nor (chain_code with require_track) those of segments not tracked over the frames seen so far or
// moving across the line more than the laser can. The others keep their validity (eligible for
// the line selection that follows in BackprojectionDetector). Without a camera motion (and relative
// scale) segments keep the front-end's verdict. Every candidate gets its segment id (-1: none), its
// index in segments() of that frame. The verdict for frame n is given when frame n is processed,
// from n-2, n-1 and n: a fixed latency of zero frames, with two frames of history. reset()
// allocates; validate() does not. Thread context: one thread at a time per instance.
class LineValidator {
 public:
  LineValidator(const ScannerGeometry& geometry, const ValidationOptions& options);

  const ValidationOptions& options() const { return options_; }
  // max_points: most candidates a frame can have.
  void reset(int width, int height, std::size_t max_points);
  // `motion`: camera motion from the previous frame to this one; `homography` (row-major,
  // p_current ~ H p_previous, or nullptr) and `image` (the original frame) are used by the
  // image_features association only. A frame without motion breaks the tracks.
  void validate(Profile& profile, const PairMotion& motion, const ImageView& image,
                const Homography* homography);

  // The segments of the last frame validated, for overlays and tests.
  const SegmentedFrame& segments() const { return frames_[current_]; }
  // Those of the frame before (age 1) and the one before it (age 2).
  const SegmentedFrame& earlier_segments(int age) const {
    return frames_[static_cast<std::size_t>((current_ + 3 - age % 3) % 3)];
  }

 private:
  void associate_by_image_features(const SegmentedFrame& previous, SegmentedFrame& current,
                                   const ImageView& image, const Homography& homography);
  // Tracks the box of `s` (frame n) into the previous image; false when it does not converge.
  bool track_box(const LineSegment& s, const ImageView& image, const Homography& h, float& du,
                 float& dv) const;
  void test_segments(SegmentedFrame& current, const SegmentedFrame& previous,
                     const SegmentedFrame& before, const PairMotion& first,
                     const PairMotion& second);

  // Whether the association follows the laser line as well as the texture: chain codes do (the
  // line keeps its place and shape), image_features does not (it follows the texture, which the
  // laser does not), so there untracked segments keep their verdict.
  bool laser_tracks() const {
    return options_.require_track && options_.association == SegmentAssociation::chain_code;
  }

  ScannerGeometry geometry_;
  ValidationOptions options_;
  std::array<SegmentedFrame, 3> frames_;
  std::array<PairMotion, 3> motions_;  // motion into each frame from the one before
  int current_ = 0;
  int history_ = 0;  // consecutive frames with motion, up to 3
  SegmentationScratch scratch_;
  std::vector<float> residuals_;        // per point of a segment: back-projection error
  std::vector<float> image_motion_;     // and its image motion over the three frames
  std::vector<std::uint8_t> eligible_;  // per candidate, as it came in
  // image_features: the previous original frame.
  std::vector<std::uint8_t> previous_image_;
  int width_ = 0, height_ = 0;
  bool have_previous_image_ = false;
};

}  // namespace laserline::pipeline
