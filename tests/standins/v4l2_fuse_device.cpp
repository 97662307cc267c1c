// A stand-in V4L2 capture device for tests: a FUSE file (libfuse3) that answers the V4L2 ioctls
// a capture client uses and serves frames through mmap, so that a V4L2 client runs its real code
// path (open, QUERYCAP, S_FMT, S_PARM, REQBUFS, QUERYBUF, mmap, QBUF, STREAMON, poll, DQBUF) on
// this machine, which has no video device. The kernel passes a FUSE file's ioctls on when their
// argument size is encoded in the command number, which holds for every V4L2 ioctl used here.
// Test-only: never installed. Over 600 lines: one device, its ioctls, FUSE callbacks and frame
// producer on one shared state.
//
// Controls, as the kernel's control framework (v4l2-ctrls) answers for a driver: "Exposure Time,
// Absolute" and "Gain" (integers), "Pixel Rate" (64-bit, read-only, as sensors report it),
// "Integer 64 Bits" (64-bit, as the vivid test driver has) and "Horizontal Flip" (boolean, grabbed
// while streaming: EBUSY, as sensor drivers do), through QUERYCTRL, QUERY_EXT_CTRL,
// G_CTRL, S_CTRL and G/S/TRY_EXT_CTRLS. An extended-control request holds a pointer to its array
// of controls; the kernel hands a plain FUSE file only the fixed-size struct (its ioctls are
// "restricted": fs/fuse/ioctl.c refuses FUSE_IOCTL_RETRY, with which CUSE asks for more of the
// caller's memory, and /dev/cuse is not available here). So the array is read from and written
// back to the calling thread's memory with process_vm_readv/writev (its id is in the request,
// fuse_get_context()): the client's unmodified ioctl goes through the kernel, for any client
// (v4l2-ctl, OpenCV, laserlined), with no LD_PRELOAD. That needs ptrace access to the caller:
// the same user, and Yama's ptrace_scope 0 (Debian's default) or the caller run as root.
// Validation is the framework's: all of a request's controls checked before any is changed
// (error_idx = count when S_EXT_CTRLS refuses then; TRY names the control), integers clamped to
// their range, a read-only control refused with EACCES, a 64-bit one refused by G/S_CTRL.
//
//   v4l2_fuse_device MOUNTPOINT [--format NAME] [--width W] [--height H] [--fps F]
//                    [--padding BYTES] [--yuv 601-limited|709-full]
//                    [--controls extended|legacy] [--control-writes work|fail]
//                    [--control-log FILE]
//
// NAME: GREY, Y16, YUYV, RGB24, BGR24, or a Bayer mosaic SRGGB8, SGRBG8, SGBRG8, SBGGR8 (also 12
// and 16 bit: SRGGB12, SRGGB16, ...), as the V4L2_PIX_FMT_ macros. --padding: bytes after each
// row (bytesperline says so, as drivers that align rows do). --yuv: the Y'CbCr encoding YUYV is
// stated in: 601-limited (the default: colorspace SMPTE170M, encoding and quantization left at
// their defaults, as most webcams) or 709-full (stated explicitly). --controls legacy: a driver
// older than the control framework, whose extended ioctls (and QUERY_EXT_CTRL) answer ENOTTY.
// --control-writes fail: a control's value passes validation but writing it to the sensor fails
// (EIO, as when a sensor stops answering on its I2C bus), error_idx naming it. --control-log: each
// control written is appended as "IOCTL ID VALUE" (S_CTRL or S_EXT_CTRLS),
// so that a test sees which ioctl a client set it with.
//
// MOUNTPOINT/video0 is the device until SIGTERM/SIGINT (then it disappears, as when a USB
// camera is unplugged). Frame n carries the pattern of v4l2_test_pattern.hpp at sequence n, a
// CLOCK_MONOTONIC timestamp taken when its exposure "starts" (just before it is written), and
// V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE.
//
// mmap is served through the page cache: each buffer lives at offset index * kBufferStride of
// the file, read() answers whole requests (a short read of a mapped page would kill the client
// with SIGBUS), and the file's cached pages are invalidated each time a buffer is refilled so the
// client's mapping sees the new frame. What it cannot cover is written in the README.
#define FUSE_USE_VERSION 35
#include <fuse.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/uio.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "v4l2_test_pattern.hpp"

namespace {

constexpr const char* kName = "/video0";
constexpr std::size_t kBufferStride = 16u << 20;  // file offset between buffers
constexpr unsigned kMaxBuffers = 8;

enum class State { kIdle, kQueued, kDone, kWithClient };

struct Buffer {
  std::vector<std::uint8_t> memory;
  State state = State::kIdle;
  v4l2_buffer info{};
};

// The controls it has, named as drivers name them.
struct Control {
  std::uint32_t id;
  const char* name;
  std::uint32_t type;  // V4L2_CTRL_TYPE_INTEGER or _INTEGER64
  std::uint32_t flags;
  std::int64_t minimum;
  std::int64_t maximum;
  std::int64_t default_value;
  std::int64_t value;
  bool grabbed_while_streaming = false;  // as sensors grab their flips (they move the mosaic)
};

constexpr std::uint32_t kInteger64Id = V4L2_CID_USER_BASE | 0xf000;  // a driver-private control

struct Device {
  std::mutex mutex;
  std::uint32_t fourcc = V4L2_PIX_FMT_GREY;
  std::uint32_t width = 640;
  std::uint32_t height = 480;
  std::uint32_t fps = 30;
  std::uint32_t padding = 0;
  bool yuv_709_full = false;
  std::vector<Buffer> buffers;
  std::deque<unsigned> queued;  // in QBUF order
  std::deque<unsigned> done;    // filled, in DQBUF order
  bool streaming = false;
  std::uint32_t sequence = 0;
  std::condition_variable frame_done;
  fuse_pollhandle* poll_handle = nullptr;
  fuse* fs = nullptr;
  std::atomic<bool> running{true};
  bool extended_controls = true;
  bool control_writes_fail = false;
  FILE* control_log = nullptr;
  Control controls[5] = {
      {V4L2_CID_EXPOSURE_ABSOLUTE, "Exposure Time, Absolute", V4L2_CTRL_TYPE_INTEGER, 0, 1, 10000,
       100, 100},
      {V4L2_CID_GAIN, "Gain", V4L2_CTRL_TYPE_INTEGER, 0, 0, 255, 32, 32},
      {V4L2_CID_PIXEL_RATE, "Pixel Rate", V4L2_CTRL_TYPE_INTEGER64, V4L2_CTRL_FLAG_READ_ONLY, 1,
       INT64_MAX, 8'000'000'000, 8'000'000'000},
      {kInteger64Id, "Integer 64 Bits", V4L2_CTRL_TYPE_INTEGER64, 0, -(std::int64_t{1} << 40),
       std::int64_t{1} << 40, 0, 0},
      {V4L2_CID_HFLIP, "Horizontal Flip", V4L2_CTRL_TYPE_BOOLEAN, 0, 0, 1, 0, 0, true}};

  std::uint32_t bytes_per_line() const {
    return width * laserline::test::pattern_bytes_per_pixel(fourcc) + padding;
  }
  std::uint32_t image_bytes() const { return bytes_per_line() * height; }
};

Device g_device;

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void fill_format(v4l2_format* f) {
  std::memset(&f->fmt, 0, sizeof(f->fmt));
  f->type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  f->fmt.pix.width = g_device.width;
  f->fmt.pix.height = g_device.height;
  f->fmt.pix.pixelformat = g_device.fourcc;
  f->fmt.pix.field = V4L2_FIELD_NONE;
  f->fmt.pix.bytesperline = g_device.bytes_per_line();
  f->fmt.pix.sizeimage = g_device.image_bytes();
  f->fmt.pix.colorspace = V4L2_COLORSPACE_RAW;
  if (g_device.fourcc == V4L2_PIX_FMT_RGB24 || g_device.fourcc == V4L2_PIX_FMT_BGR24) {
    f->fmt.pix.colorspace = V4L2_COLORSPACE_SRGB;
  } else if (g_device.fourcc == V4L2_PIX_FMT_YUYV && g_device.yuv_709_full) {
    f->fmt.pix.colorspace = V4L2_COLORSPACE_REC709;
    f->fmt.pix.ycbcr_enc = V4L2_YCBCR_ENC_709;
    f->fmt.pix.quantization = V4L2_QUANTIZATION_FULL_RANGE;
  } else if (g_device.fourcc == V4L2_PIX_FMT_YUYV) {
    f->fmt.pix.colorspace = V4L2_COLORSPACE_SMPTE170M;
  }
}

// The control with this id, or with V4L2_CTRL_FLAG_NEXT_CTRL the first one after it.
Control* find_control(std::uint32_t id) {
  const bool next = (id & V4L2_CTRL_FLAG_NEXT_CTRL) != 0;
  id &= ~V4L2_CTRL_FLAG_NEXT_CTRL;
  Control* best = nullptr;
  for (Control& c : g_device.controls) {
    if (next ? c.id > id && (best == nullptr || c.id < best->id) : c.id == id) best = &c;
  }
  return best;
}

bool grabbed(const Control& c) {
  return c.grabbed_while_streaming && g_device.streaming;
}

std::uint32_t flags(const Control& c) {
  return c.flags | (grabbed(c) ? V4L2_CTRL_FLAG_GRABBED : 0u);
}

// A new value as the framework takes it: an integer (step 1) clamped to the control's range.
std::int64_t clamped(const Control& c, std::int64_t value) {
  return std::clamp(value, c.minimum, c.maximum);
}

void log_control(const char* ioctl, const Control& c) {
  if (g_device.control_log == nullptr) return;
  std::fprintf(g_device.control_log, "%s 0x%08x %lld\n", ioctl, c.id,
               static_cast<long long>(c.value));
  std::fflush(g_device.control_log);
}

// Bytes in the calling thread's memory: the array of an extended-control request.
bool copy_caller(void* ours, void* callers, std::size_t bytes, bool to_caller) {
  iovec local{ours, bytes};
  iovec remote{callers, bytes};
  const pid_t caller = fuse_get_context()->pid;
  const ssize_t n = to_caller ? process_vm_writev(caller, &local, 1, &remote, 1, 0)
                              : process_vm_readv(caller, &local, 1, &remote, 1, 0);
  if (n != static_cast<ssize_t>(bytes)) {
    std::fprintf(stderr, "v4l2_fuse_device: cannot %s the memory of thread %d: %s\n",
                 to_caller ? "write" : "read", static_cast<int>(caller), std::strerror(errno));
    return false;
  }
  return true;
}

// VIDIOC_G/S/TRY_EXT_CTRLS as v4l2-ioctl.c (check_ext_ctrls) and the control framework
// (v4l2-ctrls-api.c) carry them out: every control found and validated before any is changed.
int ext_controls_in_place(unsigned int cmd, v4l2_ext_controls* cs) {
  const bool get = cmd == VIDIOC_G_EXT_CTRLS;
  const bool set = cmd == VIDIOC_S_EXT_CTRLS;
  cs->error_idx = cs->count;
  if (cs->which == V4L2_CTRL_WHICH_REQUEST_VAL) return -EINVAL;  // no media device
  if (cs->which == V4L2_CTRL_WHICH_DEF_VAL && !get) return -EINVAL;
  if (cs->count > V4L2_CID_MAX_CTRLS) return -EINVAL;
  const bool by_class =
      cs->which != V4L2_CTRL_WHICH_CUR_VAL && cs->which != V4L2_CTRL_WHICH_DEF_VAL;
  if (cs->count == 0) {
    if (!by_class) return 0;
    for (const Control& c : g_device.controls)
      if (V4L2_CTRL_ID2WHICH(c.id) == cs->which) return 0;
    return -EINVAL;
  }
  std::vector<v4l2_ext_control> controls(cs->count);
  const std::size_t bytes = controls.size() * sizeof(v4l2_ext_control);
  if (!copy_caller(controls.data(), cs->controls, bytes, false)) return -EFAULT;
  std::vector<Control*> found(cs->count);
  int result = 0;
  for (std::uint32_t i = 0; i < cs->count && result == 0; ++i) {
    if (by_class && V4L2_CTRL_ID2WHICH(controls[i].id) != cs->which) {
      cs->error_idx = cmd == VIDIOC_TRY_EXT_CTRLS ? i : cs->count;
      result = -EINVAL;
    }
  }
  for (std::uint32_t i = 0; i < cs->count && result == 0; ++i) {
    cs->error_idx = i;
    found[i] = find_control(controls[i].id);
    if (found[i] == nullptr) result = -EINVAL;
  }
  if (result != 0 && cmd != VIDIOC_TRY_EXT_CTRLS) cs->error_idx = cs->count;
  if (result == 0 && get) {
    for (std::uint32_t i = 0; i < cs->count; ++i) {
      const Control& c = *found[i];
      const std::int64_t v = cs->which == V4L2_CTRL_WHICH_DEF_VAL ? c.default_value : c.value;
      if (c.type == V4L2_CTRL_TYPE_INTEGER64) {
        controls[i].value64 = v;
      } else {
        controls[i].value = static_cast<std::int32_t>(v);
      }
      cs->error_idx = i;
    }
  }
  if (result == 0 && !get) {
    for (std::uint32_t i = 0; i < cs->count && result == 0; ++i) {
      cs->error_idx = i;
      if ((found[i]->flags & V4L2_CTRL_FLAG_READ_ONLY) != 0) result = -EACCES;
      if (set && grabbed(*found[i])) result = -EBUSY;
    }
    if (result != 0 && set) cs->error_idx = cs->count;
    for (std::uint32_t i = 0; i < cs->count && result == 0; ++i) {
      Control& c = *found[i];
      const bool wide = c.type == V4L2_CTRL_TYPE_INTEGER64;
      const std::int64_t v = clamped(c, wide ? controls[i].value64 : controls[i].value);
      if (wide) {
        controls[i].value64 = v;
      } else {
        controls[i].value = static_cast<std::int32_t>(v);
      }
      cs->error_idx = i;
      if (set && g_device.control_writes_fail) {
        result = -EIO;
      } else if (set) {
        c.value = v;
        log_control("S_EXT_CTRLS", c);
      }
    }
  }
  // The kernel copies the array back whatever the outcome (video_usercopy's always_copy).
  if (!copy_caller(controls.data(), cs->controls, bytes, true)) return -EFAULT;
  return result;
}

int ext_controls(unsigned int cmd, v4l2_ext_controls* cs, void* callers_struct) {
  const int result = ext_controls_in_place(cmd, cs);
  // The kernel copies the struct back when it refuses too (video_usercopy's always_copy), so that
  // error_idx reaches the caller; libfuse sends no reply data with an error, so it goes directly.
  if (result != 0 && !copy_caller(cs, callers_struct, sizeof *cs, true)) return -EFAULT;
  return result;
}

int do_ioctl(const char* path, unsigned int cmd, void* arg, fuse_file_info* fi,
             unsigned int /*flags*/, void* data) {
  if (std::strcmp(path, kName) != 0) return -ENOTTY;
  Device& d = g_device;
  std::unique_lock lock(d.mutex);
  switch (cmd) {
    case VIDIOC_QUERYCAP: {
      auto* cap = static_cast<v4l2_capability*>(data);
      std::memset(cap, 0, sizeof(*cap));
      std::snprintf(reinterpret_cast<char*>(cap->driver), sizeof(cap->driver), "laserline-fuse");
      std::snprintf(reinterpret_cast<char*>(cap->card), sizeof(cap->card), "V4L2 stand-in");
      std::snprintf(reinterpret_cast<char*>(cap->bus_info), sizeof(cap->bus_info), "fuse:0");
      cap->version = 0x060100;
      cap->device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
      cap->capabilities = cap->device_caps | V4L2_CAP_DEVICE_CAPS;
      return 0;
    }
    case VIDIOC_ENUM_FMT: {
      auto* f = static_cast<v4l2_fmtdesc*>(data);
      if (f->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || f->index != 0) return -EINVAL;
      f->flags = 0;
      f->pixelformat = d.fourcc;
      std::snprintf(reinterpret_cast<char*>(f->description), sizeof(f->description), "stand-in");
      return 0;
    }
    case VIDIOC_G_FMT:
    case VIDIOC_S_FMT:
    case VIDIOC_TRY_FMT: {
      auto* f = static_cast<v4l2_format*>(data);
      if (f->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return -EINVAL;
      // Like a fixed-mode sensor: any request is answered with the one format it has.
      if (cmd == VIDIOC_S_FMT && d.streaming) return -EBUSY;
      fill_format(f);
      return 0;
    }
    case VIDIOC_G_PARM:
    case VIDIOC_S_PARM: {
      auto* p = static_cast<v4l2_streamparm*>(data);
      if (p->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return -EINVAL;
      if (cmd == VIDIOC_S_PARM && p->parm.capture.timeperframe.numerator != 0 &&
          p->parm.capture.timeperframe.denominator != 0) {
        d.fps = std::max(
            1u, p->parm.capture.timeperframe.denominator / p->parm.capture.timeperframe.numerator);
      }
      std::memset(&p->parm, 0, sizeof(p->parm));
      p->parm.capture.capability = V4L2_CAP_TIMEPERFRAME;
      p->parm.capture.timeperframe = {1, d.fps};
      return 0;
    }
    case VIDIOC_REQBUFS: {
      auto* r = static_cast<v4l2_requestbuffers*>(data);
      if (r->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || r->memory != V4L2_MEMORY_MMAP) return -EINVAL;
      if (d.streaming) return -EBUSY;
      const unsigned count = std::min(r->count, kMaxBuffers);
      d.buffers.assign(count, Buffer{});
      d.queued.clear();
      d.done.clear();
      for (unsigned i = 0; i < count; ++i) {
        Buffer& b = d.buffers[i];
        b.memory.assign(d.image_bytes(), 0);
        b.info.index = i;
        b.info.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        b.info.memory = V4L2_MEMORY_MMAP;
        b.info.length = d.image_bytes();
        b.info.m.offset = static_cast<std::uint32_t>(i * kBufferStride);
        b.info.field = V4L2_FIELD_NONE;
      }
      r->count = count;
      r->capabilities = V4L2_BUF_CAP_SUPPORTS_MMAP;
      return 0;
    }
    case VIDIOC_QUERYBUF:
    case VIDIOC_QBUF:
    case VIDIOC_DQBUF: {
      auto* b = static_cast<v4l2_buffer*>(data);
      if (b->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || b->memory != V4L2_MEMORY_MMAP) return -EINVAL;
      if (cmd == VIDIOC_DQBUF) {
        if (!d.streaming) return -EINVAL;
        if (d.done.empty() && (fi->flags & O_NONBLOCK) != 0) return -EAGAIN;
        // Blocking, as a driver's DQBUF is (this FUSE thread waits; others serve meanwhile).
        if (!d.frame_done.wait_for(lock, std::chrono::seconds(2),
                                   [&] { return !d.done.empty() || !d.streaming; }) ||
            !d.streaming) {
          return -EIO;
        }
        const unsigned index = d.done.front();
        d.done.pop_front();
        d.buffers[index].state = State::kWithClient;
        *b = d.buffers[index].info;
        return 0;
      }
      if (b->index >= d.buffers.size()) return -EINVAL;
      Buffer& buffer = d.buffers[b->index];
      if (cmd == VIDIOC_QBUF) {
        if (buffer.state == State::kQueued || buffer.state == State::kDone) return -EINVAL;
        buffer.state = State::kQueued;
        d.queued.push_back(b->index);
      }
      *b = buffer.info;
      b->flags |= buffer.state == State::kQueued ? V4L2_BUF_FLAG_QUEUED : 0;
      return 0;
    }
    case VIDIOC_STREAMON:
    case VIDIOC_STREAMOFF: {
      const int type = *static_cast<int*>(data);
      if (type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return -EINVAL;
      d.streaming = cmd == VIDIOC_STREAMON;
      d.frame_done.notify_all();
      if (!d.streaming) {
        d.queued.clear();
        d.done.clear();
        for (Buffer& b : d.buffers)
          b.state = State::kIdle;
      }
      return 0;
    }
    case VIDIOC_QUERYCTRL: {
      auto* q = static_cast<v4l2_queryctrl*>(data);
      const Control* c = find_control(q->id);
      if (c == nullptr) return -EINVAL;
      std::memset(q, 0, sizeof(*q));
      q->id = c->id;
      q->type = c->type;
      q->flags = flags(*c);
      std::snprintf(reinterpret_cast<char*>(q->name), sizeof(q->name), "%s", c->name);
      if (c->type != V4L2_CTRL_TYPE_INTEGER64) {  // a 64-bit range only through QUERY_EXT_CTRL
        q->minimum = static_cast<std::int32_t>(c->minimum);
        q->maximum = static_cast<std::int32_t>(c->maximum);
        q->step = 1;
        q->default_value = static_cast<std::int32_t>(c->default_value);
      }
      return 0;
    }
    case VIDIOC_QUERY_EXT_CTRL: {
      if (!d.extended_controls) return -ENOTTY;
      auto* q = static_cast<v4l2_query_ext_ctrl*>(data);
      const Control* c = find_control(q->id);
      if (c == nullptr) return -EINVAL;
      std::memset(q, 0, sizeof(*q));
      q->id = c->id;
      q->type = c->type;
      q->flags = flags(*c);
      std::snprintf(q->name, sizeof(q->name), "%s", c->name);
      q->minimum = c->minimum;
      q->maximum = c->maximum;
      q->step = 1;
      q->default_value = c->default_value;
      q->elem_size = c->type == V4L2_CTRL_TYPE_INTEGER64 ? 8 : 4;
      q->elems = 1;
      return 0;
    }
    case VIDIOC_G_CTRL:
    case VIDIOC_S_CTRL: {
      auto* v = static_cast<v4l2_control*>(data);
      Control* c = find_control(v->id);
      if (c == nullptr || c->type == V4L2_CTRL_TYPE_INTEGER64) return -EINVAL;
      if (cmd == VIDIOC_S_CTRL) {
        if ((c->flags & V4L2_CTRL_FLAG_READ_ONLY) != 0) return -EACCES;
        if (grabbed(*c)) return -EBUSY;
        if (d.control_writes_fail) return -EIO;
        c->value = clamped(*c, v->value);
        log_control("S_CTRL", *c);
      }
      v->value = static_cast<std::int32_t>(c->value);
      return 0;
    }
    case VIDIOC_G_EXT_CTRLS:
    case VIDIOC_S_EXT_CTRLS:
    case VIDIOC_TRY_EXT_CTRLS:
      if (!d.extended_controls) return -ENOTTY;
      return ext_controls(cmd, static_cast<v4l2_ext_controls*>(data), arg);
    default:
      return -ENOTTY;
  }
}

int do_getattr(const char* path, struct stat* st, fuse_file_info* /*fi*/) {
  std::memset(st, 0, sizeof(*st));
  if (std::strcmp(path, "/") == 0) {
    st->st_mode = S_IFDIR | 0755;
    st->st_nlink = 2;
    return 0;
  }
  if (std::strcmp(path, kName) != 0) return -ENOENT;
  st->st_mode = S_IFREG | 0660;
  st->st_nlink = 1;
  // Fixed, so that every buffer's pages are inside the file whatever REQBUFS asks later.
  st->st_size = static_cast<off_t>(kMaxBuffers * kBufferStride);
  return 0;
}

int do_readdir(const char* path, void* buf, fuse_fill_dir_t filler, off_t /*offset*/,
               fuse_file_info* /*fi*/, fuse_readdir_flags /*flags*/) {
  if (std::strcmp(path, "/") != 0) return -ENOENT;
  filler(buf, ".", nullptr, 0, static_cast<fuse_fill_dir_flags>(0));
  filler(buf, "..", nullptr, 0, static_cast<fuse_fill_dir_flags>(0));
  filler(buf, kName + 1, nullptr, 0, static_cast<fuse_fill_dir_flags>(0));
  return 0;
}

int do_open(const char* path, fuse_file_info* fi) {
  if (std::strcmp(path, kName) != 0) return -ENOENT;
  fi->direct_io = 0;   // mmap goes through the page cache...
  fi->keep_cache = 0;  // ...which is not trusted across opens
  return 0;
}

// Whole pages, always: the bytes of the buffer at that offset, zeros past its image.
int do_read(const char* path, char* out, std::size_t size, off_t offset, fuse_file_info* /*fi*/) {
  if (std::strcmp(path, kName) != 0) return -ENOENT;
  Device& d = g_device;
  std::lock_guard lock(d.mutex);
  std::memset(out, 0, size);
  std::size_t done = 0;
  while (done < size) {
    const std::size_t at = static_cast<std::size_t>(offset) + done;
    const std::size_t index = at / kBufferStride;
    const std::size_t within = at % kBufferStride;
    const std::size_t chunk = std::min(size - done, kBufferStride - within);
    if (index < d.buffers.size() && within < d.buffers[index].memory.size()) {
      const std::size_t n = std::min(chunk, d.buffers[index].memory.size() - within);
      std::memcpy(out + done, d.buffers[index].memory.data() + within, n);
    }
    done += chunk;
  }
  return static_cast<int>(size);
}

int do_poll(const char* path, fuse_file_info* /*fi*/, fuse_pollhandle* ph, unsigned* revents) {
  if (std::strcmp(path, kName) != 0) return -ENOENT;
  Device& d = g_device;
  std::lock_guard lock(d.mutex);
  if (ph != nullptr) {
    if (d.poll_handle != nullptr) fuse_pollhandle_destroy(d.poll_handle);
    d.poll_handle = ph;
  }
  *revents = d.done.empty() ? 0 : (POLLIN | POLLRDNORM);
  return 0;
}

// The sensor: a frame every 1/fps into the oldest queued buffer; with none queued the frame is
// lost (its sequence number skipped), as a real driver does.
void produce_frames() {
  Device& d = g_device;
  std::int64_t next = monotonic_ns();
  while (d.running.load()) {
    std::uint32_t fps = 30;
    {
      std::lock_guard lock(d.mutex);
      fps = d.fps;
    }
    next += 1'000'000'000 / fps;
    const timespec until{static_cast<time_t>(next / 1'000'000'000),
                         static_cast<long>(next % 1'000'000'000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &until, nullptr);
    fuse_pollhandle* notify = nullptr;
    {
      std::lock_guard lock(d.mutex);
      if (!d.streaming) continue;
      const std::uint32_t sequence = d.sequence++;
      if (d.queued.empty()) continue;
      const unsigned index = d.queued.front();
      d.queued.pop_front();
      Buffer& b = d.buffers[index];
      const std::int64_t exposure = monotonic_ns();
      laserline::test::fill_pattern(d.fourcc, d.width, d.height, sequence, b.memory.data(),
                                    d.padding);
      b.info.bytesused = d.image_bytes();
      b.info.sequence = sequence;
      b.info.timestamp.tv_sec = static_cast<time_t>(exposure / 1'000'000'000);
      b.info.timestamp.tv_usec = static_cast<suseconds_t>((exposure % 1'000'000'000) / 1000);
      b.info.flags = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
      b.state = State::kDone;
      d.done.push_back(index);
      d.frame_done.notify_all();
      notify = d.poll_handle;
      d.poll_handle = nullptr;
    }
    // Outside the lock: the kernel may call read() on another FUSE thread while invalidating.
    fuse_invalidate_path(d.fs, kName);
    if (notify != nullptr) {
      fuse_notify_poll(notify);
      fuse_pollhandle_destroy(notify);
    }
  }
}

// 0 for a name it does not know.
std::uint32_t parse_format(const std::string& name) {
  static const std::pair<const char*, std::uint32_t> kFormats[] = {
      {"GREY", V4L2_PIX_FMT_GREY},       {"Y16", V4L2_PIX_FMT_Y16},
      {"YUYV", V4L2_PIX_FMT_YUYV},       {"RGB24", V4L2_PIX_FMT_RGB24},
      {"BGR24", V4L2_PIX_FMT_BGR24},     {"SRGGB8", V4L2_PIX_FMT_SRGGB8},
      {"SGRBG8", V4L2_PIX_FMT_SGRBG8},   {"SGBRG8", V4L2_PIX_FMT_SGBRG8},
      {"SBGGR8", V4L2_PIX_FMT_SBGGR8},   {"SRGGB12", V4L2_PIX_FMT_SRGGB12},
      {"SGRBG12", V4L2_PIX_FMT_SGRBG12}, {"SGBRG12", V4L2_PIX_FMT_SGBRG12},
      {"SBGGR12", V4L2_PIX_FMT_SBGGR12}, {"SRGGB16", V4L2_PIX_FMT_SRGGB16},
      {"SGRBG16", V4L2_PIX_FMT_SGRBG16}, {"SGBRG16", V4L2_PIX_FMT_SGBRG16},
      {"SBGGR16", V4L2_PIX_FMT_SBGGR16},
  };
  for (const auto& [known, fourcc] : kFormats) {
    if (name == known) return fourcc;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: v4l2_fuse_device MOUNTPOINT [--format NAME] [--width W] [--height H] "
                 "[--fps F] [--padding BYTES] [--yuv 601-limited|709-full] "
                 "[--controls extended|legacy] [--control-writes work|fail] "
                 "[--control-log FILE]\n");
    return 2;
  }
  const std::string mountpoint = argv[1];
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string key = argv[i];
    const std::string value = argv[i + 1];
    if (key == "--format") {
      g_device.fourcc = parse_format(value);
      if (g_device.fourcc == 0) {
        std::fprintf(stderr, "v4l2_fuse_device: --format: unknown format '%s'\n", value.c_str());
        return 2;
      }
    } else if (key == "--width") {
      g_device.width = static_cast<std::uint32_t>(std::stoul(value));
    } else if (key == "--height") {
      g_device.height = static_cast<std::uint32_t>(std::stoul(value));
    } else if (key == "--fps") {
      g_device.fps = static_cast<std::uint32_t>(std::stoul(value));
    } else if (key == "--padding") {
      g_device.padding = static_cast<std::uint32_t>(std::stoul(value));
    } else if (key == "--yuv" && (value == "601-limited" || value == "709-full")) {
      g_device.yuv_709_full = value == "709-full";
    } else if (key == "--controls" && (value == "extended" || value == "legacy")) {
      g_device.extended_controls = value == "extended";
    } else if (key == "--control-writes" && (value == "work" || value == "fail")) {
      g_device.control_writes_fail = value == "fail";
    } else if (key == "--control-log") {
      g_device.control_log = std::fopen(value.c_str(), "a");
      if (g_device.control_log == nullptr) {
        std::fprintf(stderr, "v4l2_fuse_device: --control-log: cannot open %s: %s\n", value.c_str(),
                     std::strerror(errno));
        return 2;
      }
    } else {
      std::fprintf(stderr, "v4l2_fuse_device: unknown argument '%s'\n", key.c_str());
      return 2;
    }
  }

  fuse_operations ops{};
  ops.getattr = do_getattr;
  ops.readdir = do_readdir;
  ops.open = do_open;
  ops.read = do_read;
  ops.ioctl = do_ioctl;
  ops.poll = do_poll;
  char arg0[] = "v4l2_fuse_device";
  char* fuse_argv[] = {arg0, nullptr};
  fuse_args args = FUSE_ARGS_INIT(1, fuse_argv);
  fuse* fs = fuse_new(&args, &ops, sizeof(ops), nullptr);
  if (fs == nullptr || fuse_mount(fs, mountpoint.c_str()) != 0) {
    std::fprintf(stderr, "v4l2_fuse_device: cannot mount on %s\n", mountpoint.c_str());
    return 1;
  }
  fuse_set_signal_handlers(fuse_get_session(fs));
  g_device.fs = fs;
  std::printf("v4l2_fuse_device: %s%s ready\n", mountpoint.c_str(), kName);
  std::fflush(stdout);
  std::thread sensor(produce_frames);
  fuse_loop_config config{};
  config.clone_fd = 0;
  config.max_idle_threads = 4;
  const int result = fuse_loop_mt(fs, &config);
  g_device.running.store(false);
  sensor.join();
  fuse_remove_signal_handlers(fuse_get_session(fs));
  fuse_unmount(fs);
  fuse_destroy(fs);
  fuse_opt_free_args(&args);
  if (g_device.control_log != nullptr) std::fclose(g_device.control_log);
  return result == 0 ? 0 : 1;
}
