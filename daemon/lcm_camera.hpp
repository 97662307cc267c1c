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
// size) are reported on stderr once each with where they are, and the rest is replayed.
//
// It lives in daemon/ rather than hal/ because it needs LCM; it registers itself into the same
// camera factory (register_lcm_camera()). It is a desk tool: reading and decoding allocate, which
// the real-time rule allows only because no laser or live camera depends on its timing.
//
// Thread context: open()/format() from the setup thread; grab() from the camera thread; stop()
// from any thread.
// Reads an LCM log file (the format lcm-logger writes: per event a big-endian header of marker
// 0xEDA1DA01, event number, timestamp, channel length and data length, then the channel and the
// data). Unlike lcm_eventlog_read_next_event it says where damage is and how long, and it keeps
// the whole event before a damaged region. Buffers grow to the largest event and are reused.
// Thread context: one thread.
class LcmLogReader {
 public:
  struct Event {
    std::int64_t offset = 0;  // byte offset of the event in the file
    std::int64_t number = 0;  // the event number lcm-logger gave it
    std::string channel;
    std::vector<std::uint8_t> data;
  };
  struct Damage {
    std::int64_t offset = 0;  // first damaged byte
    std::int64_t bytes = 0;   // damaged bytes skipped
  };

  ~LcmLogReader();
  bool open(const std::string& path, std::string* error);
  std::int64_t file_size() const { return size_; }
  // Reads the next whole event into *event; false at the end of the file. Damaged bytes skipped
  // before it (or before the end) are added to *damage (bytes == 0 when there were none).
  bool next(Event* event, Damage* damage);

 private:
  bool read_at(std::int64_t offset, Event* event);
  std::int64_t find_marker(std::int64_t from);  // offset of the next marker, or the file size

  std::vector<std::uint8_t> scan_;
  std::FILE* file_ = nullptr;
  std::int64_t size_ = 0;
  std::int64_t position_ = 0;
};

class LcmCamera : public hal::Camera {
 public:
  struct Options {
    std::string url;  // file:///path (offline) or an LCM URL (live)
    std::string channel = "LASERLINE_IMAGE";
    int width = 0;  // the frames expected (the calibration's size); others are skipped
    int height = 0;
  };

  // What a replay met so far; complete once grab() returned kStopped.
  struct Counts {
    std::int64_t frames = 0;           // delivered to the frame path
    std::int64_t frames_skipped = 0;   // wrong size, undecodable or unsupported
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

 private:
  hal::GrabStatus grab_offline(std::span<std::uint8_t> dst, hal::FrameInfo& info);
  hal::GrabStatus grab_live(std::span<std::uint8_t> dst, hal::FrameInfo& info,
                            std::chrono::milliseconds timeout);
  // Decodes one image_t event into dst/info; false (reported) when it cannot be used.
  bool take_frame(const void* data, int size, const std::string& where, std::span<std::uint8_t> dst,
                  hal::FrameInfo& info);
  void note_channel(const std::string& channel, const std::string& where);
  void report_end();

  static void on_live_event(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                            LcmCamera* self);

  Options options_;
  hal::FrameFormat format_;
  bool offline_ = false;
  std::string path_;  // offline: the log file
  LcmLogReader log_;
  LcmLogReader::Event event_;
  std::unique_ptr<lcm::LCM> lcm_;
  laserline::image_t image_;            // decode target, reused
  std::vector<std::uint8_t> unpacked_;  // a compressed frame's pixels
  std::vector<std::string> reported_channels_;
  std::atomic<bool> stopping_{false};
  bool ended_ = false;

  // Live: where the subscription handler puts the frame grab() waits for.
  std::span<std::uint8_t> live_dst_;
  hal::FrameInfo* live_info_ = nullptr;
  bool live_got_frame_ = false;

  std::atomic<std::int64_t> frames_{0};
  std::atomic<std::int64_t> frames_skipped_{0};
  std::atomic<std::int64_t> other_events_{0};
  std::atomic<std::int64_t> damaged_regions_{0};
  std::atomic<std::int64_t> damaged_bytes_{0};
};

// Adds the `lcm` backend to hal's camera factory (idempotent). Options under `camera.lcm`:
// url, channel.
void register_lcm_camera();

}  // namespace laserline::daemon
