#include "tools/view_state.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>

#include "tools/view_json.hpp"

namespace laserline::view {

namespace {

// Points of one profile kept for the 3-D view (every n-th): enough for the shape, small to send.
constexpr std::size_t kCloudPointsPerProfile = 160;
constexpr std::size_t kRecentProfiles = 64;  // to pair a raw frame with its profile
constexpr int kJpegQuality = 85;

}  // namespace

void LiveState::receive(int c, const void* data, std::size_t size) {
  std::string problem;
  bool ok = false;
  if (c == kProfile) {
    auto p = std::make_shared<laserline::profile_t>();
    ok = laserline::messages::decode(data, size, p.get(), limits_, &problem);
    if (ok) store_profile(std::move(p));
  } else if (c == kImage) {
    auto image = std::make_shared<laserline::image_t>();
    ok = laserline::messages::decode(data, size, image.get(), limits_, &problem);
    if (ok) {
      std::lock_guard<std::mutex> lock(mutex_);
      image_ = std::move(image);
      ++image_count_;
    }
  } else {
    auto s = std::make_shared<laserline::status_t>();
    ok = laserline::messages::decode(data, size, s.get(), limits_, &problem);
    if (ok) {
      std::lock_guard<std::mutex> lock(mutex_);
      status_ = std::move(s);
      ++status_count_;
    }
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    Channel& channel = channels_[c];
    ++channel.received;
    channel.last = Clock::now();
    if (!ok) {
      ++channel.malformed;
      last_problem_ = channel.name + ": " + problem + "; skipped";
    }
  }
  if (!ok) problems_.report(channels_[c].name, channels_[c].name + ": " + problem + "; skipped");
  changed_.notify_all();
}

void LiveState::store_profile(std::shared_ptr<laserline::profile_t> p) {
  CloudChunk chunk{0, Clock::now(), p->utime, {}};
  std::size_t with_xyz = 0;
  for (const auto& pt : p->points) {
    if (pt.valid && std::isfinite(pt.xyz[0]) && std::isfinite(pt.xyz[1]) &&
        std::isfinite(pt.xyz[2])) {
      ++with_xyz;
    }
  }
  const std::size_t step =
      std::max<std::size_t>(1, (with_xyz + kCloudPointsPerProfile - 1) / kCloudPointsPerProfile);
  std::size_t k = 0;
  for (const auto& pt : p->points) {
    if (!pt.valid || !std::isfinite(pt.xyz[0]) || !std::isfinite(pt.xyz[1]) ||
        !std::isfinite(pt.xyz[2])) {
      continue;
    }
    if (k++ % step != 0) continue;
    for (int i = 0; i < 3; ++i)
      chunk.xyz_mm.push_back(pt.xyz[i] * 1000.0f);
  }
  std::lock_guard<std::mutex> lock(mutex_);
  chunk.index = ++profile_count_;
  if (!chunk.xyz_mm.empty()) cloud_.push_back(std::move(chunk));
  while (!cloud_.empty() && cloud_.front().received < Clock::now() - history_)
    cloud_.pop_front();
  recent_.push_back(p);
  if (recent_.size() > kRecentProfiles) recent_.pop_front();
  profile_ = std::move(p);
}

std::string LiveState::status_json(const laserline::status_t& s) const {
  char instance[24];
  std::snprintf(instance, sizeof instance, "%016llx",
                static_cast<unsigned long long>(s.instance_id));
  JsonObject o;
  o.integer("utime", s.utime)
      .integer("uptime_us", s.uptime_us)
      .string("camera_backend", s.camera_backend)
      .string("detector", s.detector)
      .string("camera_state", s.camera_state)
      .boolean("laser_on", s.laser_on)
      .integer("laser_switches", s.laser_switches)
      .integer("frames_captured", s.frames_captured)
      .integer("frames_processed", s.frames_processed)
      .integer("frames_dropped", s.frames_dropped)
      .integer("profiles_published", s.profiles_published)
      .integer("profiles_dropped", s.profiles_dropped)
      .integer("images_published", s.images_published)
      .integer("images_dropped", s.images_dropped)
      .integer("grab_timeouts", s.grab_timeouts)
      .integer("grab_errors", s.grab_errors)
      .integer("publish_errors", s.publish_errors)
      .integer("laser_safety_offs", s.laser_safety_offs)
      .integer("laser_errors", s.laser_errors)
      .number("frame_rate_hz", s.frame_rate_hz, 2)
      .number("points_per_profile", s.points_per_profile, 1)
      .integer("latency_samples", s.latency_samples)
      .number("latency_p50_ms", s.latency_p50_ms, 2)
      .number("latency_p99_ms", s.latency_p99_ms, 2)
      .number("latency_max_ms", s.latency_max_ms, 2)
      .number("pipeline_p50_ms", s.pipeline_p50_ms, 2)
      .number("pipeline_p99_ms", s.pipeline_p99_ms, 2)
      .number("pipeline_max_ms", s.pipeline_max_ms, 2)
      .number("cpu_percent", s.cpu_percent, 1)
      .integer("frames_over_budget", s.frames_over_budget)
      .number("processing_max_ms", s.processing_max_ms, 2)
      .integer("laser_late_switches", s.laser_late_switches)
      .integer("camera_reconnects", s.camera_reconnects)
      .integer("camera_missing_packets", s.camera_missing_packets)
      .integer("camera_timeouts", s.camera_timeouts)
      .integer("camera_size_mismatches", s.camera_size_mismatches)
      .integer("camera_underruns", s.camera_underruns)
      .integer("camera_other_errors", s.camera_other_errors)
      .integer("camera_skipped_frames", s.camera_skipped_frames)
      .integer("bad_messages", s.bad_messages)
      .integer("bad_frames", s.bad_frames)
      .string("instance_id", instance);
  return o.str();
}

// Points in the camera frame (mm) for the plot, and the 3-D chunks after `cloud_after`.
std::string LiveState::profile_json(const laserline::profile_t& p, std::int64_t cloud_after,
                                    std::int64_t* cloud_sent) const {
  std::vector<float> xz, candidates_xz, uv;
  std::int64_t valid = 0;
  for (const auto& pt : p.points) {
    if (pt.valid) ++valid;
    uv.push_back(static_cast<float>(pt.u));
    uv.push_back(pt.v);
    if (!std::isfinite(pt.xyz[0]) || !std::isfinite(pt.xyz[2])) continue;
    auto& out = pt.valid ? xz : candidates_xz;
    out.push_back(pt.xyz[0] * 1000.0f);
    out.push_back(pt.xyz[2] * 1000.0f);
  }
  std::string cloud = "[";
  for (const auto& chunk : cloud_) {
    if (chunk.index <= cloud_after) continue;
    if (cloud.size() > 1) cloud += ',';
    // Ages by exposure time from the newest profile, and that one's by the clock here (a replay's
    // or another computer's clock is not this one's).
    const CloudChunk& newest = cloud_.back();
    const double age_ms =
        std::chrono::duration<double, std::milli>(Clock::now() - newest.received).count() +
        std::max(0.0, static_cast<double>(newest.utime - chunk.utime) * 1e-3);
    cloud += JsonObject().number("age_ms", age_ms, 0).raw("xyz", numbers(chunk.xyz_mm, 0)).str();
    *cloud_sent = chunk.index;
  }
  cloud += "]";
  JsonObject o;
  o.integer("sequence", p.sequence)
      .integer("utime", p.utime)
      .boolean("laser_on", p.laser_on)
      .string("detector", p.detector)
      .integer("width", p.width)
      .integer("height", p.height)
      .integer("points", p.num_points)
      .integer("valid", valid)
      .raw("xz", numbers(xz, 1))
      .raw("candidates_xz", numbers(candidates_xz, 1))
      .raw("cloud", cloud);
  // Pixels where nothing is triangulated: the plot shows the line in the image then.
  if (xz.empty() && candidates_xz.empty()) o.raw("uv", numbers(uv, 2));
  return o.str();
}

// The frame's description and its profile's points in the frame's own pixels.
std::string LiveState::frame_json(const laserline::image_t& image) const {
  const laserline::profile_t* match = nullptr;
  for (const auto& p : recent_) {
    if (p->sequence == image.sequence) match = p.get();
  }
  std::vector<float> points, candidates;
  if (match != nullptr) {
    // Points are in full-frame pixels; the frame may be a region, downscaled by block means
    // (a block's centre is at k*i + (k-1)/2).
    const double k = image.downscale > 1 ? image.downscale : 1;
    const double x0 = image.roi_x + (k - 1) / 2, y0 = image.roi_y + (k - 1) / 2;
    for (const auto& pt : match->points) {
      const double x = match->search_origin[0] + pt.u * match->search_line_step[0] +
                       pt.v * match->search_along[0];
      const double y = match->search_origin[1] + pt.u * match->search_line_step[1] +
                       pt.v * match->search_along[1];
      auto& out = pt.valid ? points : candidates;
      out.push_back(static_cast<float>((x - x0) / k));
      out.push_back(static_cast<float>((y - y0) / k));
    }
  }
  JsonObject o;
  o.integer("sequence", image.sequence)
      .integer("utime", image.utime)
      .boolean("laser_on", image.laser_on)
      .integer("width", image.width)
      .integer("height", image.height)
      .integer("roi_x", image.roi_x)  // where the image lies in the camera's frame
      .integer("roi_y", image.roi_y)
      .integer("downscale", image.downscale > 1 ? image.downscale : 1)
      .boolean("profile", match != nullptr)
      .raw("points", numbers(points, 1))
      .raw("candidates", numbers(candidates, 1));
  return o.str();
}

std::string LiveState::viewer_json() const {
  const auto now = Clock::now();
  std::string channels = "[";
  for (const auto& c : channels_) {
    if (channels.size() > 1) channels += ',';
    const double age_s = c.received > 0 ? std::chrono::duration<double>(now - c.last).count() : NAN;
    channels += JsonObject()
                    .string("name", c.name)
                    .integer("received", c.received)
                    .integer("malformed", c.malformed)
                    .number("age_s", age_s, 1)
                    .str();
  }
  channels += "]";
  return JsonObject()
      .raw("channels", channels)
      .string("last_problem", last_problem_)
      .integer("streams", open_streams_)
      .number("uptime_s", std::chrono::duration<double>(now - started_).count(), 0)
      .number("history_s", std::chrono::duration<double>(history_).count(), 1)
      .str();
}

std::string LiveState::Stream::next(bool* stopping) {
  std::unique_lock<std::mutex> lock(state_.mutex_);
  std::string out;
  auto event = [&out](const char* name, const std::string& data) {
    out += "event: ";
    out += name;
    out += "\ndata: ";
    out += data;
    out += "\n\n";
  };
  if (!started_) {
    started_ = true;
    out += "retry: 2000\n\n";
  }
  const auto give_up = Clock::now() + std::chrono::seconds(1);
  while (true) {
    if (state_.stopping_) {
      *stopping = true;
      return "";
    }
    const auto now = Clock::now();
    if (now >= next_viewer_) {
      event("viewer", state_.viewer_json());
      next_viewer_ = now + std::chrono::seconds(1);
    }
    if (state_.status_ && state_.status_count_ != status_sent_) {
      event("status", state_.status_json(*state_.status_));
      status_sent_ = state_.status_count_;
    }
    if (state_.profile_ && state_.profile_count_ != profile_sent_ && now >= next_profile_) {
      event("profile", state_.profile_json(*state_.profile_, cloud_sent_, &cloud_sent_));
      profile_sent_ = state_.profile_count_;
      next_profile_ = now + profile_period_;
    }
    if (state_.image_ && state_.image_count_ != frame_sent_ && now >= next_frame_) {
      event("frame", state_.frame_json(*state_.image_));
      frame_sent_ = state_.image_count_;
      next_frame_ = now + frame_period_;
    }
    if (!out.empty() || now >= give_up) return out;
    // Until something arrives, or what arrived earlier becomes due.
    auto wake = std::min(give_up, next_viewer_);
    if (state_.profile_count_ != profile_sent_) wake = std::min(wake, next_profile_);
    if (state_.image_count_ != frame_sent_) wake = std::min(wake, next_frame_);
    const std::int64_t seen = state_.profile_count_ + state_.image_count_ + state_.status_count_;
    state_.changed_.wait_until(lock, wake, [&] {
      return state_.stopping_ ||
             state_.profile_count_ + state_.image_count_ + state_.status_count_ != seen;
    });
  }
}

std::shared_ptr<const EncodedFrame> LiveState::frame_jpeg(std::string* problem) {
  std::shared_ptr<const laserline::image_t> image;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    image = image_;
    if (!image) {
      *problem = "no raw frame received yet on " + channels_[kImage].name;
      return nullptr;
    }
    if (encoded_ && encoded_->sequence == image->sequence) return encoded_;
  }
  std::lock_guard<std::mutex> encoding(encode_mutex_);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (encoded_ && encoded_->sequence == image->sequence) return encoded_;
  }
  cv::Mat pixels;
  if (!laserline::messages::unpack_image(*image, limits_, cv::IMREAD_UNCHANGED, &pixels, problem)) {
    *problem =
        channels_[kImage].name + ": frame " + std::to_string(image->sequence) + ": " + *problem;
    return nullptr;
  }
  if (pixels.depth() == CV_16U) pixels.convertTo(pixels, CV_8U, 1.0 / 256.0);
  auto encoded = std::make_shared<EncodedFrame>();
  encoded->sequence = image->sequence;
  std::vector<unsigned char> bytes;
  if (!cv::imencode(".jpg", pixels, bytes, {cv::IMWRITE_JPEG_QUALITY, kJpegQuality})) {
    *problem = "frame " + std::to_string(image->sequence) + " does not encode as JPEG";
    return nullptr;
  }
  encoded->jpeg.assign(bytes.begin(), bytes.end());
  std::lock_guard<std::mutex> lock(mutex_);
  encoded_ = encoded;
  return encoded;
}

}  // namespace laserline::view
