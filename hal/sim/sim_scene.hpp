#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "hal/calibration.hpp"
#include "hal/frame.hpp"

namespace laserline::hal {

// Everything that defines a simulated scan. Same options + same seed => same frames, bit for bit.
struct SimSceneOptions {
  Calibration calibration;  // the true geometry of the simulated scanner (distortion must be zero)
  std::uint64_t seed = 1;
  double frame_rate_hz = 30.0;  // scene time of frame n is n / frame_rate_hz

  // The surface: a plane facing the camera at distance_m along the optical axis at t = 0,
  // its normal tilted by tilt_x_deg about the camera x axis and tilt_y_deg about the y axis.
  double distance_m = 1.2;
  double tilt_x_deg = 0.0;
  double tilt_y_deg = 0.0;
  // Texture painted on the surface (it moves with the surface, not with the camera).
  double texture_scale_m = 0.01;  // size of the finest texture features on the surface
  double texture_contrast = 0.5;  // albedo = 1 + contrast * noise, noise in [-1, 1], floored at 0
  // A calibration target painted over the texture (none while columns or rows is 0): a
  // checkerboard of (columns + 1) x (rows + 1) squares (columns x rows inner corners, OpenCV's
  // pattern size) along the surface's x and y axes, centred on the surface point at distance_m
  // plus the offset (to within half a texel), inside a white margin one square wide. Its squares
  // have sharp edges only when square_m is a whole number of texels (texture_scale_m / 4);
  // required.
  struct Checkerboard {
    int columns = 0;
    int rows = 0;
    double square_m = 0.03;
    double dark_albedo = 0.1;  // the black squares; white squares and margin have albedo 1
    // The board's centre on the surface, along its x and y axes from the surface point at
    // distance_m (rounded to whole texels): a board near the image's edges and corners.
    double offset_x_m = 0.0;
    double offset_y_m = 0.0;
  } checkerboard;

  // Light, in grey levels of the 8-bit image.
  double ambient = 40.0;  // ambient light on a surface of albedo 1
  double laser_peak =
      180.0;                 // peak of the laser line on a surface of albedo 1 (before attenuation)
  double blur_px = 0.7;      // optical blur (Gaussian sigma) added to the projected sheet width
  double noise_sigma = 2.0;  // additive Gaussian sensor noise
  double backscatter = 0.0;  // glow of the sheet in the water just in front of the surface
  double attenuation_per_m = 0.0;  // water attenuation of the laser along its path

  // Sway of the free-floating camera: sinusoidal translation and rotation.
  double sway_m = 0.02;
  double sway_deg = 0.5;
  double sway_period_s = 4.0;
  // A pan-tilt unit scanning: the camera (with its laser) tilts about its x axis back and forth
  // between -scan_amplitude_deg and +scan_amplitude_deg at scan_rate_deg_s, starting at 0 going
  // up. The scene then moves across the laser line, as the paper's background subtraction needs.
  double scan_rate_deg_s = 0.0;
  double scan_amplitude_deg = 10.0;
};

// The exact answer for one frame.
struct SimGroundTruth {
  std::vector<float> row;       // per column: sub-pixel row of the laser centre, NaN where none
  std::vector<float> depth_m;   // per column: Z of the lit surface point, NaN where none
  std::vector<float> width_px;  // per column: Gaussian sigma of the rendered line profile
};

// Renders the simulated scanner's frames. Construction allocates (texture, noise table, scratch);
// render() and ground_truth() do not. Thread context: one thread at a time per instance.
class SimScene {
 public:
  explicit SimScene(const SimSceneOptions& options);

  const SimSceneOptions& options() const { return options_; }
  FrameFormat format() const;

  // Writes frame `sequence` as mono8 into dst (format().bytes() bytes).
  void render(std::uint64_t sequence, bool laser_on, std::span<std::uint8_t> dst);

  // The exact laser centre per column for frame `sequence`. `truth` vectors are resized to the
  // image width (allocation only the first time).
  void ground_truth(std::uint64_t sequence, bool laser_on, SimGroundTruth& truth) const;

 private:
  struct Pose;
  Pose pose_at(std::uint64_t sequence) const;

  SimSceneOptions options_;
  std::vector<float> texture_;  // tile of surface albedo noise, texture_size_ x texture_size_
  int texture_size_ = 0;
  std::vector<std::int8_t> noise_;  // table of Gaussian sensor noise samples (scaled)
  std::vector<float> row_buffer_;   // scratch for one image row
  SimGroundTruth scratch_truth_;    // per-column truth of the frame being rendered
  std::vector<float> line_gain_;    // per-column peak grey level of the line
};

}  // namespace laserline::hal
