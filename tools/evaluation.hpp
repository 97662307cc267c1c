#pragma once

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "hal/laser_channel.hpp"
#include "hal/sim/sim_scene.hpp"
#include "pipeline/detector.hpp"

namespace laserline::tools {

// A simulated sequence with an exact answer: what every detector is scored on.
struct Scenario {
  std::string name;
  std::string description;
  hal::SimSceneOptions scene;
  bool alternate = false;  // laser on for even frames, off for odd (the classic on/off method)
  // Colour scenes: the laser's light the camera delivers (camera.channel).
  hal::LaserChannel channel{};
  int first_frame = 0;
  int frames = 16;  // the first is warm-up for detectors that need a previous frame; not scored
};

// clean, ambient (texture as bright as the laser, PTU scanning), ambient-alternate (on/off
// subtraction), pier (as ambient on a surface with bumps and piles of 5-30 cm, the vehicle moving
// along it: parallax no homography explains), backscatter (turbid water, 3 dB line), clipped
// (saturated core).
std::vector<Scenario> standard_scenarios(int width = 1280, int height = 1024);

// Counted per epipolar line (for the paper's mounting, per column).
struct Score {
  int frames = 0;           // scored frames
  long truth_columns = 0;   // lines where the laser is visible
  long found_columns = 0;   // of those, with a point within the tolerance
  long points = 0;          // valid points the detector returned
  long correct_points = 0;  // of those, within the tolerance of the truth
  double sum_error = 0;     // over the closest correct point of each found column
  double sum_squared_error = 0;
  double max_error = 0;
  double sum_snr_db = 0;  // over the correct points: the SNR the detector gave them

  double recall() const { return truth_columns ? double(found_columns) / truth_columns : 0.0; }
  double precision() const { return points ? double(correct_points) / points : 1.0; }
  double rms() const { return found_columns ? std::sqrt(sum_squared_error / found_columns) : 0.0; }
  double bias() const { return found_columns ? sum_error / found_columns : 0.0; }
  double mean_snr_db() const { return correct_points ? sum_snr_db / correct_points : 0.0; }
};

// One scored frame, for overlays: the frame, its truth and the detector's points.
struct ScoredFrame {
  int index = 0;
  const std::vector<std::uint8_t>* pixels = nullptr;
  int width = 0, height = 0;
  const hal::SimGroundTruth* truth = nullptr;
  const pipeline::Profile* profile = nullptr;
};

// The simulator's lines for a detector's search axes.
hal::SimLineFamily line_family(const pipeline::SearchAxes& axes);

// Runs `detector` over the scenario and scores it: a point is correct within `tolerance_px` of the
// true position along its epipolar line (the truth is taken along the lines the detector searched).
// `options` supplies everything but the geometry (taken from the scene).
Score evaluate(const Scenario& scenario, const std::string& detector,
               pipeline::DetectorOptions options, double tolerance_px,
               const std::function<void(const ScoredFrame&)>& on_frame = {});

// The paper's Fig. 7 (its section V-B): the scanner 1.4 m from a wall in a tank, the water made
// more turbid step by step. `level` is the turbidity on a scale of formazine units (FTU): the
// beam attenuation (0.15 per metre per unit), the light the sheet scatters back (6 grey levels
// per unit) and forward (6 % per unit, into a halo 2 px per unit wide) and the veiling light grow
// with it.
Scenario turbidity_scenario(double level, int width = 1280, int height = 1024);

// SNR of the detected line and recall against turbidity, for several band-pass widths (the
// front-end's passband_ratio: the outer box in inner boxes) and every detector.
struct TurbiditySweep {
  std::vector<double> levels;
  std::vector<double> passband_ratios;
  std::vector<std::vector<double>> snr_db;  // [passband][level]: mean SNR of the found points (fir)
  std::vector<std::string> detectors;
  std::vector<std::vector<double>> recall;  // [detector][level]
  // Per detector, the lowest level at which its recall falls below half (NaN: it never does).
  std::vector<double> loses_line_at;
};
TurbiditySweep sweep_turbidity(const std::vector<double>& levels,
                               const std::vector<double>& passband_ratios,
                               const std::vector<std::string>& detectors, int frames,
                               double tolerance_px);
// The sweep as a plot (PNG: SNR against turbidity per passband, and recall per detector) and a
// CSV beside it. False when a file could not be written.
bool write_turbidity_plot(const std::string& png_path, const TurbiditySweep& sweep);
bool write_turbidity_csv(const std::string& csv_path, const TurbiditySweep& sweep);

// Draws the truth (blue, 6 px above the line), valid points (green within the tolerance, red
// otherwise) and rejected candidates (dim yellow) on a frame and writes a PNG. Returns false when
// it could not be written.
bool write_overlay(const std::string& path, const ScoredFrame& frame, double tolerance_px);

}  // namespace laserline::tools
