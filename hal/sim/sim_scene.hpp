#pragma once

#include <array>
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

  // Relief on the surface (a pier with piles and overgrowth): smooth round bumps, elongated
  // ridges and flat-topped posts, raised along the surface normal toward the camera, placed from
  // the seed at relief_per_m2 features per square metre of surface, heights uniform in
  // [relief_min_height_m, relief_height_m]. Their flanks are no steeper than relief_max_slope
  // (rise over run): no part of the relief hides another from a ray (camera or laser) while
  // relief_max_slope * tan(ray's angle to the normal) < 1, e.g. up to 42 degrees at slope 0.9.
  // Features are wider the higher and the gentler they are: relief_height_m / relief_max_slope
  // must stay within 0.72 m, so that they fit the relief, which repeats every 5.12 m along the
  // surface. relief_height_m = 0: the plane, exactly.
  double relief_height_m = 0.0;
  double relief_min_height_m = 0.05;
  double relief_per_m2 = 1.0;
  double relief_max_slope = 0.7;
  // The vehicle moving along the surface: the camera (with its laser) translates at this speed
  // along the surface's x axis (the world x axis turned by the tilts), on top of sway and scan.
  double vehicle_speed_m_s = 0.0;
};

// The true pose of the camera for one frame, world -> camera: X_camera = rotation X_world +
// translation (rotation row-major). The world frame is the camera frame of frame 0 at rest (x
// right, y down, z along the optical axis); the surface's base plane goes through (0, 0,
// distance_m) of the world.
struct SimCameraPose {
  std::array<double, 9> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::array<double, 3> translation{};
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

  // The true camera pose of frame `sequence` (sway, scan and vehicle motion).
  SimCameraPose camera_pose(std::uint64_t sequence) const;

  // The surface the renderer draws, in surface coordinates: (x_m, y_m) metres along the base
  // plane's axes from its point (0, 0, distance_m), the x axis being the world x axis turned by
  // tilt_y_deg then tilt_x_deg. relief_height() is the height toward the camera there (0 without
  // relief); surface_point() is the point of the relieved surface in the world frame.
  double relief_height(double x_m, double y_m) const;
  std::array<double, 3> surface_point(double x_m, double y_m) const;

 private:
  struct Pose;
  Pose pose_at(std::uint64_t sequence) const;

  SimSceneOptions options_;
  std::vector<float> texture_;  // tile of surface albedo noise, texture_size_ x texture_size_
  int texture_size_ = 0;
  std::vector<std::int8_t> noise_;      // table of Gaussian sensor noise samples (scaled)
  std::vector<float> row_buffer_;       // scratch for one image row
  SimGroundTruth scratch_truth_;        // per-column truth of the frame being rendered
  std::vector<float> line_gain_;        // per-column peak grey level of the line
  std::vector<float> relief_;           // wrapping tile of relief heights (m), empty without relief
  std::vector<float> line_s_, line_t_;  // per column: texel coordinates of the lit point
};

}  // namespace laserline::hal
