#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "hal/camera.hpp"
#include "hal/camera_link.hpp"
#include "hal/laser_channel.hpp"
#include "hal/pixel_conversion.hpp"
#include "hal/registry.hpp"

struct _ArvCamera;
struct _ArvStream;
struct _ArvDevice;

namespace laserline::hal {

enum class AravisTrigger : std::uint8_t {
  kFreeRun,   // the camera exposes at its own frame rate
  kSoftware,  // grab() triggers each exposure, after the laser was set for it
  kLine,      // an external line (trigger_source) starts each exposure
};

struct AravisCameraOptions {
  std::string device;  // device id, serial number or IP address; "" = the first found
  // One of aravis_pixel_formats(): Mono8, Mono12 / Mono16 (their top 8 bits), the Bayer mosaics
  // BayerRG8, BayerGR8, BayerGB8, BayerBG8 (and their 12 and 16-bit forms), RGB8, BGR8.
  std::string pixel_format = "Mono8";
  LaserChannel channel;  // the laser's light in colour frames (hal/pixel_conversion.hpp)
  int width = 0;         // region of interest; width/height = the calibrated size
  int height = 0;
  int offset_x = 0;
  int offset_y = 0;
  double frame_rate_hz = 30;
  double exposure_us = 0;  // 0 = leave the camera's setting
  double gain_db = -1;     // < 0 = leave the camera's setting
  int packet_size = 0;     // GigE packet size in bytes; 0 = leave; -1 = negotiate the largest
  std::int64_t packet_delay_ns = -1;  // GigE inter-packet delay; < 0 = leave
  int buffers = 16;
  AravisTrigger trigger = AravisTrigger::kFreeRun;
  std::string trigger_source = "Line1";  // for kLine
  // Further GenICam features, applied last in this order: (name, value as written in the YAML).
  std::vector<std::pair<std::string, std::string>> features;
  int lost_after_ms = 1000;  // no frame for this long (free-run/software) = camera lost
  int reconnect_min_ms = 100;
  int reconnect_max_ms = 2000;
};

// camera.exposure_us and gain_db (0 and -1: leave the camera's setting); a change while streaming
// is checked against the same ranges, then by the camera.
inline constexpr NumberRange kAravisExposureRange{0.0, 10e6};
inline constexpr NumberRange kAravisGainRange{-1.0, 100.0};

// The pixel formats the aravis backend takes, by their GenICam (SFNC) names.
const std::vector<std::string>& aravis_pixel_formats();
// The aravis backend's factory (hal/registry.hpp): its options from the `camera:` section.
std::unique_ptr<Camera> create_aravis_camera(const CameraRequest& request);
// Empty when the backend takes `options.pixel_format` at the options' size; otherwise why not, one
// line (a mosaic needs 2x2 pixels, YUYV an even width). open() checks it too.
std::string aravis_pixel_format_problem(const AravisCameraOptions& options);

// A GigE Vision (or USB3 Vision) camera through Aravis 0.8.
//
// Pixels: grab() converts each buffer into the mono8 frame, colour formats by the laser's
// channel (PixelConverter: a Bayer mosaic read on its sites, no demosaic), while the buffer is
// held; the conversion allocates nothing.
//
// Buffers: the pixel memory of `buffers` frames is allocated in open() and handed to Aravis
// (arv_buffer_new over our memory) each time the stream is created; every buffer popped is
// pushed back after its pixels were copied out. Nothing is allocated per frame.
//
// Time: the camera's timestamp (camera_ns, from its tick counter) is mapped to host
// CLOCK_MONOTONIC by offset tracking: offset = min over frames of (host arrival - camera time),
// i.e. the frame with the least transfer delay defines it, and the minimum is let rise slowly
// (drift_ns_per_frame) so that it follows drift between the clocks. exposure_mono_ns is
// camera_ns + offset: it is late by the shortest transfer delay seen (readout + network), which
// is constant for a given format. Cameras with PTP should run it; the mapping is the same.
//
// Loss: a camera is lost when Aravis emits "control-lost" (heartbeat failed) or when grab() waited
// lost_after_ms in all without any frame (free-run/software trigger; frames queued while the
// caller was away count as frames). grab() then tears the stream down and
// returns kError; later calls try to reconnect with exponential backoff (reconnect_min_ms
// doubling up to reconnect_max_ms) and re-apply the whole configuration. Reconnecting allocates
// (Aravis objects): that happens only on this recovery path, never while frames flow.
//
// Thread context: open()/format() from the setup thread, grab() from the camera thread, stop()
// and health() from any thread. The control-lost callback runs on Aravis's heartbeat thread and
// only sets a flag.
class AravisCamera final : public Camera {
 public:
  explicit AravisCamera(AravisCameraOptions options);
  ~AravisCamera() override;
  AravisCamera(const AravisCamera&) = delete;
  AravisCamera& operator=(const AravisCamera&) = delete;

  bool open(std::string* error) override;
  // Finds the camera (discovery, then its address directly) and reads its vendor, model, serial
  // and pixel formats without configuring it; the configured pixel_format must be among them.
  bool probe(std::string* found, std::string* error) override;
  FrameFormat format() const override { return format_; }
  GrabStatus grab(std::span<std::uint8_t> dst, FrameInfo& info,
                  std::chrono::milliseconds timeout) override;
  void stop() override;
  CameraHealth health() const override;
  // exposure_us, gain_db, frame_rate_hz (free-running trigger only) and any GenICam feature by
  // name ("genicam:ExposureTime"), written while streaming and read back.
  std::string check_setting(const CameraSetting& setting) const override;
  void apply_setting(const CameraSetting& setting, SettingResult& result) override;
  bool read_setting(const char* name, std::span<char> value) override;

 private:
  bool connect(std::string* error);
  void disconnect();
  bool configure(std::string* error);
  void read_exposure_and_gain(_ArvCamera* camera);
  void count_bad_buffer(int status);
  void update_stream_statistics();
  static void on_control_lost(_ArvDevice* device, void* self);

  AravisCameraOptions options_;
  FrameFormat format_;
  std::size_t payload_bytes_ = 0;
  int pixel_format_index_ = -1;  // in the table of aravis_genicam.cpp; -1: unknown name
  PixelConverter converter_;
  std::vector<std::vector<std::uint8_t>> memory_;  // the pixel memory of every buffer

  _ArvCamera* camera_ = nullptr;
  _ArvStream* stream_ = nullptr;
  unsigned long control_lost_handler_ = 0;
  std::atomic<bool> control_lost_{false};
  std::atomic<bool> stopped_{false};

  // Camera-thread state.
  std::int64_t silent_ns_ = 0;  // time spent waiting for a frame since the last one
  ReconnectBackoff backoff_;
  CameraClockOffset clock_;
  double exposure_us_ = 0;  // as read after configure(); NaN: not known or automatic
  double gain_db_ = 0;
  DeviceSequence sequence_{65535};    // from the frame id: GigE Vision 1 wraps at 16 bits, skips 0
  std::uint64_t underruns_base_ = 0;  // underruns of streams already closed

  CameraHealthCounters counters_;
};

}  // namespace laserline::hal
