// laserline-extract's inputs: what each argument is (image, folder of images, video, LCM log),
// what a log says of its calibration, and the frames of each input handed to the Extractor in
// order.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hal/calibration.hpp"
#include "tools/extractor.hpp"

namespace laserline::tools::extract {

enum class InputKind : std::uint8_t { kMissing, kFolder, kLog, kVideo, kImage };

// What an argument is: a folder, an LCM log (by its first sync word), a video (by its
// extension), else an image; kMissing when it does not exist.
InputKind kind_of(const std::string& input);

// The calibration the frames are extracted with, and what a log must name to be extracted.
struct CalibrationInUse {
  std::uint64_t id = 0;
  std::string name;            // for messages: the file, or the log it came from
  bool accept_others = false;  // --override-log-calibration
};

// What a log says of its calibration before its frames: its first laserline.calibration_t (the
// daemon publishes one at start, before any profile, and every few seconds), and the
// calibration_id of the first profile when that comes first (a logger started after the daemon).
// Reading stops at the first calibration_t: only a log without one is read to its end.
struct LogCalibration {
  std::optional<laserline::hal::Calibration> calibration;
  std::uint64_t id = 0;
  std::string where;  // the event that named the id; empty: the log names none
};

LogCalibration first_log_calibration(const std::string& path);

// Every input's frames through `x`, in the order given (`kinds` from kind_of); a problem with one
// input is reported through x.fail() and the next input is read.
void extract_inputs(Extractor& x, const std::vector<std::string>& inputs,
                    const std::vector<InputKind>& kinds, const CalibrationInUse& in_use);

}  // namespace laserline::tools::extract
