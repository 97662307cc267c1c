// V4l2Camera's settings while running: the exposure, the frame rate and the driver's own controls
// found by name (VIDIOC_QUERY_EXT_CTRL / S_EXT_CTRLS / G_EXT_CTRLS, or the old 32-bit ioctls).
// The other half of the class, opening and streaming, is v4l2_camera.cpp.
#include <linux/videodev2.h>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>

#include "hal/v4l2_camera.hpp"
#include "hal/v4l2_ioctl.hpp"

namespace laserline::hal {

namespace {

constexpr const char* kControlPrefix = "v4l2:";
constexpr std::size_t kControlPrefixBytes = 5;
constexpr double kExposureUnitUs = 100;  // V4L2_CID_EXPOSURE_ABSOLUTE counts 100 us
constexpr double kExactWholeNumbers = 9007199254740992.0;  // 2^53: a setting's number is a double

// A control's name as v4l2-ctl writes it: lower case, every run of other characters one '_',
// none at the end ("Exposure Time, Absolute" -> "exposure_time_absolute").
void control_key(const char* name, std::span<char> out) {
  std::size_t n = 0;
  bool gap = false;
  for (const char* c = name; *c != '\0' && n + 1 < out.size(); ++c) {
    const auto u = static_cast<unsigned char>(*c);
    if (std::isalnum(u)) {
      if (gap && n > 0 && n + 2 < out.size()) out[n++] = '_';
      out[n++] = static_cast<char>(std::tolower(u));
      gap = false;
    } else {
      gap = true;
    }
  }
  out[n] = '\0';
}

// A control as VIDIOC_QUERY_EXT_CTRL describes it (64-bit range); for a driver without that ioctl
// (ENOTTY: older than Linux 3.17 or the control framework) VIDIOC_QUERYCTRL's answer, widened.
bool query_control(int fd, v4l2_query_ext_ctrl* q) {
  if (xioctl(fd, VIDIOC_QUERY_EXT_CTRL, q) == 0) return true;
  if (errno != ENOTTY) return false;
  v4l2_queryctrl old{};
  old.id = q->id;
  if (xioctl(fd, VIDIOC_QUERYCTRL, &old) != 0) return false;
  *q = v4l2_query_ext_ctrl{};
  q->id = old.id;
  q->type = old.type;
  std::memcpy(q->name, old.name, sizeof old.name);
  q->minimum = old.minimum;
  q->maximum = old.maximum;
  q->step = static_cast<std::uint32_t>(old.step);
  q->default_value = old.default_value;
  q->flags = old.flags;
  return true;
}

// The control `name` names (as v4l2-ctl writes it or as the driver reports it), found by walking
// the driver's controls; false when there is none.
bool find_control(int fd, const char* name, v4l2_query_ext_ctrl* found) {
  char wanted[64];
  char key[64];
  control_key(name, wanted);
  v4l2_query_ext_ctrl q{};
  q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
  while (query_control(fd, &q)) {
    if ((q.flags & V4L2_CTRL_FLAG_DISABLED) == 0) {
      control_key(q.name, key);
      if (std::strcmp(key, wanted) == 0) {
        *found = q;
        return true;
      }
    }
    q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
  }
  return false;
}

bool integral_control(const v4l2_query_ext_ctrl& q) {
  return q.type == V4L2_CTRL_TYPE_INTEGER || q.type == V4L2_CTRL_TYPE_BOOLEAN ||
         q.type == V4L2_CTRL_TYPE_MENU || q.type == V4L2_CTRL_TYPE_INTEGER_MENU ||
         q.type == V4L2_CTRL_TYPE_INTEGER64;
}

// One control in an extended-control request on the value in force (V4L2_CTRL_WHICH_CUR_VAL).
struct ControlRequest {
  v4l2_ext_control control{};
  v4l2_ext_controls request{};

  ControlRequest(const v4l2_query_ext_ctrl& q, std::int64_t value) {
    control.id = q.id;
    if (q.type == V4L2_CTRL_TYPE_INTEGER64) {
      control.value64 = value;
    } else {
      control.value = static_cast<std::int32_t>(value);
    }
    request.which = V4L2_CTRL_WHICH_CUR_VAL;
    request.count = 1;
    request.controls = &control;
  }
  std::int64_t value(const v4l2_query_ext_ctrl& q) const {
    return q.type == V4L2_CTRL_TYPE_INTEGER64 ? control.value64 : control.value;
  }
};

// The value in force: VIDIOC_G_EXT_CTRLS, or G_CTRL where the driver has no extended controls.
bool get_control(int fd, const v4l2_query_ext_ctrl& q, std::int64_t* value) {
  ControlRequest get(q, 0);
  if (xioctl(fd, VIDIOC_G_EXT_CTRLS, &get.request) == 0) {
    *value = get.value(q);
    return true;
  }
  if (errno != ENOTTY || q.type == V4L2_CTRL_TYPE_INTEGER64) return false;
  v4l2_control old{q.id, 0};
  if (xioctl(fd, VIDIOC_G_CTRL, &old) != 0) return false;
  *value = old.value;
  return true;
}

// VIDIOC_S_EXT_CTRLS, or S_CTRL where the driver has no extended controls; false with the
// driver's refusal in `reason`. error_idx tells whether the driver refused the request before
// changing anything (it then equals count) or failed while applying it.
bool set_control(int fd, const v4l2_query_ext_ctrl& q, std::int64_t value, const char* name,
                 std::span<char> reason) {
  ControlRequest set(q, value);
  if (xioctl(fd, VIDIOC_S_EXT_CTRLS, &set.request) == 0) return true;
  if (errno == ENOTTY && q.type != V4L2_CTRL_TYPE_INTEGER64) {
    v4l2_control old{q.id, static_cast<std::int32_t>(value)};
    if (xioctl(fd, VIDIOC_S_CTRL, &old) == 0) return true;
    write_setting_line(reason, "%s: the driver refused it (VIDIOC_S_CTRL: %s)", name,
                       std::strerror(errno));
    return false;
  }
  const int error = errno;
  if (set.request.error_idx == set.request.count) {
    write_setting_line(reason,
                       "%s: the driver refused it before changing anything "
                       "(VIDIOC_S_EXT_CTRLS: %s)",
                       name, std::strerror(error));
  } else {
    write_setting_line(reason, "%s: the driver failed while setting it (VIDIOC_S_EXT_CTRLS: %s)",
                       name, std::strerror(error));
  }
  return false;
}

// The control a setting names (exposure_us: the absolute exposure), as the driver describes it.
bool setting_control(int fd, const char* name, v4l2_query_ext_ctrl* q) {
  if (std::strcmp(name, "exposure_us") == 0) {
    q->id = V4L2_CID_EXPOSURE_ABSOLUTE;
    return query_control(fd, q);
  }
  if (std::strncmp(name, kControlPrefix, kControlPrefixBytes) != 0) return false;
  return find_control(fd, name + kControlPrefixBytes, q) && integral_control(*q);
}

}  // namespace

std::string V4l2Camera::check_setting(const CameraSetting& setting) const {
  const std::string name = setting.name;
  if (name == "exposure_us") {
    // The range is the device's (QUERY_EXT_CTRL), checked where the device is.
    return range_problem(setting.name, setting.value, setting.number,
                         {kExposureUnitUs, std::numeric_limits<double>::max()});
  }
  if (name == "frame_rate_hz") {
    return range_problem(setting.name, setting.value, setting.number, kFrameRateRange);
  }
  if (name == "gain_db") {
    return "gain_db: V4L2's gain has no unit; set the driver's control, e.g. v4l2:gain";
  }
  if (name.rfind(kControlPrefix, 0) == 0) {
    if (name.size() == kControlPrefixBytes) return name + ": a control name is missing";
    const double v = setting.number;
    if (!(v == std::floor(v) && std::fabs(v) <= kExactWholeNumbers)) {
      return name +
             ": must be a whole number (the control's value, a menu's index; at most 2^53 in "
             "size), got '" +
             setting.value + "'";
    }
    return "";
  }
  return name + ": not a setting of the v4l2 camera (exposure_us, frame_rate_hz, v4l2:<control>)";
}

bool V4l2Camera::read_setting(const char* name, std::span<char> value) {
  if (fd_ < 0) return false;
  if (std::strcmp(name, "frame_rate_hz") == 0) {
    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(fd_, VIDIOC_G_PARM, &parm) != 0 || parm.parm.capture.timeperframe.numerator == 0) {
      return false;
    }
    write_setting_value(value, static_cast<double>(parm.parm.capture.timeperframe.denominator) /
                                   parm.parm.capture.timeperframe.numerator);
    return true;
  }
  v4l2_query_ext_ctrl q{};
  std::int64_t current = 0;
  if (!setting_control(fd_, name, &q) || !get_control(fd_, q, &current)) return false;
  if (std::strcmp(name, "exposure_us") == 0) {
    write_setting_value(value, static_cast<double>(current) * kExposureUnitUs);
  } else {
    write_setting_line(value, "%lld", static_cast<long long>(current));
  }
  return true;
}

void V4l2Camera::apply_setting(const CameraSetting& setting, SettingResult& result) {
  result.accepted = false;
  const char* name = setting.name;
  if (fd_ < 0) {
    write_setting_text(result.reason, "the camera is not open (reconnecting)");
    return;
  }
  if (!read_setting(name, result.old_value)) {
    write_setting_line(result.reason,
                       std::strcmp(name, "exposure_us") == 0
                           ? "%s: the device has no absolute exposure"
                           : "%s: the device has no such control (integer, boolean or menu)",
                       name);
    return;
  }
  if (std::strcmp(name, "frame_rate_hz") == 0) {
    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    parm.parm.capture.timeperframe.numerator = 1000;
    parm.parm.capture.timeperframe.denominator =
        static_cast<std::uint32_t>(setting.number * 1000.0 + 0.5);
    if (xioctl(fd_, VIDIOC_S_PARM, &parm) != 0) {
      write_setting_line(result.reason, "frame_rate_hz: the driver refused it (S_PARM: %s)",
                         std::strerror(errno));
      return;
    }
  } else {
    const bool exposure = std::strcmp(name, "exposure_us") == 0;
    v4l2_query_ext_ctrl q{};
    setting_control(fd_, name, &q);
    const double wanted = exposure ? std::round(setting.number / kExposureUnitUs) : setting.number;
    const long long scale = exposure ? static_cast<long long>(kExposureUnitUs) : 1;
    if ((q.flags & V4L2_CTRL_FLAG_READ_ONLY) != 0) {
      write_setting_line(result.reason, "%s: the control is read-only", name);
      return;
    }
    if (wanted < static_cast<double>(q.minimum) || wanted > static_cast<double>(q.maximum)) {
      write_setting_line(result.reason,
                         "%s: must be between %lld and %lld (the device's range), got %s", name,
                         static_cast<long long>(q.minimum) * scale,
                         static_cast<long long>(q.maximum) * scale, setting.value);
      return;
    }
    if (!set_control(fd_, q, static_cast<std::int64_t>(wanted), name, result.reason)) return;
  }
  if (!read_setting(name, result.in_force)) {
    write_setting_line(result.reason, "%s: written but cannot be read back", name);
    return;
  }
  if (std::strcmp(name, "exposure_us") == 0) exposure_us_ = std::strtod(result.in_force, nullptr);
  result.accepted = true;
}

}  // namespace laserline::hal
