// laserline-evaluate: scores every detector on every simulated scenario against the simulator's
// exact ground truth and prints a table of recall, precision and sub-pixel error. Anyone can rerun
// it; the tests assert the same figures.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

#include "pipeline/detector.hpp"
#include "tools/cli.hpp"
#include "tools/evaluation.hpp"

namespace {

constexpr const char* kUsage =
    "usage: laserline-evaluate [--tolerance PX] [--frames N] [--size WxH] [--seed N] "
    "[--overlay-dir DIR] [--detector NAME]... [--scenario NAME]...\n"
    "                          [--validation chain_code|image_features] [--markdown]\n"
    "       laserline-evaluate --list\n"
    "       laserline-evaluate --turbidity-plot FILE.png [--frames N]\n"
    "Scores detectors on simulated scenarios (ground truth exact): recall, precision\n"
    "within the tolerance (default 2 px), RMS error and bias of the found points.\n"
    "--seed N: another draw of every scenario (texture, relief, particles, noise, motion),\n"
    "N added to each scenario's own seed; 0 (default) is the table in the README.\n"
    "--validation: how backprojection associates segments between frames (default\n"
    "chain_code, the paper's; image_features tracks the segment's box in the image).\n"
    "--markdown: one row per scenario, recall / precision of each detector.\n"
    "--list: the scenarios, one line each: name and description.\n"
    "--turbidity-plot: the paper's Fig. 7: the SNR of the detected line against\n"
    "turbidity (0 to 12 FTU, the wall 1.4 m away) for band-pass widths 2, 3, 4.5 and 6\n"
    "(passband_ratio), and each detector's recall, as FILE.png and FILE.csv.\n";

int run_evaluate(int argc, char** argv) {
  using namespace laserline;
  double tolerance = 2.0;
  int frames = 16;
  int width = 1280, height = 1024;
  std::uint64_t seed = 0;
  std::string overlay_dir, turbidity_plot;
  bool markdown = false;
  std::vector<std::string> detectors, scenarios;
  pipeline::DetectorOptions options;
  cli::Arguments args(argc, argv, "laserline-evaluate", kUsage,
                      {{"tolerance", true},
                       {"frames", true},
                       {"size", true},
                       {"seed", true},
                       {"overlay-dir", true},
                       {"detector", true},
                       {"validation", true},
                       {"markdown", false},
                       {"list", false},
                       {"turbidity-plot", true},
                       {"scenario", true}});
  while (args.next()) {
    const std::string& arg = args.name();
    auto value = [&]() -> std::string { return args.value(); };
    try {
      if (arg == "--tolerance") {
        tolerance = std::stod(value());
      } else if (arg == "--frames") {
        frames = std::stoi(value());
      } else if (arg == "--size") {
        const std::string s = value();
        const auto x = s.find('x');
        if (x == std::string::npos) throw std::invalid_argument(s);
        width = std::stoi(s.substr(0, x));
        height = std::stoi(s.substr(x + 1));
      } else if (arg == "--seed") {
        const std::string v = value();
        std::size_t used = 0;
        seed = std::stoull(v, &used);
        if (used != v.size() || v.find('-') != std::string::npos) throw std::invalid_argument(v);
      } else if (arg == "--overlay-dir") {
        overlay_dir = value();
      } else if (arg == "--detector") {
        detectors.push_back(value());
      } else if (arg == "--validation") {
        const std::string v = value();
        if (v == "chain_code") {
          options.validation.association = pipeline::SegmentAssociation::chain_code;
        } else if (v == "image_features") {
          options.validation.association = pipeline::SegmentAssociation::image_features;
        } else {
          throw std::invalid_argument(v);
        }
      } else if (arg == "--markdown") {
        markdown = true;
      } else if (arg == "--list") {
        for (const tools::Scenario& s : tools::standard_scenarios(width, height))
          std::printf("%s: %s\n", s.name.c_str(), s.description.c_str());
        return 0;
      } else if (arg == "--turbidity-plot") {
        turbidity_plot = value();
      } else if (arg == "--scenario") {
        scenarios.push_back(value());
      } else {
        args.fail("unexpected argument '" + args.value() + "'");
      }
    } catch (const std::exception&) {
      std::fprintf(stderr, "laserline-evaluate: bad value for %s\n", arg.c_str());
      return 2;
    }
  }
  if (!(tolerance > 0) || frames < 2 || width < 64 || height < 64) {
    std::fprintf(stderr, "laserline-evaluate: need tolerance > 0, frames >= 2, size >= 64x64\n");
    return 2;
  }
  if (detectors.empty()) detectors = pipeline::detector_names();
  if (!overlay_dir.empty()) std::filesystem::create_directories(overlay_dir);
  if (!turbidity_plot.empty()) {
    std::vector<double> levels;
    for (int level = 0; level <= 12; ++level)
      levels.push_back(level);
    const tools::TurbiditySweep sweep =
        tools::sweep_turbidity(levels, {2.0, 3.0, 4.5, 6.0}, detectors, frames, tolerance);
    const std::string csv =
        std::filesystem::path(turbidity_plot).replace_extension(".csv").string();
    if (!tools::write_turbidity_plot(turbidity_plot, sweep) ||
        !tools::write_turbidity_csv(csv, sweep)) {
      std::fprintf(stderr, "laserline-evaluate: cannot write %s or %s\n", turbidity_plot.c_str(),
                   csv.c_str());
      return 1;
    }
    for (std::size_t k = 0; k < sweep.detectors.size(); ++k) {
      if (std::isnan(sweep.loses_line_at[k])) {
        std::printf("%-14s finds over half the line up to %g FTU\n", sweep.detectors[k].c_str(),
                    levels.back());
      } else {
        std::printf("%-14s loses the line (under half found) at %g FTU\n",
                    sweep.detectors[k].c_str(), sweep.loses_line_at[k]);
      }
    }
    std::printf("wrote %s and %s\n", turbidity_plot.c_str(), csv.c_str());
    return 0;
  }
  if (markdown) {
    std::printf("| scenario |");
    for (const std::string& name : detectors)
      std::printf(" %s |", name.c_str());
    std::printf("\n|---|");
    for (std::size_t k = 0; k < detectors.size(); ++k)
      std::printf("---|");
    std::printf("\n");
  }

  if (!markdown)
    std::printf("%-24s %-14s %7s %9s %9s %8s %8s %8s\n", "scenario", "detector", "frames", "recall",
                "precision", "rms_px", "bias_px", "max_px");
  for (tools::Scenario scenario : tools::standard_scenarios(width, height)) {
    if (!scenarios.empty() &&
        std::find(scenarios.begin(), scenarios.end(), scenario.name) == scenarios.end()) {
      continue;
    }
    scenario.frames = frames;
    scenario.scene.seed += seed;
    if (markdown) std::printf("| %s |", scenario.name.c_str());
    for (const std::string& name : detectors) {
      tools::Score score;
      try {
        score =
            tools::evaluate(scenario, name, options, tolerance, [&](const tools::ScoredFrame& f) {
              if (!overlay_dir.empty() && f.index == frames / 2) {
                const std::string path = overlay_dir + "/" + scenario.name + "-" + name + ".png";
                if (!tools::write_overlay(path, f, tolerance)) {
                  std::fprintf(stderr, "laserline-evaluate: cannot write %s\n", path.c_str());
                }
              }
            });
      } catch (const std::exception& e) {
        std::fprintf(stderr, "laserline-evaluate: %s on %s: %s\n", name.c_str(),
                     scenario.name.c_str(), e.what());
        return 1;
      }
      if (markdown) {
        std::printf(" %.1f / %.1f |", 100.0 * score.recall(), 100.0 * score.precision());
      } else {
        std::printf("%-24s %-14s %7d %8.2f%% %8.2f%% %8.3f %8.3f %8.3f\n", scenario.name.c_str(),
                    name.c_str(), score.frames, 100.0 * score.recall(), 100.0 * score.precision(),
                    score.rms(), score.bias(), score.max_error);
      }
    }
    if (markdown) std::printf("\n");
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_evaluate);
}
