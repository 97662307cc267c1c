#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "pipeline/geometry.hpp"
#include "pipeline/image_view.hpp"
#include "pipeline/line_selection.hpp"
#include "pipeline/motion.hpp"
#include "pipeline/parts.hpp"
#include "pipeline/profile.hpp"
#include "pipeline/validation.hpp"

namespace laserline::pipeline {

// The paper's Section III front-end (stages III-B to III-E), shared by `fir` and `background`.
struct FrontendOptions {
  // Depth range the laser is searched in: rows where the sheet would lie outside it are never
  // looked at (the laser cannot physically appear there). Paper V-A: 0.5 - 2.5 m working area.
  double min_depth_m = 0.5;
  double max_depth_m = 2.5;
  double normalised_width_px = 3.0;  // laser width after width normalisation (III-B)
  // The width of the image of a sheet far thinner than a pixel: the line is taken as
  // sqrt(l(v)^2 + line_blur_px^2) wide, l(v) the sheet's projected width. A sheet a millimetre or
  // two thick is under a pixel wide at a few metres, and filters sized for that answer the line
  // weakly. 0.7: the pixel's own width (a one-pixel box spreads light as a Gaussian of 0.68 px full
  // width at half maximum does), the part of the blur every camera has; the lens adds its own.
  // 0: the projected width alone (paper III-B).
  double line_blur_px = 0.7;
  // Band-pass (III-C): inner box = normalised width, outer box = passband_ratio times it. A wider
  // passband tolerates backscatter and non-Lambertian surfaces at some loss of SNR.
  double passband_ratio = 3.0;
  // SNR (III-D): noise = mean |band-pass| over this window (normalised rows x columns).
  int noise_rows = 31;
  int noise_columns = 9;
  // Where the mean |band-pass| of the window's rows on one side of the pixel is this many times
  // that on the other, the noise is the quieter side's (a smallest-of CFAR at a clutter edge): an
  // edge beside the line (a checkerboard's square, the rim of a bright patch) is no noise on the
  // line, and counted it hid a line on a dark square next to a white one. Texture and noise rarely
  // differ so much between the sides. 0: always the whole window (paper III-D).
  double noise_side_ratio = 8.0;
  double snr_threshold_db = 6.0;  // III-E: paper 3 - 6 dB
  // Hysteresis in time: within selection.previous_tolerance_px of where the previous frame found
  // the line, a candidate needs this much less SNR. The line stays where it was while clutter
  // beside it (a caustic, a texture ridge moving past) fills its noise window and pulls its SNR
  // under the threshold for a few frames; elsewhere the threshold keeps noise out. 0: none.
  double snr_hysteresis_db = 6.0;
  int max_candidates_per_column = 16;
  // A run at or above this is a clipped core: its centre is the peak. Below 255: a camera's
  // processing (white balance after the sensor clipped, lossy compression) leaves clipped pixels a
  // few levels under it, and a single such pixel would break the run.
  int saturation_level = 250;
  // Which candidate of each epipolar line is the laser point (the others stay, not valid).
  LineSelectionOptions selection;

  // Throws OptionError (pipeline/options.hpp) naming the first field outside what the pipeline
  // supports.
  void validate() const;
};

// Which earlier frame `background` subtracts (paper III-A). The previous frame only removes the
// texture when the scene moved across the laser line between the two frames by more than the
// line is wide; else the previous frame's line lies on this one's and takes it away.
struct BackgroundOptions {
  // Frames kept as candidate backgrounds (the newest first): the most recent one exposed with the
  // laser off; else the most recent one the scene moved far enough from (its motion chained
  // frame to frame); else (remove_own_line) the most recent one with its own line taken out;
  // else none, and the frame is searched as it is (as `fir`).
  int history_frames = 8;
  // How far the scene must have moved across the line, in laser line widths (the width the
  // calibration gives where the line is).
  double min_motion_widths = 1.0;
  // A camera holding still (hovering, a fixed rig, a turntable) or just setting off: the newest
  // frame is subtracted all the same, its own line taken out where it found it, and nothing
  // subtracted where it did not. (Not where the water glows in front of the line.)
  bool remove_own_line = true;

  // Throws OptionError (pipeline/options.hpp) naming the first field outside what the pipeline
  // supports.
  void validate() const;
};

// Where a detector looks for the laser: a rectangle of the frame's pixels, (x, y) its top left
// pixel, width x height pixels. Points and candidates outside it are not produced: its epipolar
// lines alone are searched, and along them only its stretch; the filters still read the pixels
// around it (band-pass, noise window, background warp), so that inside it a detector finds what
// it finds on the whole frame. All four 0 (the default): the whole frame.
struct DetectionRegion {
  int x = 0;
  int y = 0;
  int width = 0;
  int height = 0;

  bool whole() const { return x == 0 && y == 0 && width == 0 && height == 0; }
  // The region in a frame of this size: the whole frame for whole(), else its part inside the
  // frame (empty, width or height 0, where none is).
  DetectionRegion in_frame(int frame_width, int frame_height) const;
  // Whether the pixel nearest (px, py) lies inside (a region resolved by in_frame()).
  bool contains(double px, double py) const;
  // Throws OptionError (pipeline/options.hpp) with field "roi" unless the region is whole() or
  // non-empty and inside a frame of this size.
  void validate(int frame_width, int frame_height) const;
  // "x,y,width,height", the form commands and the configuration give.
  std::string text() const;
  bool operator==(const DetectionRegion&) const = default;
};

// Options of every detector, filled from the configuration. Each detector reads its own part.
struct DetectorOptions {
  // maxvalue: a column's maximum is a laser point when it is at least this bright (grey level).
  int maxvalue_threshold = 40;
  ScannerGeometry geometry;
  FrontendOptions frontend;
  BackgroundOptions background;
  MotionOptions motion;
  ValidationOptions validation;  // `backprojection` (Section IV)
  // Where the laser is searched, in the frame's pixels (checked against the geometry's frame by
  // make_detector()).
  DetectionRegion roi;

  // Every part above but the geometry and the roi: throws OptionError naming the first field
  // outside what
  // the pipeline supports.
  void validate() const;
};

// What the pipeline may know about a frame besides its pixels.
struct FrameContext {
  std::uint64_t sequence = 0;
  bool laser_on = true;  // the laser state the frame was exposed with
};

// Finds laser points in one frame, along each epipolar line; a frame exposed with the laser off
// gives none (it may serve a later frame as background). A detector itself looks along image
// columns; make_detector() runs it on the frame's search image (pipeline/search_axes.hpp) when the
// calibration puts the epipolar lines along rows or at an angle, and the profile says how its
// points map to the frame. reset() sizes every buffer for a frame size (allocates); detect() then
// does not allocate and its work is bounded by the image size. Detectors that use earlier frames
// keep what they need themselves: the image passed to detect() is not valid after it returns.
// Thread context: one thread at a time per instance.
class Detector {
 public:
  virtual ~Detector() = default;
  virtual const char* name() const = 0;
  // Most points one frame can produce (capacity the caller gives the output Profile).
  virtual std::size_t max_points(int width, int height) const = 0;
  virtual void reset(int width, int height) = 0;
  // Splits each frame's work into runner.parts() parts (pipeline/parts.hpp), the same profile to
  // the bit for any number; before reset(), which sizes each part's buffers. The runner must
  // outlive the detector's use of it. Default: one part.
  virtual void use_parts(PartRunner& runner) { (void)runner; }
  virtual void detect(const ImageView& image, const FrameContext& frame, Profile& out) = 0;
  // Searches only `region` from the next detect() on, in the coordinates of the image detect() is
  // given (make_detector()'s detectors: the frame's pixels); it must be whole() or inside the
  // frame (DetectionRegion::validate()). Does not allocate: may change between any two frames.
  virtual void set_region(const DetectionRegion& region) = 0;
  // The region searched, resolved to the frame (DetectionRegion::in_frame()) of the last reset(),
  // before the first one to the geometry's.
  virtual DetectionRegion region() const = 0;
};

std::vector<std::string> detector_names();
// nullptr for an unknown name. The detector searches along the epipolar lines options.geometry
// gives (columns, rows or at an angle: choose_search_axes()); every detector's valid points come
// out triangulated (xyz in metres in the camera frame; NaN where not on the laser sheet). Throws
// std::invalid_argument when the options cannot work (e.g. a laser plane through the camera
// centre, a roi beyond the geometry's frame), naming the option. It searches options.roi.
std::unique_ptr<Detector> make_detector(const std::string& name, const DetectorOptions& options);

}  // namespace laserline::pipeline
