#pragma once

#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "lcmtypes/checked_decode.hpp"

// What laserline-view has received: the latest message of each channel (decoded and checked on
// the LCM thread, kept under one mutex), the points of the last seconds for the 3-D view, and each
// browser's event stream of them as JSON.
namespace laserline::view {

using Clock = std::chrono::steady_clock;

// A channel subscribed to: its name and what came on it.
struct Channel {
  std::string name;
  std::int64_t received = 0;
  std::int64_t malformed = 0;
  Clock::time_point last{};
};

// Points of one profile for the 3-D view, millimetres in the camera frame.
struct CloudChunk {
  std::int64_t index;
  Clock::time_point received;
  std::int64_t utime;  // exposure: profiles are spaced as exposed, not as they arrived in bursts
  std::vector<float> xyz_mm;
};

struct EncodedFrame {
  std::int64_t sequence = -1;
  std::string jpeg;
};

class LiveState {
 public:
  LiveState(std::string profile_channel, std::string image_channel, std::string status_channel,
            double history_s)
      : history_(
            std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(history_s))) {
    channels_[kProfile].name = std::move(profile_channel);
    channels_[kImage].name = std::move(image_channel);
    channels_[kStatus].name = std::move(status_channel);
  }

  // --- the LCM thread ---
  void on_message(const lcm::ReceiveBuffer* rbuf, const std::string& channel_name) {
    for (int c = 0; c < kChannels; ++c) {
      if (channel_name == channels_[c].name) receive(c, rbuf->data, rbuf->data_size);
    }
  }

  // --- any thread ---
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    changed_.notify_all();
  }

  // One browser's event stream: what it has been sent, and when it may have more.
  class Stream {
   public:
    Stream(LiveState& state, double frame_rate_hz, double profile_rate_hz)
        : state_(state),
          frame_period_(period(frame_rate_hz)),
          profile_period_(period(profile_rate_hz)) {}

    // Waits (at most about a second) for something new that is due and returns it as SSE text;
    // empty when stopping.
    std::string next(bool* stopping);

   private:
    static Clock::duration period(double hz) {
      return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
    }
    LiveState& state_;
    Clock::duration frame_period_, profile_period_;
    std::int64_t status_sent_ = 0, profile_sent_ = 0, frame_sent_ = 0, cloud_sent_ = -1;
    Clock::time_point next_frame_{}, next_profile_{}, next_viewer_{};
    bool started_ = false;
  };

  // The latest raw frame as JPEG (encoded once per frame, whoever asks); nullptr when none
  // arrived or it does not decode (then *problem says why).
  std::shared_ptr<const EncodedFrame> frame_jpeg(std::string* problem);

  std::atomic<int> open_streams_{0};

 private:
  enum { kProfile, kImage, kStatus, kChannels };

  void receive(int c, const void* data, std::size_t size);
  void store_profile(std::shared_ptr<laserline::profile_t> p);

  std::string status_json(const laserline::status_t& s) const;
  std::string profile_json(const laserline::profile_t& p, std::int64_t cloud_after,
                           std::int64_t* cloud_sent) const;
  std::string frame_json(const laserline::image_t& image) const;
  std::string viewer_json() const;

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  bool stopping_ = false;
  Channel channels_[kChannels];
  std::string last_problem_;
  std::shared_ptr<const laserline::profile_t> profile_;
  std::shared_ptr<const laserline::image_t> image_;
  std::shared_ptr<const laserline::status_t> status_;
  std::int64_t profile_count_ = 0, image_count_ = 0, status_count_ = 0;
  std::deque<std::shared_ptr<const laserline::profile_t>> recent_;
  std::deque<CloudChunk> cloud_;
  Clock::duration history_;
  const Clock::time_point started_ = Clock::now();

  // Only the LCM thread touches these.
  laserline::messages::Limits limits_;
  laserline::messages::ProblemLog problems_{"laserline-view: "};

  std::mutex encode_mutex_;  // one encoder at a time; readers of the cache take mutex_
  std::shared_ptr<const EncodedFrame> encoded_;
};

}  // namespace laserline::view
