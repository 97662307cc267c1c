#pragma once

#include <atomic>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "hal/camera.hpp"
#include "hal/camera_link.hpp"
#include "hal/laser_channel.hpp"
#include "hal/pixel_conversion.hpp"
#include "hal/registry.hpp"

namespace laserline::hal {

struct V4l2CameraOptions {
  std::string device = "/dev/video0";
  // One of v4l2_pixel_formats(), named as the V4L2_PIX_FMT_ macros: GREY, Y16 (top 8 bits kept),
  // YUYV, the Bayer mosaics SRGGB8, SGRBG8, SGBRG8, SBGGR8 (and their 12 and 16-bit forms),
  // RGB24, BGR24.
  std::string pixel_format = "GREY";
  LaserChannel channel;  // the laser's light in colour frames (hal/pixel_conversion.hpp)
  int width = 0;
  int height = 0;
  double frame_rate_hz = 30;
  int buffers = 4;
  int reconnect_min_ms = 100;
  int reconnect_max_ms = 2000;
};

// The pixel formats the v4l2 backend takes (names of the V4L2_PIX_FMT_ macros).
const std::vector<std::string>& v4l2_pixel_formats();
// The v4l2 backend's factory (hal/registry.hpp): its options from the `camera:` section.
std::unique_ptr<Camera> create_v4l2_camera(const CameraRequest& request);
// Empty when the backend takes `options.pixel_format` at the options' size; otherwise why not, one
// line (a mosaic needs 2x2 pixels, YUYV an even width). open() checks it too.
std::string v4l2_pixel_format_problem(const V4l2CameraOptions& options);

// A V4L2 capture device with mmap streaming (REQBUFS / QBUF / poll / DQBUF).
//
// Buffers: the driver's buffers are mapped once per open and every one dequeued is queued again
// after its pixels were converted into the mono8 frame slot (PixelConverter: colour formats by
// the laser's channel, a Bayer mosaic on its sites, YUYV from its luma and chroma by the
// Y'CbCr encoding and range the driver states); nothing is allocated per frame.
//
// Time: the driver's timestamp is CLOCK_MONOTONIC when it says so (V4L2_BUF_FLAG_TIMESTAMP_
// MONOTONIC; every modern driver): it is then taken as is for exposure_mono_ns. Drivers stamp the
// start of exposure (V4L2_BUF_FLAG_TSTAMP_SRC_SOE) or, more often, the end of readout (EOF); for
// EOF the exposure began one exposure + readout earlier, which this backend does not know and does
// not subtract. A driver with another clock has its stamps mapped like the aravis backend's
// (minimum offset to arrival).
//
// Loss: ENODEV / POLLERR (device unplugged) closes the device; later grabs reopen it with
// exponential backoff, which allocates only on that recovery path.
//
// Thread context: open()/format() from the setup thread, grab() from the camera thread, stop()
// and health() from any thread.
class V4l2Camera final : public Camera {
 public:
  explicit V4l2Camera(V4l2CameraOptions options);
  ~V4l2Camera() override;
  V4l2Camera(const V4l2Camera&) = delete;
  V4l2Camera& operator=(const V4l2Camera&) = delete;

  bool open(std::string* error) override;
  // Opens the device node and reads its name, driver and formats (QUERYCAP, ENUM_FMT) without
  // setting a format or mapping buffers; the configured pixel_format must be among them.
  bool probe(std::string* found, std::string* error) override;
  FrameFormat format() const override { return format_; }
  GrabStatus grab(std::span<std::uint8_t> dst, FrameInfo& info,
                  std::chrono::milliseconds timeout) override;
  void stop() override;
  CameraHealth health() const override;
  // exposure_us (V4L2_CID_EXPOSURE_ABSOLUTE, in its 100 us units, within the device's range),
  // frame_rate_hz (S_PARM, where the driver takes it while streaming) and any integer, 64-bit,
  // boolean or menu control by name ("v4l2:gain"; the name as v4l2-ctl writes it or as the
  // driver reports it), found with VIDIOC_QUERY_EXT_CTRL, set with VIDIOC_S_EXT_CTRLS on the
  // value in force and read back with VIDIOC_G_EXT_CTRLS, as v4l2-ctl and libcamera do. A driver
  // without the extended ioctls (ENOTTY) gets QUERYCTRL/S_CTRL/G_CTRL for its 32-bit controls.
  std::string check_setting(const CameraSetting& setting) const override;
  void apply_setting(const CameraSetting& setting, SettingResult& result) override;
  bool read_setting(const char* name, std::span<char> value) override;

 private:
  struct Mapping {
    void* address = nullptr;
    std::size_t length = 0;
  };

  bool connect(std::string* error);
  void disconnect();
  void lost();

  V4l2CameraOptions options_;
  FrameFormat format_;
  int pixel_format_index_ = -1;       // in the table of v4l2_camera.cpp; -1: unknown name
  std::uint32_t bytes_per_line_ = 0;  // as the driver set it
  PixelConverter converter_;
  int fd_ = -1;
  std::vector<Mapping> mappings_;
  std::atomic<bool> stopped_{false};

  // Camera-thread state.
  ReconnectBackoff backoff_;
  CameraClockOffset clock_;  // for drivers without monotonic timestamps
  DeviceSequence sequence_;  // from the driver's sequence (it restarts on reopen)
  double exposure_us_ = std::numeric_limits<double>::quiet_NaN();  // once set by a command

  CameraHealthCounters counters_;  // underruns: gaps in the driver's sequence, frames it lost
};

}  // namespace laserline::hal
