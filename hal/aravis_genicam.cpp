// AravisCamera's GenICam side: the pixel formats it takes and how they are asked for, probing a
// camera, configuring it (format, region, transport, trigger, timing, the user's features) and
// its settings while streaming. Finding it and streaming: aravis_camera.cpp.
#include <arv.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <limits>

#include "hal/aravis_camera.hpp"
#include "hal/aravis_genicam.hpp"

namespace laserline::hal {

namespace {

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

std::string take_gerror(GError*& error) {
  if (error == nullptr) return "";
  std::string message = error->message;
  g_clear_error(&error);
  return message;
}

int aravis_pixel_format_index(const std::string& name) {
  for (std::size_t i = 0; i < std::size(kPixelFormats); ++i) {
    if (name == kPixelFormats[i].name) return static_cast<int>(i);
  }
  return -1;
}

const SourceFormat& aravis_source_format(int index) {
  return kPixelFormats[index].source;
}

const std::vector<std::string>& aravis_pixel_formats() {
  static const std::vector<std::string> names = pixel_format_names(kPixelFormats);
  return names;
}

std::string aravis_pixel_format_problem(const AravisCameraOptions& options) {
  return pixel_format_problem(kPixelFormats, options.pixel_format, options.width, options.height);
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
    const std::string why = take_gerror(e);
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
    const std::string message = take_gerror(e);
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
    const std::string message = take_gerror(e);
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
