#pragma once

#include <laserline/calibration_t.hpp>
#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "daemon/calibration_message.hpp"
#include "daemon/frame_slots.hpp"
#include "daemon/raw_frame_encoder.hpp"
#include "hal/calibration.hpp"
#include "hal/frame.hpp"

namespace laserline::daemon {

struct PublisherChannels {
  std::string profile = "LASERLINE_PROFILE";
  std::string image = "LASERLINE_IMAGE";
  std::string status = "LASERLINE_STATUS";
  std::string calibration = "LASERLINE_CALIBRATION";
  // lcm.profile_points: false sends only the accepted points, true the rejected candidates too.
  bool all_points = false;
};

// Turns slots into LCM messages. Messages and the encode buffer are sized at construction for the
// largest profile and frame, so publishing allocates nothing (LCM's typed publish() would
// allocate a buffer per call; we encode ourselves and hand LCM the bytes).
// Thread context: the publisher thread only (lcm_publish takes a lock and makes a syscall, which
// is why it is kept off the real-time threads).
class LcmPublisher {
 public:
  // `image_lcm`, when given, carries the raw frames: LCM's UDP publish holds one lock while it
  // sends all fragments of a message, so a megabyte frame on the same instance would hold up
  // the profile published after it.
  // `calibration`: the one in force, published by publish_calibration() and named by its id in
  // every profile.
  LcmPublisher(lcm::LCM& lcm, lcm::LCM* image_lcm, PublisherChannels channels,
               const std::string& detector, std::size_t max_points, const hal::FrameFormat& format,
               const hal::Calibration& calibration);

  bool publish_profile(const ProfileSlot& slot);
  // Thread context: the image thread (its own message and buffer; lcm_publish is thread-safe).
  bool publish_image(const ImageSlot& slot, RawFrameEncoder& encoder);
  // The caller fills status() and then publishes it.
  laserline::status_t& status() { return status_; }
  bool publish_status();
  bool publish_calibration();

 private:
  template <typename Message>
  bool publish(lcm::LCM& lcm, const std::string& channel, const Message& message,
               std::vector<std::uint8_t>& buffer);

  lcm::LCM& lcm_;
  lcm::LCM& image_lcm_;
  PublisherChannels channels_;
  laserline::profile_t profile_;
  laserline::image_t image_;
  laserline::status_t status_;
  laserline::calibration_t calibration_;
  std::vector<std::uint8_t> buffer_;        // profiles and status (publisher thread)
  std::vector<std::uint8_t> image_buffer_;  // raw frames (image thread)
};

// Creates the LCM instance for `url`, or returns null with why in *error ("cannot open 'URL':
// ..."). LCM prints its own complaints on stderr, several lines per attempt; they are taken into
// that one line (and passed on to stderr when the instance is good after all). A tcpq:// instance
// whose hub did not answer is refused: LCM would try to connect again, and say so in three lines,
// on every message. Thread context: at start, before other threads write to stderr.
std::unique_ptr<lcm::LCM> open_lcm(const std::string& url, std::string* error);

// This process's id in status_t and profile_t: 64 random bits drawn once, never 0, so that two
// daemons publishing on the same channels can be told apart.
std::int64_t process_instance_id();

// Microseconds since the Unix epoch of a frame's exposure (LCM's utime convention).
std::int64_t frame_utime(const hal::FrameInfo& info);

}  // namespace laserline::daemon
