#pragma once

#include <laserline/image_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "hal/camera.hpp"
#include "lcmtypes/checked_decode.hpp"
#include "lcmtypes/lcm_log.hpp"

namespace laserline::daemon {

// Replays raw frames (laserline.image_t, as laserlined publishes them on LASERLINE_IMAGE and
// lcm-logger records them) as a camera, so that a recorded dive runs through the same frame path.
//
//  - Offline, `url: file:///path/dive.lcmlog`: reads the log file directly, every frame in order
//    and as fast as the frame path takes them (paced_by_consumer()), deterministic.
//  - Live, any other LCM URL (udpm://...): subscribes to the channel, e.g. while lcm-logplayer
//    plays a log; frames that arrive while the frame path is busy are dropped like a camera's.
//
// The frame's sequence number, camera timestamp, laser state and exposure time come from the
// recording, so a replay publishes the same profiles as the original run. Problems in the log
// (a damaged region, an event on another channel, a frame that does not decode or has another
// size) are reported on stderr with where they are, and the rest is replayed. Every message is
// decoded only after its lengths are checked against the bytes received and the calibrated
// frame's size (messages::decode); bad messages and unusable frames are counted by kind in
// health() (status_t.bad_messages, bad_frames) and reported at a limited rate.
//
// It lives in daemon/ rather than hal/ because it needs LCM; it registers itself as the `lcm`
// camera backend (hal/registry.hpp; options under `camera.lcm`: url, channel,
// calibration_channel). It is a desk tool: reading and decoding allocate, which the real-time rule
// allows only because no laser or live camera depends on its timing.
//
// Thread context: open()/format() from the setup thread; grab() from the camera thread; stop()
// from any thread.
class LcmCamera : public hal::Camera {
 public:
  struct Options {
    std::string url;  // file:///path (offline) or an LCM URL (live)
    std::string channel = "LASERLINE_IMAGE";
    int width = 0;  // the frames expected (the calibration's size); others are skipped
    int height = 0;
    // The recording's laserline.calibration_t: a replay under another calibration is refused
    // (its 3-D points would be wrong without a word).
    std::string calibration_channel = "LASERLINE_CALIBRATION";
    std::uint64_t calibration_id = 0;  // the calibration in force
  };

  // What a replay met so far; complete once grab() returned kStopped.
  struct Counts {
    std::int64_t frames = 0;           // delivered to the frame path
    std::int64_t frames_skipped = 0;   // bad messages and bad frames
    std::int64_t bad_messages = 0;     // not a valid laserline.image_t within the limits
    std::int64_t bad_frames = 0;       // a valid message whose frame cannot be used
    std::int64_t other_events = 0;     // events on other channels
    std::int64_t damaged_regions = 0;  // places where the log could not be read
    std::int64_t damaged_bytes = 0;    // bytes of the log lost in them
  };

  explicit LcmCamera(Options options);
  ~LcmCamera() override;

  bool open(std::string* error) override;
  hal::FrameFormat format() const override { return format_; }
  hal::GrabStatus grab(std::span<std::uint8_t> dst, hal::FrameInfo& info,
                       std::chrono::milliseconds timeout) override;
  void stop() override;
  bool paced_by_consumer() const override { return offline_; }

  Counts counts() const;
  hal::CameraHealth health() const override;

 private:
  hal::GrabStatus grab_offline(std::span<std::uint8_t> dst, hal::FrameInfo& info);
  hal::GrabStatus grab_live(std::span<std::uint8_t> dst, hal::FrameInfo& info,
                            std::chrono::milliseconds timeout);
  // Decodes one image_t event into dst/info; false (reported) when it cannot be used.
  bool take_frame(const void* data, int size, const std::string& where, std::span<std::uint8_t> dst,
                  hal::FrameInfo& info);
  bool skip_frame(bool bad_message, const std::string& kind, const std::string& where,
                  const std::string& problem);
  void note_channel(const std::string& channel, const std::string& where);
  // A calibration_t of the recording: false (reported, the replay ends) when it names another
  // calibration than the one in force.
  bool check_calibration(const void* data, int size, const std::string& where);
  void report_end();

  static void on_live_event(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                            LcmCamera* self);
  static void on_live_calibration(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                                  LcmCamera* self);

  Options options_;
  hal::FrameFormat format_;
  bool offline_ = false;
  std::string path_;  // offline: the log file
  messages::LcmLogReader log_;
  messages::LcmLogReader::Event event_;
  messages::Limits limits_;  // the calibrated frame's size bounds every message
  messages::ProblemLog problems_{"laserlined: replay "};
  cv::Mat pixels_;  // a frame's unpacked pixels
  std::unique_ptr<lcm::LCM> lcm_;
  laserline::image_t image_;  // decode target, reused
  std::vector<std::string> reported_channels_;
  std::string unfit_frame_;  // the first recorded frame that does not fit the calibration
  std::atomic<std::int64_t> unfit_frames_{0};
  bool jpeg_reported_ = false;
  std::int64_t last_sequence_ = 0;   // of the last frame replayed
  std::int64_t missing_frames_ = 0;  // sequence numbers skipped between replayed frames
  std::atomic<bool> stopping_{false};
  bool ended_ = false;
  std::atomic<bool> refused_{false};  // the recording names another calibration

  // Live: where the subscription handler puts the frame grab() waits for.
  std::span<std::uint8_t> live_dst_;
  hal::FrameInfo* live_info_ = nullptr;
  bool live_got_frame_ = false;

  std::atomic<std::int64_t> frames_{0};
  std::atomic<std::int64_t> bad_messages_{0};
  std::atomic<std::int64_t> bad_frames_{0};
  std::atomic<std::int64_t> other_events_{0};
  std::atomic<std::int64_t> damaged_regions_{0};
  std::atomic<std::int64_t> damaged_bytes_{0};
};

}  // namespace laserline::daemon
