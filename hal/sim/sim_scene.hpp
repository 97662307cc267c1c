#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "hal/calibration.hpp"
#include "hal/frame.hpp"
#include "hal/pixel_conversion.hpp"

namespace laserline::hal {

// What the simulated camera delivers: mono frames, or colour ones (interleaved RGB, or a Bayer
// mosaic named by its top-left 2x2 cell) that the camera turns into the laser's channel.
enum class SimColour : std::uint8_t { kMono, kRgb, kBayerRggb, kBayerGrbg, kBayerGbrg, kBayerBggr };

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

  // Colour frames: the camera's red, green and blue response to the laser's light (a 535 nm
  // laser is green; a red one gives about {1, 0.08, 0.03}) and to the ambient light (white: 1, 1,
  // 1), as factors of laser_peak, backscatter and ambient. Mono frames see laser and ambient as
  // they are.
  SimColour colour = SimColour::kMono;
  std::array<double, 3> laser_rgb{0.08, 1.0, 0.12};
  std::array<double, 3> ambient_rgb{1.0, 1.0, 1.0};

  // Light, in grey levels of the 8-bit image.
  double ambient = 40.0;  // ambient light on a surface of albedo 1
  double laser_peak =
      180.0;  // peak of the laser line on a surface of albedo 1 (before attenuation)
  // The laser's fan (full angle within the sheet; 0: wider than the image): the line ends inside
  // the image, and the surface beyond its ends shows only the ambient light. The fan's apex is the
  // sheet's point nearest the camera, its axis the optical axis projected onto the sheet.
  double laser_fan_deg = 0.0;
  double blur_px = 0.7;      // optical blur (Gaussian sigma) added to the projected sheet width
  double noise_sigma = 2.0;  // additive Gaussian sensor noise
  double backscatter = 0.0;  // glow of the sheet in the water just in front of the surface
  double attenuation_per_m = 0.0;  // water attenuation of the laser along its path
  // Turbid water besides: forward scatter spreads this share of the line's light into a halo
  // (a Gaussian as wide as the line and scatter_halo_px added in quadrature, the same energy);
  // veiling light is this share of the ambient light scattered into a uniform glare.
  double forward_scatter = 0.0;
  double scatter_halo_px = 8.0;
  double veiling = 0.0;
  // Sunlight caustics: the ambient light on the surface focused into a network of thin bright
  // curves by the waves, cells of caustic_scale_m, drifting at caustic_speed_m_s over the surface
  // (independently of the surface and the camera). caustic_peak is how bright the curves are
  // against the mean ambient light, which stays the same (1: no caustics); beyond some 30 the
  // curves get thinner and the light between them is 0.
  double caustic_peak = 1.0;
  double caustic_scale_m = 0.15;
  double caustic_speed_m_s = 0.2;
  // Marine snow: particles in the water lit where they cross the laser sheet, in front of the
  // surface: this many per frame (new ones each frame: they drift), Gaussian spots of about
  // snow_size_px (sigma), as bright as snow_brightness times laser_peak at most, at depths from
  // snow_min_depth_m to the surface.
  int snow_per_frame = 0;
  double snow_size_px = 1.2;
  double snow_brightness = 1.0;
  double snow_min_depth_m = 0.3;
  // Bright marks with sharp edges on the surface (paint strokes, shells): this many per square
  // metre, of albedo up to marks_albedo (the texture's mean albedo is 1).
  double marks_per_m2 = 0.0;
  double marks_albedo = 3.0;

  // Sway of the free-floating camera: sinusoidal translation and rotation.
  double sway_m = 0.02;
  double sway_deg = 0.5;
  double sway_period_s = 4.0;
  // A pan-tilt unit scanning: the camera (with its laser) tilts about its x axis back and forth
  // between -scan_amplitude_deg and +scan_amplitude_deg at scan_rate_deg_s, starting at 0 going
  // up. The scene then moves across the laser line, as the paper's background subtraction needs.
  double scan_rate_deg_s = 0.0;
  double scan_amplitude_deg = 10.0;
  // The unit pans (turns about the camera's y axis) instead: the scene then moves across a line
  // that runs down the image (a laser beside the camera).
  bool scan_pan = false;

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
  // Objects moving on a still surface (a rig scanning a moving part): the relief, with the texture
  // on it, slides along the surface's x axis at this speed while the base plane stays.
  double object_speed_m_s = 0.0;
};

// A family of parallel image lines: line k's pixel at `position` along it is
// origin + k * line_step + position * along (line_step and along orthonormal).
struct SimLineFamily {
  std::array<double, 2> origin{0.0, 0.0};
  std::array<double, 2> line_step{1.0, 0.0};
  std::array<double, 2> along{0.0, 1.0};
  int count = 0;

  std::array<double, 2> to_image(double line, double position) const {
    return {origin[0] + line * line_step[0] + position * along[0],
            origin[1] + line * line_step[1] + position * along[1]};
  }
  std::array<double, 2> to_family(double x, double y) const {
    const double dx = x - origin[0], dy = y - origin[1];
    return {dx * line_step[0] + dy * line_step[1], dx * along[0] + dy * along[1]};
  }
  // The columns of a width-pixel image (line k = column k, position = row).
  static SimLineFamily columns(int width);
};

// The epipolar lines of a scanner, along which the simulator draws and measures the line: along
// the gradient of the laser sheet's inverse depth over the image: columns (or rows) when it lies
// within 5 degrees of the image's v (or u) axis, else the rotated family through the image (as
// pipeline::choose_search_axes(), which the detectors use: the same lines).
SimLineFamily epipolar_lines(const Calibration& calibration);

// The true pose of the camera for one frame, world -> camera: X_camera = rotation X_world +
// translation. The world frame is the camera frame of frame 0 at rest (x
// right, y down, z along the optical axis); the surface's base plane goes through (0, 0,
// distance_m) of the world.
struct SimCameraPose {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
};

// The exact answer for one frame, along a family of lines (for the paper's mounting, columns:
// position = the row of the laser centre in each column).
struct SimGroundTruth {
  SimLineFamily lines;
  std::vector<float> position;  // per line: sub-pixel position of the laser centre, NaN where none
  std::vector<float> depth_m;   // per line: Z of the lit surface point, NaN where none
  std::vector<float> width_px;  // per line: Gaussian sigma of the rendered line profile along it
};

// Renders the simulated scanner's frames. Construction allocates (texture, noise table, scratch);
// render() and ground_truth() do not. Thread context: one thread at a time per instance.
class SimScene {
 public:
  explicit SimScene(const SimSceneOptions& options);

  const SimSceneOptions& options() const { return options_; }
  // The frame the camera delivers to the pipeline: mono8.
  FrameFormat format() const;
  // What render() writes: mono8, or the colour frame (3 bytes a pixel, or a Bayer mosaic of one),
  // rows of raw_bytes() / height bytes.
  SourceFormat raw_format() const;
  std::size_t raw_bytes() const;

  // Writes frame `sequence` as raw_format() into dst (raw_bytes() bytes).
  void render(std::uint64_t sequence, bool laser_on, std::span<std::uint8_t> dst);

  // The lines the renderer draws the laser along (epipolar_lines() of the calibration).
  const SimLineFamily& lines() const { return lines_; }

  // The exact laser centre along each line of `lines` (default: lines()) for frame `sequence`;
  // NaN where the line is not lit or its centre lies within 1.5 px of the frame's border. `truth`
  // vectors are resized to the number of lines (allocation only the first time).
  void ground_truth(std::uint64_t sequence, bool laser_on, SimGroundTruth& truth) const;
  void ground_truth(std::uint64_t sequence, bool laser_on, const SimLineFamily& lines,
                    SimGroundTruth& truth) const;

  // The true camera pose of frame `sequence` (sway, scan and vehicle motion).
  SimCameraPose camera_pose(std::uint64_t sequence) const;

  // The surface the renderer draws, in surface coordinates: (x_m, y_m) metres along the base
  // plane's axes from its point (0, 0, distance_m), the x axis being the world x axis turned by
  // tilt_y_deg then tilt_x_deg. relief_height() is the height toward the camera there (0 without
  // relief); surface_point() is the point of the relieved surface in the world frame.
  double relief_height(double x_m, double y_m) const;
  Eigen::Vector3d surface_point(double x_m, double y_m) const;

 private:
  struct Pose;
  Pose pose_at(std::uint64_t sequence) const;

  // Draws the laser's light (the line, forward scatter, marine snow) into image row v.
  void add_laser_row(int v, float* light) const;
  // Image row v of a colour frame from its ambient and laser light (noise from `noise_offset`).
  void colour_row(int v, const float* ambient, const float* light, std::uint64_t noise_offset,
                  std::uint8_t* out);
  // Places this frame's marine snow (snow_).
  void place_snow(std::uint64_t sequence);

  SimSceneOptions options_;
  SimLineFamily lines_;
  std::vector<float> texture_;      // tile of surface albedo
  std::vector<float> caustics_;     // tile of the caustic pattern (empty without caustics)
  float caustic_mean_ = 1.0f;       // its mean
  std::vector<std::int8_t> noise_;  // table of Gaussian sensor noise samples (scaled)
  // Scratch: one image row, the glow floor per pixel, the laser's light (colour), one channel.
  std::vector<float> row_buffer_;
  std::vector<std::uint8_t> channel_rows_;  // colour: one row of each channel, quantised
  SimGroundTruth scratch_truth_;            // per-line truth of the frame being rendered
  std::vector<float> line_gain_;            // per line: peak grey level of the line
  std::vector<float> glow_floor_;  // per line: inverse depth of the lit point (see render())
  std::vector<float> relief_;      // wrapping tile of relief heights (m), empty without relief
  struct Particle {
    float x, y, sigma, peak;
  };
  std::vector<Particle> snow_;  // this frame's marine snow (capacity snow_per_frame)
};

}  // namespace laserline::hal
