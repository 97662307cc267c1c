#include "daemon/frame_path.hpp"

#include <pthread.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "daemon/thread_priorities.hpp"
#include "hal/clock.hpp"
#include "pipeline/image_view.hpp"

namespace laserline::daemon {

namespace {

constexpr std::int64_t kMs = 1'000'000;

// A recording (Camera::paced_by_consumer()) waits for room in a ring instead of dropping; it is
// not a real-time source, so a short sleep is the right way to wait.
template <typename T>
T* claim_waiting(SpscRing<T>& ring, const std::atomic<bool>& stopping) {
  T* slot = ring.try_claim();
  while (slot == nullptr && !stopping.load(std::memory_order_relaxed)) {
    const timespec pause{0, 200'000};
    nanosleep(&pause, nullptr);
    slot = ring.try_claim();
  }
  return slot;
}

// Names the thread and, when asked, gives it its real-time priority and CPUs. Returns "" or why
// the system refused.
std::string configure_thread(pthread_t thread, const ThreadSpec& spec, bool realtime,
                             const std::vector<int>& cpus) {
  pthread_setname_np(thread, spec.name);
  if (!realtime || spec.fifo_priority == 0) return "";
  if (!cpus.empty()) {
    cpu_set_t set;
    CPU_ZERO(&set);
    for (int cpu : cpus)
      CPU_SET(cpu, &set);
    if (const int e = pthread_setaffinity_np(thread, sizeof(set), &set); e != 0) {
      return std::string("realtime.cpus: cannot pin ") + spec.name + ": " + std::strerror(e);
    }
  }
  sched_param param{};
  param.sched_priority = spec.fifo_priority;
  if (const int e = pthread_setschedparam(thread, SCHED_FIFO, &param); e != 0) {
    return std::string("realtime.enabled: cannot give ") + spec.name + " SCHED_FIFO priority " +
           std::to_string(spec.fifo_priority) + ": " + std::strerror(e) +
           " (needs CAP_SYS_NICE or LimitRTPRIO)";
  }
  return "";
}

}  // namespace

const char* to_string(CameraState state) {
  switch (state) {
    case CameraState::kStarting:
      return "starting";
    case CameraState::kStreaming:
      return "streaming";
    case CameraState::kTimeout:
      return "timeout";
    case CameraState::kError:
      return "error";
    case CameraState::kStopped:
      return "stopped";
  }
  return "unknown";
}

FramePath::FramePath(const DaemonConfig& config, hal::Camera& camera, hal::Laser& laser,
                     pipeline::Detector& detector, lcm::LCM& lcm)
    : config_(config),
      camera_(camera),
      laser_(laser),
      strobe_(laser.strobe()),
      detector_(&detector),
      lcm_(lcm),
      commands_(camera, counters_.camera_state),
      parts_(config.worker_threads) {}

FramePath::~FramePath() {
  stop();
}

bool FramePath::start(std::string* error) {
  format_ = camera_.format();
  frame_rate_hz_ =
      camera_.own_frame_rate_hz() > 0 ? camera_.own_frame_rate_hz() : config_.frame_rate_hz;
  try {
    detector_->use_parts(parts_);
    detector_->reset(format_.width, format_.height);  // allocates: before any thread runs
  } catch (const std::exception& e) {
    // E.g. a camera whose frames are not the size the calibration describes.
    if (error != nullptr) *error = std::string("detector ") + detector_->name() + ": " + e.what();
    return false;
  }
  const std::size_t max_points = detector_->max_points(format_.width, format_.height);

  FrameSlot frame_prototype;
  frame_prototype.pixels.assign(format_.bytes(), 0);
  frames_ = std::make_unique<SpscRing<FrameSlot>>(config_.frame_slots, frame_prototype);
  ProfileSlot profile_prototype{{}, format_.width, format_.height, pipeline::Profile(max_points)};
  profiles_ = std::make_unique<SpscRing<ProfileSlot>>(config_.profile_slots, profile_prototype);
  // Detectors that look at earlier frames must see every frame, even one whose profile has no slot.
  unpublished_profile_ = pipeline::Profile(max_points);
  ImageSlot image_prototype{{}, format_, std::vector<std::uint8_t>(format_.bytes(), 0)};
  images_ = std::make_unique<SpscRing<ImageSlot>>(config_.image_slots, image_prototype);
  // A second instance only where it is a second socket; a file:// log must have one writer.
  if (config_.raw_frames.every_n > 0 && config_.lcm_url.rfind("udpm://", 0) == 0) {
    image_lcm_ = std::make_unique<lcm::LCM>(config_.lcm_url);
    if (!image_lcm_->good()) {
      if (error != nullptr)
        *error = "lcm.url: cannot open '" + config_.lcm_url + "' for raw frames";
      return false;
    }
  }
  publisher_ = std::make_unique<LcmPublisher>(
      lcm_, image_lcm_.get(),
      PublisherChannels{config_.profile_channel, config_.image_channel, config_.status_channel,
                        config_.calibration_channel, config_.profile_all_points},
      config_.detector, max_points, format_, config_.calibration);
  publisher_->status().camera_backend = config_.camera_backend;
  publisher_->status().strobe_state.reserve(kStrobeLineBytes);
  encoder_ = std::make_unique<RawFrameEncoder>(config_.raw_frames, format_);
  // Enough room for every frame of a status period at 4x the nominal rate (a memory camera's
  // rate can be far beyond what the frame path takes: at most 2^20 samples, 8 MB).
  const auto window = static_cast<std::size_t>(
      std::min(std::ceil(frame_rate_hz_ * config_.status_period_s * 4.0) + 64, 1048576.0));
  latency_ = std::make_unique<LatencyStats>(window);
  pipeline_ = std::make_unique<LatencyStats>(window);

  start_mono_ns_ = hal::monotonic_ns();
  counters_.last_frame_mono_ns.store(start_mono_ns_, std::memory_order_relaxed);
  stopping_.store(false);
  worker_done_.store(false);
  source_ended_.store(false);
  images_done_.store(false);
  stop_requested_.store(false);
  running_.store(true);
  // Consumers first, so that nothing is produced before someone can take it.
  publisher_thread_ = std::thread([this] { publisher_loop(); });
  image_thread_ = std::thread([this] { image_loop(); });
  // The CPUs its threads are pinned to, else the process's.
  parts_.start(config_.realtime ? static_cast<int>(config_.cpus.size()) : 0);
  worker_thread_ = std::thread([this] { worker_loop(); });
  camera_thread_ = std::thread([this] { camera_loop(); });
  for (auto [thread, spec] :
       {std::pair{&publisher_thread_, kPublisherThread}, std::pair{&image_thread_, kImageThread},
        std::pair{&worker_thread_, kWorkerThread}, std::pair{&camera_thread_, kCameraThread}}) {
    const std::string problem =
        configure_thread(thread->native_handle(), spec, config_.realtime, config_.cpus);
    if (!problem.empty()) {
      stop();
      if (error != nullptr) *error = problem;
      return false;
    }
  }
  for (std::size_t i = 0; i < parts_.helpers().size(); ++i) {
    const pthread_t helper = parts_.helpers()[i].native_handle();
    const std::string problem =
        configure_thread(helper, kWorkerHelperThread, config_.realtime, config_.cpus);
    pthread_setname_np(helper, (kWorkerHelperThread.name + std::to_string(i + 1)).c_str());
    if (!problem.empty()) {
      stop();
      if (error != nullptr) *error = problem;
      return false;
    }
  }
  if (strobe_ != nullptr && strobe_->native_thread() != pthread_t{}) {
    const std::string problem =
        configure_thread(strobe_->native_thread(), kStrobeThread, config_.realtime, config_.cpus);
    if (!problem.empty()) {
      stop();
      if (error != nullptr) *error = problem;
      return false;
    }
  }
  return true;
}

void FramePath::stop() {
  if (!running_.exchange(false)) return;
  stop_requested_.store(true);
  stopping_.store(true);
  camera_.stop();
  if (camera_thread_.joinable()) camera_thread_.join();
  switch_laser(false, 0);
  frames_->wake();
  if (worker_thread_.joinable()) worker_thread_.join();
  parts_.stop();
  profiles_->wake();
  if (publisher_thread_.joinable()) publisher_thread_.join();
  images_->wake();
  if (image_thread_.joinable()) image_thread_.join();
}

bool FramePath::desired_laser(LaserMode mode, std::uint64_t grab_index) const {
  switch (mode) {
    case LaserMode::kOn:
      return true;
    case LaserMode::kOff:
      return false;
    case LaserMode::kAlternate:
      return grab_index % 2 == 0;
    case LaserMode::kPattern:
      return config_.laser_pattern[grab_index % config_.laser_pattern.size()];
  }
  return false;
}

void FramePath::switch_laser(bool on, std::uint64_t for_frame, hal::LaserSwitch* record) {
  if (laser_.set(on, for_frame, record)) {
    counters_.laser_switches.fetch_add(1, std::memory_order_relaxed);
  } else {
    counters_.laser_errors.fetch_add(1, std::memory_order_relaxed);
  }
}

void FramePath::enforce_laser_safety() {
  const std::int64_t age =
      hal::monotonic_ns() - counters_.last_frame_mono_ns.load(std::memory_order_relaxed);
  if (laser_.is_on() && age > config_.laser_frame_timeout_ms * kMs) {
    switch_laser(false, 0);
    counters_.laser_safety_offs.fetch_add(1, std::memory_order_relaxed);
  }
}

void FramePath::camera_loop() {
  // Where frames go when the worker is behind: the camera must still be drained.
  std::vector<std::uint8_t> overflow(format_.bytes());
  hal::FrameInfo overflow_info;
  const std::chrono::milliseconds timeout(config_.grab_timeout_ms);
  std::uint64_t grab_index = 0;
  const bool lossless = camera_.paced_by_consumer();
  bool frames_flowing = true;  // until a grab fails; the laser stays off until frames return
  LaserMode laser_mode = config_.laser_mode;
  hal::FrameLaserDecider laser_decider(strobe_, frame_rate_hz_);
  auto switch_recorded = [&](bool on) {
    hal::LaserSwitch record;
    record.mono_ns = 0;
    switch_laser(on, grab_index, &record);
    if (record.mono_ns == 0) return;  // refused: is_on() says on, the next frame tries again
    laser_decider.switched(record);
  };

  while (!stopping_.load(std::memory_order_relaxed)) {
    commands_.run_camera_commands(laser_mode, frames_flowing, grab_index);
    const bool want_laser = frames_flowing && desired_laser(laser_mode, grab_index);
    if (want_laser != laser_.is_on()) switch_recorded(want_laser);

    FrameSlot* slot = lossless ? claim_waiting(*frames_, stopping_) : frames_->try_claim();
    if (lossless && slot == nullptr) break;  // stopping
    std::span<std::uint8_t> pixels =
        slot != nullptr ? std::span<std::uint8_t>(slot->pixels) : std::span<std::uint8_t>(overflow);
    hal::FrameInfo& info = slot != nullptr ? slot->info : overflow_info;
    info.laser_on = want_laser;  // cameras that observe the laser themselves overwrite it
    const hal::GrabStatus status = camera_.grab(pixels, info, timeout);
    switch (status) {
      case hal::GrabStatus::kOk: {
        const hal::FrameLaserDecider::Decision decided = laser_decider.decide(info, grab_index);
        if (decided.late_switch) {
          counters_.laser_late_switches.fetch_add(1, std::memory_order_relaxed);
        }
        if (strobe_ != nullptr) {
          (decided.matched ? counters_.strobe_matched : counters_.strobe_unmatched)
              .fetch_add(1, std::memory_order_relaxed);
        }
        ++grab_index;
        frames_flowing = true;
        counters_.frames_captured.fetch_add(1, std::memory_order_relaxed);
        counters_.last_frame_mono_ns.store(info.arrival_mono_ns, std::memory_order_relaxed);
        counters_.camera_state.store(CameraState::kStreaming, std::memory_order_relaxed);
        if (slot != nullptr) {
          frames_->publish();
        } else {
          counters_.frames_dropped.fetch_add(1, std::memory_order_relaxed);
        }
        break;
      }
      case hal::GrabStatus::kTimeout:
        frames_flowing = false;
        laser_decider.frames_stopped();
        if (laser_.is_on()) switch_recorded(false);
        counters_.grab_timeouts.fetch_add(1, std::memory_order_relaxed);
        counters_.camera_state.store(CameraState::kTimeout, std::memory_order_relaxed);
        break;
      case hal::GrabStatus::kError:
        frames_flowing = false;
        laser_decider.frames_stopped();
        if (laser_.is_on()) switch_recorded(false);
        counters_.grab_errors.fetch_add(1, std::memory_order_relaxed);
        counters_.camera_state.store(CameraState::kError, std::memory_order_relaxed);
        {
          // A camera that fails at once must not turn this thread into a busy loop.
          const timespec backoff{0, 10'000'000};
          nanosleep(&backoff, nullptr);
        }
        break;
      case hal::GrabStatus::kStopped:
        if (!stopping_.load(std::memory_order_relaxed)) {
          source_ended_.store(true, std::memory_order_release);
        }
        stopping_.store(true, std::memory_order_relaxed);
        break;
    }
  }
  if (laser_.is_on()) switch_laser(false, grab_index);
  counters_.camera_state.store(CameraState::kStopped, std::memory_order_relaxed);
}

void FramePath::worker_loop() {
  std::int64_t processed = 0;
  const bool lossless = camera_.paced_by_consumer();
  const auto budget_ns = static_cast<std::int64_t>(1e9 / frame_rate_hz_);
  // Raw frames at most this often (arrival times, so no clock read here).
  const std::int64_t image_interval_ns =
      config_.raw_frames.max_rate_hz > 0
          ? static_cast<std::int64_t>(1e9 / config_.raw_frames.max_rate_hz)
          : 0;
  std::int64_t last_image_ns = INT64_MIN / 2;
  while (true) {
    commands_.run_worker_commands(detector_);
    if (!frames_->wait(100 * kMs)) {
      if (stopping_.load(std::memory_order_acquire)) break;
      continue;
    }
    FrameSlot* frame = frames_->front();
    const pipeline::ImageView view{frame->pixels.data(), format_.width, format_.height,
                                   format_.stride};
    const RawFrameOptions& raw = config_.raw_frames;
    if (raw.every_n > 0 && processed % raw.every_n == 0 &&
        frame->info.arrival_mono_ns - last_image_ns >= image_interval_ns) {
      last_image_ns = frame->info.arrival_mono_ns;
      if (ImageSlot* image =
              lossless ? claim_waiting(*images_, stop_requested_) : images_->try_claim()) {
        image->info = frame->info;
        image->format = format_;
        std::memcpy(image->pixels.data(), frame->pixels.data(), format_.bytes());
        images_->publish();
      } else {
        counters_.images_dropped.fetch_add(1, std::memory_order_relaxed);
      }
    }
    const pipeline::FrameContext context{frame->info.sequence, frame->info.laser_on};
    ProfileSlot* out =
        lossless ? claim_waiting(*profiles_, stop_requested_) : profiles_->try_claim();
    {
      const std::int64_t t0 = hal::monotonic_ns();  // vDSO clock read, no syscall
      detector_->detect(view, context, out ? out->profile : unpublished_profile_);
      const std::int64_t took = hal::monotonic_ns() - t0;
      if (took > budget_ns) counters_.frames_over_budget.fetch_add(1, std::memory_order_relaxed);
      if (took > counters_.processing_max_ns.load(std::memory_order_relaxed)) {
        counters_.processing_max_ns.store(took, std::memory_order_relaxed);
      }
    }
    if (out) {
      out->info = frame->info;
      out->width = format_.width;
      out->height = format_.height;
      profiles_->publish();
    } else {
      counters_.profiles_dropped.fetch_add(1, std::memory_order_relaxed);
    }
    ++processed;
    counters_.frames_processed.fetch_add(1, std::memory_order_relaxed);
    frames_->pop();
  }
  worker_done_.store(true, std::memory_order_release);
  profiles_->wake();
  images_->wake();
}

void FramePath::fill_status(std::int64_t now_mono, std::int64_t period_ns) {
  laserline::status_t& s = publisher_->status();
  s.utime = hal::wall_ns() / 1000;
  s.uptime_us = (now_mono - start_mono_ns_) / 1000;
  s.camera_state = to_string(counters_.camera_state.load(std::memory_order_relaxed));
  s.laser_on = laser_.is_on();
  s.laser_switches = counters_.laser_switches.load(std::memory_order_relaxed);
  s.frames_captured = counters_.frames_captured.load(std::memory_order_relaxed);
  s.frames_processed = counters_.frames_processed.load(std::memory_order_relaxed);
  s.frames_dropped = counters_.frames_dropped.load(std::memory_order_relaxed);
  s.profiles_published = profiles_published_.load(std::memory_order_relaxed);
  s.profiles_dropped = counters_.profiles_dropped.load(std::memory_order_relaxed);
  s.images_published = images_published_.load(std::memory_order_relaxed);
  s.images_dropped = counters_.images_dropped.load(std::memory_order_relaxed);
  s.grab_timeouts = counters_.grab_timeouts.load(std::memory_order_relaxed);
  s.grab_errors = counters_.grab_errors.load(std::memory_order_relaxed);
  s.publish_errors = publish_errors_.load(std::memory_order_relaxed);
  s.laser_safety_offs = counters_.laser_safety_offs.load(std::memory_order_relaxed);
  s.laser_errors = counters_.laser_errors.load(std::memory_order_relaxed);
  s.laser_late_switches = counters_.laser_late_switches.load(std::memory_order_relaxed);
  {
    const std::int64_t matched = counters_.strobe_matched.load(std::memory_order_relaxed);
    const std::int64_t unmatched = counters_.strobe_unmatched.load(std::memory_order_relaxed);
    char line[kStrobeLineBytes];
    describe_strobe(now_mono, matched - last_status_matched_, unmatched - last_status_unmatched_,
                    line, sizeof line);
    s.strobe_state.assign(line);  // within the capacity reserved at start: no allocation
    s.strobe_unmatched_frames = unmatched;
    last_status_matched_ = matched;
    last_status_unmatched_ = unmatched;
  }
  const hal::CameraHealth health = camera_.health();
  s.camera_reconnects = health.reconnects;
  s.camera_missing_packets = health.missing_packets;
  s.camera_timeouts = health.timeouts;
  s.camera_size_mismatches = health.size_mismatches;
  s.camera_underruns = health.underruns;
  s.camera_other_errors = health.other_errors;
  s.camera_skipped_frames = health.skipped_frames;
  s.bad_messages = health.bad_messages + counters_.bad_commands.load(std::memory_order_relaxed);
  s.bad_frames = health.bad_frames;
  const double seconds = static_cast<double>(std::max<std::int64_t>(period_ns, 1)) * 1e-9;
  s.frame_rate_hz =
      static_cast<float>(static_cast<double>(s.frames_processed - last_status_frames_) / seconds);
  last_status_frames_ = s.frames_processed;
  s.points_per_profile = profiles_in_period_ > 0 ? static_cast<float>(points_in_period_) /
                                                       static_cast<float>(profiles_in_period_)
                                                 : 0.0f;
  points_in_period_ = 0;
  profiles_in_period_ = 0;
  const LatencySummary window = latency_->take_window();
  s.latency_samples = static_cast<std::int32_t>(window.samples);
  s.latency_p50_ms = static_cast<float>(window.p50_ms);
  s.latency_p99_ms = static_cast<float>(window.p99_ms);
  s.latency_max_ms = static_cast<float>(window.max_ms);
  s.cpu_percent = static_cast<float>(cpu_.percent_since_last());
  s.frames_over_budget = counters_.frames_over_budget.load(std::memory_order_relaxed);
  // The worker only raises it; a racing store may keep one frame's figure a period longer.
  s.processing_max_ms = static_cast<float>(
      static_cast<double>(counters_.processing_max_ns.exchange(0, std::memory_order_relaxed)) *
      1e-6);
  const LatencySummary pipeline = pipeline_->take_window();
  s.pipeline_p50_ms = static_cast<float>(pipeline.p50_ms);
  s.pipeline_p99_ms = static_cast<float>(pipeline.p99_ms);
  s.pipeline_max_ms = static_cast<float>(pipeline.max_ms);
}

void FramePath::describe_strobe(std::int64_t now_mono, std::int64_t matched, std::int64_t unmatched,
                                char* out, std::size_t size) const {
  if (size == 0) return;
  out[0] = '\0';
  if (strobe_ == nullptr) return;
  hal::describe_strobe_health(*strobe_, frame_rate_hz_, now_mono, matched, unmatched, out, size);
}

void FramePath::publisher_loop() {
  const auto period_ns = static_cast<std::int64_t>(config_.status_period_s * 1e9);
  std::int64_t last_status = hal::monotonic_ns();
  std::int64_t next_status = last_status + period_ns;
  // The calibration first, before any profile that names it; then periodically, so that a log
  // started later (or a subscriber that joined late) has it too. It cannot change while running.
  const auto calibration_period_ns = static_cast<std::int64_t>(config_.calibration_period_s * 1e9);
  if (!publisher_->publish_calibration()) publish_errors_.fetch_add(1, std::memory_order_relaxed);
  std::int64_t next_calibration = last_status + calibration_period_ns;
  while (true) {
    const std::int64_t wait_ns = std::clamp<std::int64_t>(
        std::min(next_status, next_calibration) - hal::monotonic_ns(), 0, 100 * kMs);
    profiles_->wait(wait_ns);
    while (ProfileSlot* slot = profiles_->front()) {
      if (publisher_->publish_profile(*slot)) {
        const std::int64_t published = hal::monotonic_ns();
        latency_->add(published - slot->info.exposure_mono_ns);
        pipeline_->add(published - slot->info.arrival_mono_ns);
        profiles_published_.fetch_add(1, std::memory_order_relaxed);
        points_in_period_ += static_cast<std::int64_t>(slot->profile.size());
        ++profiles_in_period_;
      } else {
        publish_errors_.fetch_add(1, std::memory_order_relaxed);
      }
      profiles_->pop();
    }
    const std::int64_t now = hal::monotonic_ns();
    const bool finished = worker_done_.load(std::memory_order_acquire) &&
                          profiles_->front() == nullptr &&
                          // The last status waits for raw frames at the end of a recording,
                          // not when stopped: a frame being compressed must not hold it back.
                          (images_done_.load(std::memory_order_acquire) ||
                           stop_requested_.load(std::memory_order_relaxed));
    if (now >= next_calibration) {
      if (!publisher_->publish_calibration()) {
        publish_errors_.fetch_add(1, std::memory_order_relaxed);
      }
      next_calibration =
          std::max(next_calibration + calibration_period_ns, now + calibration_period_ns / 2);
    }
    if (now >= next_status || finished) {
      fill_status(now, now - last_status);
      if (!publisher_->publish_status()) publish_errors_.fetch_add(1, std::memory_order_relaxed);
      last_status = now;
      next_status = std::max(next_status + period_ns, now + period_ns / 2);
    }
    if (finished) break;
  }
  final_latency_ = latency_->total();
  final_pipeline_ = pipeline_->total();
}

void FramePath::image_loop() {
  // Normal scheduling even when the process was started real-time (the unit's
  // CPUSchedulingPolicy=fifo): a compressing thread at the publisher's FIFO priority would hold
  // it up. Nice rather than SCHED_IDLE: an idle-class thread on a busy machine can take seconds
  // to finish one frame, and stop() waits for it.
  const sched_param normal{};
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);
  setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), kImageThread.nice);
  while (true) {
    if (!images_->wait(100 * kMs)) {
      if (worker_done_.load(std::memory_order_acquire) && images_->front() == nullptr) break;
      continue;
    }
    ImageSlot* image = images_->front();
    if (stop_requested_.load(std::memory_order_relaxed)) {
      // Stopping: frames still queued are not worth delaying the exit for.
      counters_.images_dropped.fetch_add(1, std::memory_order_relaxed);
    } else if (publisher_->publish_image(*image, *encoder_)) {
      images_published_.fetch_add(1, std::memory_order_relaxed);
    } else {
      publish_errors_.fetch_add(1, std::memory_order_relaxed);
    }
    images_->pop();
  }
  images_done_.store(true, std::memory_order_release);
}

FramePathSummary FramePath::summary() const {
  FramePathSummary s;
  s.frames_captured = counters_.frames_captured.load();
  s.frames_processed = counters_.frames_processed.load();
  s.frames_dropped = counters_.frames_dropped.load();
  s.profiles_published = profiles_published_.load();
  s.profiles_dropped = counters_.profiles_dropped.load();
  s.images_published = images_published_.load();
  s.images_dropped = counters_.images_dropped.load();
  s.grab_timeouts = counters_.grab_timeouts.load();
  s.grab_errors = counters_.grab_errors.load();
  s.publish_errors = publish_errors_.load();
  s.laser_safety_offs = counters_.laser_safety_offs.load();
  s.frames_over_budget = counters_.frames_over_budget.load();
  s.laser_switches = counters_.laser_switches.load();
  s.laser_late_switches = counters_.laser_late_switches.load();
  s.strobe_matched = counters_.strobe_matched.load();
  s.strobe_unmatched = counters_.strobe_unmatched.load();
  s.latency = final_latency_;  // complete once stop() returned
  s.pipeline = final_pipeline_;
  return s;
}

}  // namespace laserline::daemon
