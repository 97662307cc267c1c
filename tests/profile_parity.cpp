// The same frames must give the same profiles on every architecture (scripts/test-arm64.sh).
//   profile_parity detect FRAMES PROFILES   every detector over every scenario of a frames file
//                                           (make_parity_frames), the profiles as text
//   profile_parity compare EXPECTED ACTUAL  exit 0 when the two profile files are identical
// Floats are written exactly (hexadecimal), so identical files mean bit-identical profiles.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "parity_frames.hpp"
#include "pipeline/detector.hpp"

#if defined(__aarch64__)
#include <sys/auxv.h>
#endif
#include <hwy/targets.h>

#include "pipeline/kernels/kernels.hpp"

namespace {

using namespace laserline;

// Which vector instructions the pipeline's kernels run with here: what the compiler targeted and
// what the CPU (or qemu's emulated CPU) offers.
std::string vector_path() {
  std::string path = std::string("kernels: ") + pipeline::kernels::target_name();
#if defined(__aarch64__)
  const unsigned long hwcap = getauxval(AT_HWCAP);
  const unsigned long hwcap2 = getauxval(AT_HWCAP2);
  path += std::string("; the CPU has ASIMD ") + ((hwcap & HWCAP_ASIMD) ? "yes" : "no") + ", SVE " +
          ((hwcap & HWCAP_SVE) ? "yes" : "no") + ", SVE2 " +
          ((hwcap2 & HWCAP2_SVE2) ? "yes" : "no");
#endif
  path += "; Highway's targets here:";
  for (const std::int64_t target : hwy::SupportedAndGeneratedTargets())
    path += std::string(" ") + hwy::TargetName(target);
  return path;
}

// %a: the exact value, the same text on every machine with IEEE floats.
void write_float(std::ostream& out, float value) {
  char text[48];
  std::snprintf(text, sizeof text, " %a", static_cast<double>(value));
  out << text;
}

int detect(const std::string& frames_path, const std::string& profiles_path) {
  std::printf("profile_parity: vector path: %s\n", vector_path().c_str());
  parity::FramesReader reader(frames_path);
  std::ofstream out(profiles_path);
  if (!out) throw std::runtime_error(profiles_path + ": cannot be written");
  parity::ParityScenario scenario;
  long profiles = 0, points = 0;
  while (reader.next(scenario)) {
    pipeline::DetectorOptions options;
    options.geometry = scenario.geometry;
    const int width = scenario.geometry.width, height = scenario.geometry.height;
    for (const std::string& name : pipeline::detector_names()) {
      auto detector = pipeline::make_detector(name, options);
      detector->reset(width, height);
      pipeline::Profile profile(detector->max_points(width, height));
      for (const parity::ParityFrame& frame : scenario.frames) {
        const pipeline::ImageView view{frame.pixels.data(), width, height, width};
        detector->detect(view, {frame.sequence, frame.laser_on}, profile);
        out << scenario.name << ' ' << name << " frame " << frame.sequence << " points "
            << profile.size() << " overflowed " << profile.overflowed() << " background "
            << profile.background_sequence() << ' ' << profile.background_laser_off() << '\n';
        for (const pipeline::ProfilePoint& p : profile.points()) {
          out << p.u;
          write_float(out, p.v);
          write_float(out, p.snr_db);
          out << ' ' << p.segment << ' ' << p.valid;
          for (float c : p.xyz)
            write_float(out, c);
          out << '\n';
        }
        ++profiles;
        points += static_cast<long>(profile.size());
      }
    }
  }
  out.close();
  if (!out) throw std::runtime_error(profiles_path + ": could not be written whole");
  std::printf("profile_parity: %ld profiles, %ld points into %s\n", profiles, points,
              profiles_path.c_str());
  return 0;
}

std::vector<std::string> read_lines(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot be read");
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);)
    lines.push_back(line);
  if (lines.empty() || lines.front().find(" frame ") == std::string::npos)
    throw std::runtime_error(path + ": line 1: not a profile_parity profiles file");
  return lines;
}

// The point line's numbers: u v snr segment valid x y z.
std::vector<double> numbers(const std::string& line) {
  std::vector<double> values;
  std::istringstream in(line);
  for (std::string word; in >> word;)
    values.push_back(std::strtod(word.c_str(), nullptr));
  return values;
}

int compare(const std::string& expected_path, const std::string& actual_path) {
  const std::vector<std::string> expected = read_lines(expected_path);
  const std::vector<std::string> actual = read_lines(actual_path);
  long differing = 0;
  std::size_t first = std::min(expected.size(), actual.size());
  double worst_v = 0, worst_snr = 0, worst_xyz = 0;
  bool structure = expected.size() == actual.size();
  std::string heading, first_heading;
  for (std::size_t i = 0; i < std::min(expected.size(), actual.size()); ++i) {
    if (expected[i].find(" frame ") != std::string::npos) heading = expected[i];
    if (expected[i] == actual[i]) continue;
    if (differing++ == 0) {
      first = i;
      first_heading = heading;
    }
    const std::vector<double> e = numbers(expected[i]), a = numbers(actual[i]);
    if (e.size() != 8 || a.size() != 8 || e[0] != a[0] || e[3] != a[3] || e[4] != a[4]) {
      structure = false;  // another frame heading, point count, line, segment or validity
      continue;
    }
    worst_v = std::max(worst_v, std::abs(e[1] - a[1]));
    worst_snr = std::max(worst_snr, std::abs(e[2] - a[2]));
    for (int k = 5; k < 8; ++k)
      if (!(std::isnan(e[k]) && std::isnan(a[k])))
        worst_xyz = std::max(worst_xyz, std::abs(e[k] - a[k]));
  }
  if (differing == 0 && structure) {
    std::printf("profile_parity: %s and %s identical (%zu lines)\n", expected_path.c_str(),
                actual_path.c_str(), expected.size());
    return 0;
  }
  if (differing == 0) first_heading = heading;  // one file is the other cut short
  std::fprintf(
      stderr,
      "profile_parity: %s differs from %s: %ld lines differ (%zu lines expected, %zu got), "
      "first at line %zu (%s): expected '%s', got '%s'; %s; largest differences in "
      "differing points: row %.3g px, SNR %.3g dB, xyz %.3g mm\n",
      actual_path.c_str(), expected_path.c_str(), differing, expected.size(), actual.size(),
      first + 1, first_heading.c_str(), first < expected.size() ? expected[first].c_str() : "",
      first < actual.size() ? actual[first].c_str() : "",
      structure ? "the same points" : "points found or judged differently", worst_v, worst_snr,
      worst_xyz * 1000.0);
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (argc != 4 || (mode != "detect" && mode != "compare")) {
    std::fprintf(stderr,
                 "usage: profile_parity detect FRAMES PROFILES | profile_parity compare EXPECTED "
                 "ACTUAL\n");
    return 2;
  }
  try {
    return mode == "detect" ? detect(argv[2], argv[3]) : compare(argv[2], argv[3]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "profile_parity: %s\n", e.what());
    return 1;
  }
}
