#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <vector>

#include "hal/camera.hpp"
#include "hal/laser.hpp"
#include "hal/sim/sim_scene.hpp"

namespace laserline::hal {

// The built-in simulated scanner as a camera: renders SimScene frames at the configured rate,
// paced on CLOCK_MONOTONIC like a free-running sensor, lit by `laser` as it is at exposure time.
// Frame n has sequence number n, so SimScene(options).ground_truth(n, ...) is its exact answer.
// A stall (no frames for a while, as when a cable is pulled) can be injected to test what the
// rest of the system does when frames stop.
struct SimCameraStall {
  double after_s = 0;  // seconds after open(); 0 = never
  double for_s = 0;
};

// What the simulated camera reports as each frame's exposure and gain (camera.sim.exposure_us,
// gain_db), as a real camera reports its settings; the rendered scene's brightness is the scene's
// own (laser_peak, ambient) at these. Changed while streaming (apply_setting), they scale the
// frame's grey levels as a sensor's would: by the ratio of exposures times the gain's ratio in
// amplitude, clipped at 255.
struct SimCameraExposure {
  double exposure_us = 1000;
  double gain_db = 0;
};
inline constexpr NumberRange kSimExposureRange{1.0, 1e7};  // camera.sim.exposure_us
inline constexpr NumberRange kSimGainRange{-20.0, 60.0};   // camera.sim.gain_db

class SimCamera final : public Camera {
 public:
  // Colour scenes are delivered as `channel` of them (the conversion a colour camera backend
  // makes, hal/pixel_conversion.hpp).
  SimCamera(const SimSceneOptions& options, const Laser* laser, SimCameraStall stall = {},
            const LaserChannel& channel = {}, SimCameraExposure exposure = {});

  bool open(std::string* error) override;
  FrameFormat format() const override { return scene_.format(); }
  GrabStatus grab(std::span<std::uint8_t> dst, FrameInfo& info,
                  std::chrono::milliseconds timeout) override;
  void stop() override;
  // exposure_us and gain_db; the frame rate is the scene's time base and stays as configured.
  std::string check_setting(const CameraSetting& setting) const override;
  void apply_setting(const CameraSetting& setting, SettingResult& result) override;
  bool read_setting(const char* name, std::span<char> value) override;

  // Writes frame `sequence` as grab() delivers it (pixels; the info's laser state, exposure and
  // gain) without waiting for its time and without open(): for sources that render ahead (the
  // memory camera). Timestamps are left to the caller.
  void render_frame(std::uint64_t sequence, bool laser_on, std::span<std::uint8_t> dst,
                    FrameInfo& info);

 private:
  void update_brightness();

  SimScene scene_;
  PixelConverter converter_;       // colour scenes: raw_ -> the frame
  std::vector<std::uint8_t> raw_;  // colour scenes: the frame as rendered
  const Laser* laser_;
  SimCameraStall stall_;
  SimCameraExposure exposure_;
  const SimCameraExposure configured_exposure_;
  std::array<std::uint8_t, 256> brightness_{};  // grey level -> grey level at exposure_
  bool scaled_ = false;                         // brightness_ is not the identity
  std::int64_t period_ns_;
  std::int64_t start_mono_ns_ = 0;
  std::uint64_t next_sequence_ = 0;
  std::atomic<bool> stopped_{false};
};

}  // namespace laserline::hal
