#pragma once

#include <laserline/calibration_t.hpp>

#include <cstdint>
#include <string>

#include "hal/calibration.hpp"

namespace laserline::daemon {

// laserline.calibration_t, the calibration a log or a live daemon names (published by the daemon,
// read by the replay camera and the desk tools): here rather than in the publisher so that the
// tools read it without linking the daemon.

// The calibration as a message (utime left 0): its values and calibration_id.
laserline::calibration_t calibration_message(const hal::Calibration& calibration,
                                             std::int64_t instance_id);

// The calibration a message carries, or false with a one-line reason in *problem (the field and
// what is wrong) when a value is out of the range a calibration file allows, or its
// calibration_id is not the id of its content.
bool calibration_from_message(const laserline::calibration_t& message,
                              hal::Calibration* calibration, std::string* problem);

}  // namespace laserline::daemon
