#include "hal/aravis_camera.hpp"

#include <arv.h>
#include <time.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <limits>

#include "hal/clock.hpp"

namespace laserline::hal {

namespace {

constexpr std::int64_t kMs = 1'000'000;
// Longest single wait inside grab(), so that stop() is noticed quickly.
constexpr std::int64_t kWaitSliceUs = 50'000;

// Takes the message out of a GError (and frees it); "" when there was none.
std::string take_error(GError*& error) {
  if (error == nullptr) return "";
  std::string message = error->message;
  g_clear_error(&error);
  return message;
}

// A pixel format as the user names it, the GenICam names to ask the camera for (the SFNC name,
// then the older one some cameras still use), and its layout.
struct AravisPixelFormat {
  const char* name;
  const char* genicam_names[2];
  SourceFormat source;
};

constexpr AravisPixelFormat kPixelFormats[] = {
    {"Mono8", {"Mono8", nullptr}, {PixelLayout::kMono, 8}},
    {"Mono12", {"Mono12", nullptr}, {PixelLayout::kMono, 12}},
    {"Mono16", {"Mono16", nullptr}, {PixelLayout::kMono, 16}},
    {"BayerRG8", {"BayerRG8", nullptr}, {PixelLayout::kBayerRggb, 8}},
    {"BayerGR8", {"BayerGR8", nullptr}, {PixelLayout::kBayerGrbg, 8}},
    {"BayerGB8", {"BayerGB8", nullptr}, {PixelLayout::kBayerGbrg, 8}},
    {"BayerBG8", {"BayerBG8", nullptr}, {PixelLayout::kBayerBggr, 8}},
    {"BayerRG12", {"BayerRG12", nullptr}, {PixelLayout::kBayerRggb, 12}},
    {"BayerGR12", {"BayerGR12", nullptr}, {PixelLayout::kBayerGrbg, 12}},
    {"BayerGB12", {"BayerGB12", nullptr}, {PixelLayout::kBayerGbrg, 12}},
    {"BayerBG12", {"BayerBG12", nullptr}, {PixelLayout::kBayerBggr, 12}},
    {"BayerRG16", {"BayerRG16", nullptr}, {PixelLayout::kBayerRggb, 16}},
    {"BayerGR16", {"BayerGR16", nullptr}, {PixelLayout::kBayerGrbg, 16}},
    {"BayerGB16", {"BayerGB16", nullptr}, {PixelLayout::kBayerGbrg, 16}},
    {"BayerBG16", {"BayerBG16", nullptr}, {PixelLayout::kBayerBggr, 16}},
    {"RGB8", {"RGB8", "RGB8Packed"}, {PixelLayout::kRgb, 8}},
    {"BGR8", {"BGR8", "BGR8Packed"}, {PixelLayout::kBgr, 8}},
};

}  // namespace

const std::vector<std::string>& aravis_pixel_formats() {
  static const std::vector<std::string> names = pixel_format_names(kPixelFormats);
  return names;
}

std::string aravis_pixel_format_problem(const AravisCameraOptions& options) {
  return pixel_format_problem(kPixelFormats, options.pixel_format, options.width, options.height);
}

AravisCamera::AravisCamera(AravisCameraOptions options)
    : options_(std::move(options)), backoff_(options_.reconnect_min_ms, options_.reconnect_max_ms) {
  format_.width = options_.width;
  format_.height = options_.height;
  format_.stride = options_.width;
  format_.pixel_format = PixelFormat::kMono8;
  for (std::size_t i = 0; i < std::size(kPixelFormats); ++i) {
    if (options_.pixel_format == kPixelFormats[i].name) pixel_format_index_ = static_cast<int>(i);
  }
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
  const SourceFormat& source = kPixelFormats[pixel_format_index_].source;
  converter_ = PixelConverter(source, options_.width, options_.height, options_.channel);
  payload_bytes_ = converter_.row_bytes() * static_cast<std::size_t>(options_.height);
  memory_.assign(static_cast<std::size_t>(options_.buffers),
                 std::vector<std::uint8_t>(payload_bytes_, 0));
  stopped_.store(false, std::memory_order_release);
  clock_.reset();
  have_frame_id_ = false;
  next_sequence_ = 0;
  backoff_.reset();
  return connect(error);
}

bool AravisCamera::probe(std::string* found, std::string* error) {
  const std::string name = options_.device.empty() ? "the first camera found" : options_.device;
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = "device '" + name + "': " + why;
    return false;
  };
  // Discovery on every interface (about 1 s), then the device by any of its names.
  arv_update_device_list();
  const unsigned n = arv_get_n_devices();
  std::string id;
  auto names_it = [&](const char* s) { return s != nullptr && options_.device == s; };
  for (unsigned i = 0; i < n && id.empty(); ++i) {
    if (options_.device.empty() || names_it(arv_get_device_id(i)) ||
        names_it(arv_get_device_serial_nbr(i)) || names_it(arv_get_device_address(i)) ||
        names_it(arv_get_device_physical_id(i))) {
      id = arv_get_device_id(i);
    }
  }
  if (id.empty() && options_.device.empty()) {
    return fail("no camera answered the discovery on any interface");
  }
  // An address the discovery's broadcast does not reach is asked directly (Aravis gives up
  // after about 2.5 s).
  GError* e = nullptr;
  ArvCamera* camera = arv_camera_new(id.empty() ? options_.device.c_str() : id.c_str(), &e);
  if (camera == nullptr) {
    const std::string why = take_error(e);
    if (id.empty()) {
      return fail("not among the " + std::to_string(n) +
                  " cameras that answered the discovery, and nothing answers at that address (" +
                  why + ")");
    }
    return fail("found, but cannot be opened: " + why);
  }
  auto text = [&](const char* s) {
    g_clear_error(&e);
    return std::string(s != nullptr && *s != '\0' ? s : "?");
  };
  const std::string vendor = text(arv_camera_get_vendor_name(camera, &e));
  const std::string model = text(arv_camera_get_model_name(camera, &e));
  const std::string serial = text(arv_camera_get_device_serial_number(camera, &e));
  guint count = 0;
  const char** formats = arv_camera_dup_available_pixel_formats_as_strings(camera, &count, &e);
  g_clear_error(&e);
  std::string format_list;
  bool offered = false;
  for (guint i = 0; formats != nullptr && i < count; ++i) {
    if (formats[i] == nullptr) continue;
    format_list += (format_list.empty() ? "" : ", ") + std::string(formats[i]);
    for (const char* genicam : kPixelFormats[std::max(pixel_format_index_, 0)].genicam_names) {
      if (genicam != nullptr && std::string(genicam) == formats[i]) offered = true;
    }
  }
  g_free(formats);
  g_object_unref(camera);
  const std::string what =
      vendor + " " + model + ", serial " + serial + ", id " + (id.empty() ? options_.device : id);
  if (!format_list.empty() && !offered) {
    return fail(what + ": pixel_format '" + options_.pixel_format + "' is not among its formats (" +
                format_list + ")");
  }
  if (found != nullptr) *found = "device '" + name + "': " + what + "; formats " + format_list;
  return true;
}

bool AravisCamera::configure(std::string* error) {
  GError* e = nullptr;
  auto failed = [&](const std::string& what) {
    const std::string message = take_error(e);
    if (message.empty()) return false;
    if (error != nullptr) *error = what + ": " + message;
    return true;
  };
  ArvCamera* camera = camera_;
  // Acquisition must be stopped to change the format; the order is the one GenICam cameras
  // accept: pixel format, then the region (offsets to 0 first so any size fits), transport,
  // trigger, timing, then the user's own features.
  arv_camera_stop_acquisition(camera, &e);
  g_clear_error(&e);
  // The first of the format's GenICam names the camera takes; the first refusal is reported.
  std::string refusal;
  for (const char* name : kPixelFormats[pixel_format_index_].genicam_names) {
    if (name == nullptr) break;
    arv_camera_set_pixel_format_from_string(camera, name, &e);
    if (e == nullptr) {
      refusal.clear();
      break;
    }
    const std::string message = take_error(e);
    if (refusal.empty()) refusal = message;
  }
  if (!refusal.empty()) {
    if (error != nullptr) *error = "pixel_format '" + options_.pixel_format + "': " + refusal;
    return false;
  }
  arv_camera_set_region(camera, 0, 0, options_.width, options_.height, &e);
  if (failed("width/height " + std::to_string(options_.width) + "x" +
             std::to_string(options_.height))) {
    return false;
  }
  if (options_.offset_x != 0 || options_.offset_y != 0) {
    arv_camera_set_region(camera, options_.offset_x, options_.offset_y, options_.width,
                          options_.height, &e);
    if (failed("offset_x/offset_y")) return false;
  }
  if (arv_camera_is_gv_device(camera)) {
    if (options_.packet_size == -1) {
      arv_camera_gv_auto_packet_size(camera, &e);
      if (failed("packet_size: negotiation")) return false;
    } else if (options_.packet_size > 0) {
      arv_camera_gv_set_packet_size(camera, options_.packet_size, &e);
      if (failed("packet_size")) return false;
    }
    if (options_.packet_delay_ns >= 0) {
      arv_camera_gv_set_packet_delay(camera, options_.packet_delay_ns, &e);
      if (failed("packet_delay_ns")) return false;
    }
  }
  switch (options_.trigger) {
    case AravisTrigger::kFreeRun:
      arv_camera_clear_triggers(camera, &e);
      if (failed("trigger: free")) return false;
      arv_camera_set_frame_rate(camera, options_.frame_rate_hz, &e);
      if (failed("frame_rate_hz")) return false;
      break;
    case AravisTrigger::kSoftware:
      arv_camera_set_trigger(camera, "Software", &e);
      if (failed("trigger: software")) return false;
      break;
    case AravisTrigger::kLine:
      arv_camera_set_trigger(camera, options_.trigger_source.c_str(), &e);
      if (failed("trigger_source '" + options_.trigger_source + "'")) return false;
      break;
  }
  if (options_.exposure_us > 0) {
    arv_camera_set_exposure_time(camera, options_.exposure_us, &e);
    if (failed("exposure_us")) return false;
  }
  if (options_.gain_db >= 0) {
    arv_camera_set_gain(camera, options_.gain_db, &e);
    if (failed("gain_db")) return false;
  }
  ArvDevice* device = arv_camera_get_device(camera);
  for (const auto& [name, value] : options_.features) {
    arv_device_set_features_from_string(device, (name + "=" + value).c_str(), &e);
    if (failed("features." + name)) return false;
  }
  read_exposure_and_gain(camera);
  const guint payload = arv_camera_get_payload(camera, &e);
  if (failed("payload size")) return false;
  if (payload != payload_bytes_) {
    if (error != nullptr) {
      *error = "the camera sends " + std::to_string(payload) + " bytes per frame, expected " +
               std::to_string(payload_bytes_) + " for " + std::to_string(options_.width) + "x" +
               std::to_string(options_.height) + " " + options_.pixel_format;
    }
    return false;
  }
  return true;
}

void AravisCamera::read_exposure_and_gain(_ArvCamera* camera) {
  // Read once, as configured: a register read per frame would be a network round trip on the
  // frame path. Under the camera's automatic control the value changes from frame to frame, so
  // none is reported then. A camera without the feature answers with an error: not known.
  GError* e = nullptr;
  auto known = [&e](double value) {
    const bool ok = e == nullptr;
    g_clear_error(&e);
    return ok ? value : std::numeric_limits<double>::quiet_NaN();
  };
  auto automatic = [&e](ArvAuto mode) {
    const bool ok = e == nullptr;
    g_clear_error(&e);
    return ok && mode != ARV_AUTO_OFF;
  };
  const bool exposure_auto = automatic(arv_camera_get_exposure_time_auto(camera, &e));
  const double exposure = known(arv_camera_get_exposure_time(camera, &e));
  const bool gain_auto = automatic(arv_camera_get_gain_auto(camera, &e));
  const double gain = known(arv_camera_get_gain(camera, &e));
  exposure_us_ = exposure_auto ? std::numeric_limits<double>::quiet_NaN() : exposure;
  gain_db_ = gain_auto ? std::numeric_limits<double>::quiet_NaN() : gain;
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
    const std::string why = take_error(e);
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
    if (error != nullptr) *error = "device '" + name + "': cannot create stream: " + take_error(e);
    disconnect();
    return false;
  }
  for (auto& memory : memory_)
    arv_stream_push_buffer(stream_, arv_buffer_new(memory.size(), memory.data()));
  arv_camera_start_acquisition(camera_, &e);
  if (e != nullptr) {
    if (error != nullptr) {
      *error = "device '" + name + "': cannot start acquisition: " + take_error(e);
    }
    disconnect();
    return false;
  }
  silent_ns_ = 0;
  // The camera may count frames from anywhere after a reconnect: sequence numbers continue
  // from ours instead.
  have_frame_id_ = false;
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

    // Frame ids: GigE Vision 1 wraps at 16 bits and skips 0; after a reconnect the camera may
    // start again, so our sequence continues from where it was.
    if (!have_frame_id_) {
      sequence_base_ =
          static_cast<std::int64_t>(next_sequence_) - static_cast<std::int64_t>(frame_id);
      have_frame_id_ = true;
    } else if (frame_id < last_frame_id_ && last_frame_id_ - frame_id > 32768 &&
               last_frame_id_ <= 65535) {
      sequence_base_ += 65535;
    }
    last_frame_id_ = frame_id;
    const std::uint64_t expected = next_sequence_;
    next_sequence_ =
        static_cast<std::uint64_t>(sequence_base_ + static_cast<std::int64_t>(frame_id)) + 1;
    if (next_sequence_ > expected + 1) {
      CameraHealthCounters::add(counters_.skipped_frames,
                                static_cast<std::int64_t>(next_sequence_ - expected - 1));
    }

    info.sequence = next_sequence_ - 1;
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

namespace {

constexpr const char* kGenicamPrefix = "genicam:";
constexpr std::size_t kGenicamPrefixBytes = 8;

// A GError's message into a setting's reason, the error cleared.
void take_error_into(GError*& e, const char* what, std::span<char> reason) {
  write_setting_line(reason, "%s: %s", what, e != nullptr ? e->message : "refused");
  g_clear_error(&e);
}

// GenICam feature names are identifiers (SFNC: letters, digits, underscore).
bool is_feature_name(const char* name) {
  if (*name == '\0') return false;
  for (const char* c = name; *c != '\0'; ++c) {
    if (!std::isalnum(static_cast<unsigned char>(*c)) && *c != '_') return false;
  }
  return true;
}

}  // namespace

std::string AravisCamera::check_setting(const CameraSetting& setting) const {
  const std::string name = setting.name;
  if (name == "exposure_us") {
    return range_problem(setting.name, setting.value, setting.number, kAravisExposureRange);
  }
  if (name == "gain_db") {
    return range_problem(setting.name, setting.value, setting.number, kAravisGainRange);
  }
  if (name == "frame_rate_hz") {
    if (options_.trigger != AravisTrigger::kFreeRun) {
      return "frame_rate_hz: the camera is triggered (camera.trigger), its trigger sets the rate";
    }
    return range_problem(setting.name, setting.value, setting.number, kFrameRateRange);
  }
  if (name.rfind(kGenicamPrefix, 0) == 0) {
    if (!is_feature_name(setting.name + kGenicamPrefixBytes)) {
      return name + ": a GenICam feature name is letters, digits and '_'";
    }
    return "";
  }
  return name +
         ": not a setting of the aravis camera (exposure_us, gain_db, frame_rate_hz, "
         "genicam:<Feature>)";
}

bool AravisCamera::read_setting(const char* name, std::span<char> value) {
  if (camera_ == nullptr) return false;
  GError* e = nullptr;
  double number = 0;
  if (std::strcmp(name, "exposure_us") == 0) {
    number = arv_camera_get_exposure_time(camera_, &e);
  } else if (std::strcmp(name, "gain_db") == 0) {
    number = arv_camera_get_gain(camera_, &e);
  } else if (std::strcmp(name, "frame_rate_hz") == 0) {
    number = arv_camera_get_frame_rate(camera_, &e);
  } else if (std::strncmp(name, kGenicamPrefix, kGenicamPrefixBytes) == 0) {
    ArvGcNode* node =
        arv_device_get_feature(arv_camera_get_device(camera_), name + kGenicamPrefixBytes);
    if (node == nullptr || !ARV_IS_GC_FEATURE_NODE(node)) return false;
    const char* text = arv_gc_feature_node_get_value_as_string(ARV_GC_FEATURE_NODE(node), &e);
    if (e != nullptr) {
      g_clear_error(&e);
      return false;
    }
    write_setting_text(value, text);
    return true;
  } else {
    return false;
  }
  if (e != nullptr) {
    g_clear_error(&e);
    return false;
  }
  write_setting_value(value, number);
  return true;
}

void AravisCamera::apply_setting(const CameraSetting& setting, SettingResult& result) {
  result.accepted = false;
  if (camera_ == nullptr) {
    write_setting_text(result.reason, "the camera is not connected (reconnecting)");
    return;
  }
  GError* e = nullptr;
  const char* name = setting.name;
  if (!read_setting(name, result.old_value)) {
    write_setting_line(result.reason, "%s: the camera has no such feature", name);
    return;
  }
  if (std::strcmp(name, "exposure_us") == 0) {
    arv_camera_set_exposure_time(camera_, setting.number, &e);
  } else if (std::strcmp(name, "gain_db") == 0) {
    arv_camera_set_gain(camera_, setting.number, &e);
  } else if (std::strcmp(name, "frame_rate_hz") == 0) {
    arv_camera_set_frame_rate(camera_, setting.number, &e);
  } else {
    ArvGcNode* node =
        arv_device_get_feature(arv_camera_get_device(camera_), name + kGenicamPrefixBytes);
    arv_gc_feature_node_set_value_from_string(ARV_GC_FEATURE_NODE(node), setting.value, &e);
  }
  if (e != nullptr) {
    take_error_into(e, name, result.reason);
    return;
  }
  // Any feature may move exposure or gain (ExposureAuto, a selector): the frames carry them.
  read_exposure_and_gain(camera_);
  if (!read_setting(name, result.in_force)) {
    write_setting_line(result.reason, "%s: written but cannot be read back", name);
    return;
  }
  result.accepted = true;
}

}  // namespace laserline::hal
