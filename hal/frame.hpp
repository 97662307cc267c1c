#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>

namespace laserline::hal {

// Pixel layouts a camera can deliver. Only 8-bit mono is processed by the pipeline: cameras
// convert what their sensors send into it (hal/pixel_conversion.hpp).
enum class PixelFormat : std::uint8_t { kMono8 };

// Geometry of the frames a camera delivers; fixed once the camera is opened.
struct FrameFormat {
  int width = 0;
  int height = 0;
  int stride = 0;  // bytes per row
  PixelFormat pixel_format = PixelFormat::kMono8;

  std::size_t bytes() const {
    return static_cast<std::size_t>(stride) * static_cast<std::size_t>(height);
  }
};

// What is known about one delivered frame. Times are nanoseconds.
struct FrameInfo {
  std::uint64_t sequence = 0;  // the camera's frame counter (gaps mean frames the camera lost)
  std::int64_t camera_ns = 0;  // the camera's own timestamp (its clock, arbitrary epoch)
  std::int64_t exposure_mono_ns = 0;  // camera timestamp mapped to host CLOCK_MONOTONIC
  std::int64_t arrival_mono_ns = 0;   // host CLOCK_MONOTONIC when the frame was complete
  std::int64_t arrival_wall_ns = 0;   // host CLOCK_REALTIME at the same instant
  bool laser_on = false;              // laser state during the exposure
  // Host CLOCK_MONOTONIC of the last laser switch before this frame was grabbed (0 = none yet).
  // When it is later than exposure_mono_ns the switch came too late for this frame.
  std::int64_t laser_switch_mono_ns = 0;
  // The exposure as the camera's strobe output showed it (laser.strobe_line), host
  // CLOCK_MONOTONIC; both 0 where no strobe edge was matched to the frame. laser_on is then
  // decided from the laser's switch times against them (hal/exposure_strobe.hpp).
  std::int64_t exposure_start_mono_ns = 0;
  std::int64_t exposure_end_mono_ns = 0;
  // The exposure time and analogue gain the camera reports for this frame; NaN where it does not.
  double exposure_us = std::numeric_limits<double>::quiet_NaN();
  double gain_db = std::numeric_limits<double>::quiet_NaN();

  // Exposure time on the wall clock, from the two host clocks read together at arrival.
  std::int64_t exposure_wall_ns() const {
    return arrival_wall_ns - (arrival_mono_ns - exposure_mono_ns);
  }
};

}  // namespace laserline::hal
