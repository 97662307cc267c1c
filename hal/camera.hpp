#pragma once

#include <chrono>
#include <cstdint>
#include <span>
#include <string>

#include "hal/frame.hpp"

namespace laserline::hal {

enum class GrabStatus : std::uint8_t {
  kOk,       // a frame was written
  kTimeout,  // no frame within the timeout; the camera may still come back
  kError,    // the frame or the camera failed; counted, the caller carries on
  kStopped,  // stop() was called
};

const char* to_string(GrabStatus status);

// A setting's accepted values, where the configuration and a change while streaming check them.
struct NumberRange {
  double min;
  double max;
  bool holds(double value) const { return value >= min && value <= max; }  // false for NaN
};
// camera.frame_rate_hz, every backend.
inline constexpr NumberRange kFrameRateRange{0.1, 1000.0};

// A camera setting changed while streaming (laserlined's command channel): exposure_us, gain_db,
// frame_rate_hz, or a backend's own ("genicam:<Feature>", "v4l2:<control name>"). Fixed buffers:
// it travels to the camera thread, which neither allocates nor locks.
struct CameraSetting {
  static constexpr std::size_t kTextBytes = 256;
  char name[kTextBytes] = {};
  char value[kTextBytes] = {};  // as given
  double number = 0;            // the value as a number, when it is one (the generic settings)
};
// What became of a CameraSetting: the value in force before and after, as read back from the
// device, or why it was refused (one line).
struct SettingResult {
  static constexpr std::size_t kTextBytes = 256;
  bool accepted = false;
  char old_value[kTextBytes] = {};
  char in_force[kTextBytes] = {};
  char reason[kTextBytes] = {};
};

// Failures a camera backend counts by kind, totals since open(). Read from any thread.
struct CameraHealth {
  std::int64_t missing_packets = 0;  // frames incomplete: packets lost on the network
  std::int64_t timeouts = 0;         // frames the driver gave up waiting for
  std::int64_t size_mismatches = 0;  // frames whose size was not the configured one
  std::int64_t underruns = 0;        // frames lost because no buffer was free
  std::int64_t other_errors = 0;     // any other failed frame or device error
  std::int64_t reconnects = 0;       // times the camera was lost and opened again
  // Frames the camera numbered that never arrived whole: gaps in its frame ids (or the driver's
  // sequence) between frames delivered, whatever the cause (all packets lost, a bad buffer, no
  // free buffer). Not counted across a reconnect, where the numbering starts again.
  std::int64_t skipped_frames = 0;
  // Backends fed by messages (lcm): input refused before it became a frame.
  std::int64_t bad_messages = 0;  // not a valid message of its type, or beyond the limits
  std::int64_t bad_frames = 0;    // a valid message whose frame cannot be used
};

// A source of frames. Backends (sim, aravis, v4l2, replay) implement it and register with
// CameraRegistry. Thread context: open()/format() from the setup thread; grab() from the one
// camera thread; stop() from any thread (it wakes a blocked grab()).
// Helpers for the backends' settings. The reason a number `text` is outside `range`, in the
// configuration's words ("exposure_us: must be between 1 and 1e+07, got 2e7"), or "".
std::string range_problem(const char* name, const char* text, double value, NumberRange range);
// Writes a number, or a text, into a setting's fixed buffer (truncated to fit, NUL-terminated).
void write_setting_value(std::span<char> out, double value);
void write_setting_text(std::span<char> out, const char* text);
// printf into a fixed buffer, truncated to fit (a reason longer than the buffer is cut).
void write_setting_line(std::span<char> out, const char* format, ...)
    __attribute__((format(printf, 2, 3)));

class Camera {
 public:
  virtual ~Camera() = default;

  // Opens the device and fixes the frame format. Returns false with a one-line reason in *error.
  virtual bool open(std::string* error) = 0;
  virtual FrameFormat format() const = 0;

  // For --check-config: finds the device and says in one line what it is (*found: model,
  // serial, formats) without configuring or streaming it, or false with a one-line reason in
  // *error. Sources that are no device (the simulator, a recording): true and *found empty.
  virtual bool probe(std::string* found, std::string* error) {
    (void)error;
    if (found != nullptr) found->clear();
    return true;
  }

  // Waits up to `timeout` for the next frame and writes its pixels (format().bytes()) into `dst`.
  // No allocation and no exception: the frame path calls it.
  virtual GrabStatus grab(std::span<std::uint8_t> dst, FrameInfo& info,
                          std::chrono::milliseconds timeout) = 0;

  virtual void stop() = 0;

  // True for a source that is a recording rather than a live device (a log file): it can wait,
  // so the frame path waits for room in its rings instead of dropping, and every frame is
  // processed, which makes a replay deterministic. A live camera cannot wait: false.
  virtual bool paced_by_consumer() const { return false; }

  // The rate frames come at when the source sets it itself rather than following
  // camera.frame_rate_hz (the memory camera's rate_hz); 0: camera.frame_rate_hz is the rate.
  virtual double own_frame_rate_hz() const { return 0.0; }

  // Counters by failure kind; backends without any report zeros.
  virtual CameraHealth health() const { return {}; }

  // Settings while streaming. check_setting(): from any thread, without touching the device:
  // "" when `setting` names one this camera has and its value lies in the range its option in
  // the configuration takes, else why not (one line, naming the setting). apply_setting(): from
  // the camera thread between grabs, for a setting check_setting() passed; writes it to the
  // device and reads it back into `result` (no allocation in our code: the driver's own call may
  // take its locks or make a network round trip). read_setting(): the value in force, from the
  // camera thread; false for a setting this camera does not have.
  virtual std::string check_setting(const CameraSetting& setting) const {
    return std::string(setting.name) + ": not a setting of this camera";
  }
  virtual void apply_setting(const CameraSetting& setting, SettingResult& result) {
    (void)setting;
    result.accepted = false;
    write_setting_text(result.reason, "not a setting of this camera");
  }
  virtual bool read_setting(const char* name, std::span<char> value) {
    (void)name;
    (void)value;
    return false;
  }
};

}  // namespace laserline::hal
