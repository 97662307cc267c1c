#include "hal/aravis_camera.hpp"

#include <arv.h>
#include <time.h>

#include <algorithm>

#include "hal/aravis_genicam.hpp"
#include "hal/clock.hpp"

namespace laserline::hal {

namespace {

constexpr std::int64_t kMs = 1'000'000;
// Longest single wait inside grab(), so that stop() is noticed quickly.
constexpr std::int64_t kWaitSliceUs = 50'000;

}  // namespace

AravisCamera::AravisCamera(AravisCameraOptions options)
    : options_(std::move(options)), backoff_(options_.reconnect_min_ms, options_.reconnect_max_ms) {
  format_.width = options_.width;
  format_.height = options_.height;
  format_.stride = options_.width;
  format_.pixel_format = PixelFormat::kMono8;
  pixel_format_index_ = aravis_pixel_format_index(options_.pixel_format);
}

AravisCamera::~AravisCamera() {
  disconnect();
}

void AravisCamera::on_control_lost(_ArvDevice* /*device*/, void* self) {
  static_cast<AravisCamera*>(self)->control_lost_.store(true, std::memory_order_release);
}

bool AravisCamera::open(std::string* error) {
  disconnect();
  if (const std::string problem = aravis_pixel_format_problem(options_); !problem.empty()) {
    if (error != nullptr) *error = "pixel_format '" + options_.pixel_format + "': " + problem;
    return false;
  }
  const SourceFormat& source = aravis_source_format(pixel_format_index_);
  converter_ = PixelConverter(source, options_.width, options_.height, options_.channel);
  payload_bytes_ = converter_.row_bytes() * static_cast<std::size_t>(options_.height);
  memory_.assign(static_cast<std::size_t>(options_.buffers),
                 std::vector<std::uint8_t>(payload_bytes_, 0));
  stopped_.store(false, std::memory_order_release);
  clock_.reset();
  sequence_.reset();
  backoff_.reset();
  return connect(error);
}

bool AravisCamera::connect(std::string* error) {
  GError* e = nullptr;
  const std::string name = options_.device.empty() ? "the first camera found" : options_.device;
  camera_ = arv_camera_new(options_.device.empty() ? nullptr : options_.device.c_str(), &e);
  if (camera_ == nullptr && !options_.device.empty()) {
    // Aravis opens by device id, physical or IP address; a serial number is looked up here.
    arv_update_device_list();
    for (unsigned i = 0; i < arv_get_n_devices() && camera_ == nullptr; ++i) {
      const char* serial = arv_get_device_serial_nbr(i);
      if (serial != nullptr && options_.device == serial) {
        g_clear_error(&e);
        camera_ = arv_camera_new(arv_get_device_id(i), &e);
      }
    }
  }
  if (camera_ == nullptr) {
    const std::string why = take_gerror(e);
    if (error != nullptr) *error = "device '" + name + "': " + (why.empty() ? "not found" : why);
    return false;
  }
  std::string why;
  if (!configure(&why)) {
    if (error != nullptr) *error = "device '" + name + "': " + why;
    disconnect();
    return false;
  }
  control_lost_.store(false, std::memory_order_release);
  control_lost_handler_ = g_signal_connect(arv_camera_get_device(camera_), "control-lost",
                                           G_CALLBACK(on_control_lost), this);
  stream_ = arv_camera_create_stream(camera_, nullptr, nullptr, &e);
  if (stream_ == nullptr) {
    if (error != nullptr) *error = "device '" + name + "': cannot create stream: " + take_gerror(e);
    disconnect();
    return false;
  }
  for (auto& memory : memory_)
    arv_stream_push_buffer(stream_, arv_buffer_new(memory.size(), memory.data()));
  arv_camera_start_acquisition(camera_, &e);
  if (e != nullptr) {
    if (error != nullptr) {
      *error = "device '" + name + "': cannot start acquisition: " + take_gerror(e);
    }
    disconnect();
    return false;
  }
  silent_ns_ = 0;
  // The camera may count frames from anywhere after a reconnect: sequence numbers continue
  // from ours instead.
  sequence_.restart();
  return true;
}

void AravisCamera::disconnect() {
  if (stream_ != nullptr) update_stream_statistics();
  if (camera_ != nullptr) {
    GError* e = nullptr;
    if (stream_ != nullptr) arv_camera_stop_acquisition(camera_, &e);  // fails when it is gone
    g_clear_error(&e);
  }
  if (stream_ != nullptr) {
    guint64 completed = 0, failures = 0, underruns = 0;
    arv_stream_get_statistics(stream_, &completed, &failures, &underruns);
    underruns_base_ += underruns;
    // Unreferencing the stream stops its thread and frees the ArvBuffer wrappers; the pixel
    // memory is ours and stays for the next stream.
    g_object_unref(stream_);
    stream_ = nullptr;
  }
  if (camera_ != nullptr) {
    if (control_lost_handler_ != 0) {
      g_signal_handler_disconnect(arv_camera_get_device(camera_), control_lost_handler_);
      control_lost_handler_ = 0;
    }
    g_object_unref(camera_);
    camera_ = nullptr;
  }
}

void AravisCamera::stop() {
  stopped_.store(true, std::memory_order_release);
}

void AravisCamera::count_bad_buffer(int status) {
  switch (status) {
    case ARV_BUFFER_STATUS_MISSING_PACKETS:
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID:
      CameraHealthCounters::add(counters_.missing_packets);
      break;
    case ARV_BUFFER_STATUS_TIMEOUT:
      CameraHealthCounters::add(counters_.timeouts);
      break;
    case ARV_BUFFER_STATUS_SIZE_MISMATCH:
      CameraHealthCounters::add(counters_.size_mismatches);
      break;
    default:
      CameraHealthCounters::add(counters_.other_errors);
      break;
  }
}

void AravisCamera::update_stream_statistics() {
  guint64 completed = 0, failures = 0, underruns = 0;
  arv_stream_get_statistics(stream_, &completed, &failures, &underruns);
  counters_.underruns.store(static_cast<std::int64_t>(underruns_base_ + underruns),
                            std::memory_order_relaxed);
}

GrabStatus AravisCamera::grab(std::span<std::uint8_t> dst, FrameInfo& info,
                              std::chrono::milliseconds timeout) {
  if (stopped_.load(std::memory_order_acquire)) return GrabStatus::kStopped;
  if (dst.size() < format_.bytes()) return GrabStatus::kError;
  const std::int64_t start = monotonic_ns();
  const std::int64_t deadline = start + timeout.count() * kMs;

  if (stream_ == nullptr) {
    // Lost: try again when the backoff has passed, waiting for it (in slices) meanwhile.
    if (const GrabStatus waited = backoff_.wait(deadline, stopped_); waited != GrabStatus::kOk) {
      return waited;
    }
    std::string ignored;
    if (!connect(&ignored)) {
      disconnect();
      backoff_.failed();
      return GrabStatus::kError;
    }
    CameraHealthCounters::add(counters_.reconnects);
    backoff_.succeeded();
  }

  if (options_.trigger == AravisTrigger::kSoftware) {
    // The frame path set the laser before calling grab(): the exposure starts now, after it.
    GError* e = nullptr;
    arv_camera_software_trigger(camera_, &e);
    if (e != nullptr) {
      g_clear_error(&e);
      CameraHealthCounters::add(counters_.other_errors);
    }
  }

  while (true) {
    if (stopped_.load(std::memory_order_acquire)) return GrabStatus::kStopped;
    const std::int64_t now = monotonic_ns();
    // Only the time spent waiting in vain counts: frames queue up while the caller is away.
    const bool silent_too_long =
        options_.trigger != AravisTrigger::kLine && silent_ns_ > options_.lost_after_ms * kMs;
    if (control_lost_.load(std::memory_order_acquire) || silent_too_long) {
      disconnect();
      CameraHealthCounters::add(counters_.other_errors);
      backoff_.lost();
      return GrabStatus::kError;
    }
    if (now >= deadline) return GrabStatus::kTimeout;
    const std::int64_t wait_us = std::min<std::int64_t>(kWaitSliceUs, (deadline - now) / 1000 + 1);
    ArvBuffer* buffer = arv_stream_timeout_pop_buffer(stream_, static_cast<guint64>(wait_us));
    if (buffer == nullptr) {
      silent_ns_ += monotonic_ns() - now;
      continue;
    }
    silent_ns_ = 0;

    const std::int64_t arrival_mono = monotonic_ns();
    const std::int64_t arrival_wall = wall_ns();
    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    std::size_t size = 0;
    const auto* data = static_cast<const std::uint8_t*>(arv_buffer_get_data(buffer, &size));
    if (status != ARV_BUFFER_STATUS_SUCCESS || data == nullptr || size != payload_bytes_) {
      // Counted and skipped: the camera is alive (a frame came), this one is unusable.
      if (status == ARV_BUFFER_STATUS_SUCCESS) {
        CameraHealthCounters::add(counters_.size_mismatches);
      } else {
        count_bad_buffer(status);
      }
      arv_stream_push_buffer(stream_, buffer);
      update_stream_statistics();
      continue;
    }

    converter_.convert(data, converter_.row_bytes(), dst.data(),
                       static_cast<std::size_t>(format_.stride));
    const auto camera_ns = static_cast<std::int64_t>(arv_buffer_get_timestamp(buffer));
    const std::uint64_t frame_id = arv_buffer_get_frame_id(buffer);
    arv_stream_push_buffer(stream_, buffer);

    std::int64_t skipped = 0;
    info.sequence = sequence_.next(frame_id, skipped);
    if (skipped > 0) CameraHealthCounters::add(counters_.skipped_frames, skipped);
    info.camera_ns = camera_ns;
    info.exposure_mono_ns = clock_.to_monotonic(camera_ns, arrival_mono);
    info.arrival_mono_ns = arrival_mono;
    info.arrival_wall_ns = arrival_wall;
    info.exposure_us = exposure_us_;
    info.gain_db = gain_db_;
    update_stream_statistics();
    return GrabStatus::kOk;
  }
}

CameraHealth AravisCamera::health() const {
  return counters_.load();
}

}  // namespace laserline::hal
