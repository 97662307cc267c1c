// V4l2Camera opening the device, negotiating its format and streaming; its settings while running
// (exposure, frame rate, the driver's controls) are in v4l2_controls.cpp.
#include "hal/v4l2_camera.hpp"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "hal/clock.hpp"
#include "hal/v4l2_ioctl.hpp"

namespace laserline::hal {

namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr int kWaitSliceMs = 50;  // longest single poll, so that stop() is noticed quickly

struct V4l2PixelFormat {
  const char* name;
  std::uint32_t fourcc;
  SourceFormat source;
};

// 12-bit Bayer: unpacked, right-aligned in 16 bits.
const V4l2PixelFormat kPixelFormats[] = {
    {"GREY", V4L2_PIX_FMT_GREY, {PixelLayout::kMono, 8}},
    {"Y16", V4L2_PIX_FMT_Y16, {PixelLayout::kMono, 16}},
    {"YUYV", V4L2_PIX_FMT_YUYV, {PixelLayout::kYuyv, 8}},
    {"SRGGB8", V4L2_PIX_FMT_SRGGB8, {PixelLayout::kBayerRggb, 8}},
    {"SGRBG8", V4L2_PIX_FMT_SGRBG8, {PixelLayout::kBayerGrbg, 8}},
    {"SGBRG8", V4L2_PIX_FMT_SGBRG8, {PixelLayout::kBayerGbrg, 8}},
    {"SBGGR8", V4L2_PIX_FMT_SBGGR8, {PixelLayout::kBayerBggr, 8}},
    {"SRGGB12", V4L2_PIX_FMT_SRGGB12, {PixelLayout::kBayerRggb, 12}},
    {"SGRBG12", V4L2_PIX_FMT_SGRBG12, {PixelLayout::kBayerGrbg, 12}},
    {"SGBRG12", V4L2_PIX_FMT_SGBRG12, {PixelLayout::kBayerGbrg, 12}},
    {"SBGGR12", V4L2_PIX_FMT_SBGGR12, {PixelLayout::kBayerBggr, 12}},
    {"SRGGB16", V4L2_PIX_FMT_SRGGB16, {PixelLayout::kBayerRggb, 16}},
    {"SGRBG16", V4L2_PIX_FMT_SGRBG16, {PixelLayout::kBayerGrbg, 16}},
    {"SGBRG16", V4L2_PIX_FMT_SGBRG16, {PixelLayout::kBayerGbrg, 16}},
    {"SBGGR16", V4L2_PIX_FMT_SBGGR16, {PixelLayout::kBayerBggr, 16}},
    {"RGB24", V4L2_PIX_FMT_RGB24, {PixelLayout::kRgb, 8}},
    {"BGR24", V4L2_PIX_FMT_BGR24, {PixelLayout::kBgr, 8}},
};

// Our name of a fourcc, or its four characters ("MJPG") when we do not take it.
std::string fourcc_name(std::uint32_t fourcc) {
  for (const auto& f : kPixelFormats) {
    if (f.fourcc == fourcc) return f.name;
  }
  std::string s(4, ' ');
  for (int i = 0; i < 4; ++i)
    s[static_cast<std::size_t>(i)] = static_cast<char>((fourcc >> (8 * i)) & 0xff);
  while (!s.empty() && s.back() == ' ')
    s.pop_back();
  return s;
}

// The Y'CbCr encoding of a YUYV format as the driver states it (its defaults resolved the way
// V4L2 defines them), or false for one we do not convert.
bool read_yuv_encoding(const v4l2_pix_format& pix, SourceFormat& source, std::string& problem) {
  const std::uint32_t encoding =
      pix.ycbcr_enc != V4L2_YCBCR_ENC_DEFAULT
          ? pix.ycbcr_enc
          : static_cast<std::uint32_t>(V4L2_MAP_YCBCR_ENC_DEFAULT(pix.colorspace));
  const std::uint32_t quantization = pix.quantization != V4L2_QUANTIZATION_DEFAULT
                                         ? pix.quantization
                                         : static_cast<std::uint32_t>(V4L2_MAP_QUANTIZATION_DEFAULT(
                                               false, pix.colorspace, encoding));
  if (encoding == V4L2_YCBCR_ENC_601 || encoding == V4L2_YCBCR_ENC_XV601) {
    source.yuv_matrix = YuvMatrix::kBt601;
  } else if (encoding == V4L2_YCBCR_ENC_709 || encoding == V4L2_YCBCR_ENC_XV709) {
    source.yuv_matrix = YuvMatrix::kBt709;
  } else {
    problem = "the driver's Y'CbCr encoding " + std::to_string(encoding) +
              " is not converted (BT.601 and BT.709 are)";
    return false;
  }
  source.yuv_range =
      quantization == V4L2_QUANTIZATION_FULL_RANGE ? YuvRange::kFull : YuvRange::kLimited;
  return true;
}

}  // namespace

const std::vector<std::string>& v4l2_pixel_formats() {
  static const std::vector<std::string> names = pixel_format_names(kPixelFormats);
  return names;
}

std::string v4l2_pixel_format_problem(const V4l2CameraOptions& options) {
  return pixel_format_problem(kPixelFormats, options.pixel_format, options.width, options.height);
}

V4l2Camera::V4l2Camera(V4l2CameraOptions options)
    : options_(std::move(options)), backoff_(options_.reconnect_min_ms, options_.reconnect_max_ms) {
  format_.width = options_.width;
  format_.height = options_.height;
  format_.stride = options_.width;
  format_.pixel_format = PixelFormat::kMono8;
  for (std::size_t i = 0; i < std::size(kPixelFormats); ++i) {
    if (options_.pixel_format == kPixelFormats[i].name) pixel_format_index_ = static_cast<int>(i);
  }
}

V4l2Camera::~V4l2Camera() {
  disconnect();
}

bool V4l2Camera::open(std::string* error) {
  disconnect();
  stopped_.store(false, std::memory_order_release);
  clock_.reset();
  sequence_.reset();
  backoff_.reset();
  return connect(error);
}

bool V4l2Camera::probe(std::string* found, std::string* error) {
  const std::string& path = options_.device;
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = path + ": " + why;
    return false;
  };
  // Read only: QUERYCAP and ENUM_FMT change nothing on the device (no S_FMT, no buffers).
  const int fd = ::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return fail(std::string("cannot open: ") + std::strerror(errno));
  v4l2_capability cap{};
  if (xioctl(fd, VIDIOC_QUERYCAP, &cap) != 0) {
    const int e = errno;
    ::close(fd);
    return fail(std::string("not a V4L2 device (QUERYCAP): ") + std::strerror(e));
  }
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  std::string formats;
  bool offered = false;
  const std::uint32_t wanted =
      pixel_format_index_ >= 0 ? kPixelFormats[pixel_format_index_].fourcc : 0;
  v4l2_fmtdesc desc{};
  desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  for (desc.index = 0; desc.index < 64 && xioctl(fd, VIDIOC_ENUM_FMT, &desc) == 0; ++desc.index) {
    formats += (formats.empty() ? "" : ", ") + fourcc_name(desc.pixelformat);
    offered = offered || desc.pixelformat == wanted;
  }
  ::close(fd);
  const std::string what = std::string(reinterpret_cast<const char*>(cap.card)) + " (driver " +
                           reinterpret_cast<const char*>(cap.driver) + ", " +
                           reinterpret_cast<const char*>(cap.bus_info) + ")";
  if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0) return fail(what + ": not a video capture device");
  if ((caps & V4L2_CAP_STREAMING) == 0) return fail(what + ": does not support streaming I/O");
  if (!formats.empty() && !offered) {
    return fail(what + ": pixel_format '" + options_.pixel_format + "' is not among its formats (" +
                formats + ")");
  }
  if (found != nullptr) *found = path + ": " + what + "; formats " + formats;
  return true;
}

bool V4l2Camera::connect(std::string* error) {
  const std::string& path = options_.device;
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = path + ": " + why;
    disconnect();
    return false;
  };
  auto fail_errno = [&](const std::string& what) {
    return fail(what + ": " + std::strerror(errno));
  };

  if (const std::string problem = v4l2_pixel_format_problem(options_); !problem.empty()) {
    return fail("pixel_format '" + options_.pixel_format + "': " + problem);
  }
  const V4l2PixelFormat& wanted = kPixelFormats[pixel_format_index_];
  SourceFormat source = wanted.source;

  fd_ = ::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) return fail_errno("cannot open");
  v4l2_capability cap{};
  if (xioctl(fd_, VIDIOC_QUERYCAP, &cap) != 0) return fail_errno("not a V4L2 device (QUERYCAP)");
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0) return fail("not a video capture device");
  if ((caps & V4L2_CAP_STREAMING) == 0) return fail("does not support streaming I/O");

  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = static_cast<std::uint32_t>(options_.width);
  fmt.fmt.pix.height = static_cast<std::uint32_t>(options_.height);
  fmt.fmt.pix.pixelformat = wanted.fourcc;
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (xioctl(fd_, VIDIOC_S_FMT, &fmt) != 0) return fail_errno("cannot set the format (S_FMT)");
  // Drivers adjust what they cannot do instead of failing: compare.
  if (fmt.fmt.pix.pixelformat != wanted.fourcc ||
      fmt.fmt.pix.width != static_cast<std::uint32_t>(options_.width) ||
      fmt.fmt.pix.height != static_cast<std::uint32_t>(options_.height)) {
    return fail("asked for " + options_.pixel_format + " " + std::to_string(options_.width) + "x" +
                std::to_string(options_.height) + ", the driver offers " +
                fourcc_name(fmt.fmt.pix.pixelformat) + " " + std::to_string(fmt.fmt.pix.width) +
                "x" + std::to_string(fmt.fmt.pix.height));
  }
  if (source.layout == PixelLayout::kYuyv) {
    std::string problem;
    if (!read_yuv_encoding(fmt.fmt.pix, source, problem)) return fail(problem);
  }
  converter_ = PixelConverter(source, options_.width, options_.height, options_.channel);
  bytes_per_line_ =
      std::max(fmt.fmt.pix.bytesperline, static_cast<std::uint32_t>(converter_.row_bytes()));

  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(fd_, VIDIOC_G_PARM, &parm) == 0 &&
      (parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME) != 0) {
    parm.parm.capture.timeperframe.numerator = 1000;
    parm.parm.capture.timeperframe.denominator =
        static_cast<std::uint32_t>(options_.frame_rate_hz * 1000.0 + 0.5);
    if (xioctl(fd_, VIDIOC_S_PARM, &parm) != 0) return fail_errno("cannot set the frame rate");
  }

  v4l2_requestbuffers req{};
  req.count = static_cast<std::uint32_t>(options_.buffers);
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (xioctl(fd_, VIDIOC_REQBUFS, &req) != 0) return fail_errno("no mmap streaming (REQBUFS)");
  if (req.count < 2) return fail("the driver gave " + std::to_string(req.count) + " buffers");
  mappings_.assign(req.count, Mapping{});
  for (std::uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (xioctl(fd_, VIDIOC_QUERYBUF, &buf) != 0) return fail_errno("QUERYBUF");
    void* address =
        mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset);
    if (address == MAP_FAILED) return fail_errno("cannot map buffer " + std::to_string(i));
    mappings_[i] = Mapping{address, buf.length};
    if (xioctl(fd_, VIDIOC_QBUF, &buf) != 0) return fail_errno("QBUF");
  }
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(fd_, VIDIOC_STREAMON, &type) != 0) return fail_errno("STREAMON");
  sequence_.restart();
  return true;
}

void V4l2Camera::disconnect() {
  if (fd_ >= 0) {
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    xioctl(fd_, VIDIOC_STREAMOFF, &type);  // fails when the device is gone; nothing to do then
  }
  for (const Mapping& m : mappings_)
    if (m.address != nullptr) munmap(m.address, m.length);
  mappings_.clear();
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
}

void V4l2Camera::lost() {
  disconnect();
  CameraHealthCounters::add(counters_.other_errors);
  backoff_.lost();
}

void V4l2Camera::stop() {
  stopped_.store(true, std::memory_order_release);
}

GrabStatus V4l2Camera::grab(std::span<std::uint8_t> dst, FrameInfo& info,
                            std::chrono::milliseconds timeout) {
  if (stopped_.load(std::memory_order_acquire)) return GrabStatus::kStopped;
  if (dst.size() < format_.bytes()) return GrabStatus::kError;
  const std::int64_t deadline = monotonic_ns() + timeout.count() * kMs;

  if (fd_ < 0) {
    if (const GrabStatus waited = backoff_.wait(deadline, stopped_); waited != GrabStatus::kOk) {
      return waited;
    }
    std::string ignored;
    if (!connect(&ignored)) {
      backoff_.failed();
      return GrabStatus::kError;
    }
    CameraHealthCounters::add(counters_.reconnects);
    backoff_.succeeded();
  }

  while (true) {
    if (stopped_.load(std::memory_order_acquire)) return GrabStatus::kStopped;
    const std::int64_t now = monotonic_ns();
    if (now >= deadline) return GrabStatus::kTimeout;
    pollfd pfd{fd_, POLLIN, 0};
    const int wait_ms =
        static_cast<int>(std::min<std::int64_t>(kWaitSliceMs, (deadline - now) / kMs + 1));
    const int ready = poll(&pfd, 1, wait_ms);
    if (ready < 0 && errno != EINTR) {
      lost();
      return GrabStatus::kError;
    }
    if (ready <= 0) continue;
    if ((pfd.revents & (POLLERR | POLLHUP | POLLNVAL)) != 0) {
      lost();
      return GrabStatus::kError;
    }
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    if (xioctl(fd_, VIDIOC_DQBUF, &buf) != 0) {
      if (errno == EAGAIN) continue;
      lost();  // ENODEV when unplugged; anything else leaves the stream unusable too
      return GrabStatus::kError;
    }
    const std::int64_t arrival_mono = monotonic_ns();
    const std::int64_t arrival_wall = wall_ns();
    const std::size_t expected =
        static_cast<std::size_t>(bytes_per_line_) * static_cast<std::size_t>(options_.height);
    if (buf.index >= mappings_.size() || (buf.flags & V4L2_BUF_FLAG_ERROR) != 0 ||
        buf.bytesused < expected) {
      if (buf.index < mappings_.size() && (buf.flags & V4L2_BUF_FLAG_ERROR) == 0) {
        CameraHealthCounters::add(counters_.size_mismatches);
      } else {
        CameraHealthCounters::add(counters_.other_errors);
      }
      if (xioctl(fd_, VIDIOC_QBUF, &buf) != 0) {
        lost();
        return GrabStatus::kError;
      }
      continue;
    }

    converter_.convert(static_cast<const std::uint8_t*>(mappings_[buf.index].address),
                       bytes_per_line_, dst.data(), static_cast<std::size_t>(format_.stride));
    const std::int64_t stamp = static_cast<std::int64_t>(buf.timestamp.tv_sec) * 1'000'000'000 +
                               static_cast<std::int64_t>(buf.timestamp.tv_usec) * 1000;
    const bool monotonic =
        (buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
    const std::uint32_t driver_sequence = buf.sequence;
    if (xioctl(fd_, VIDIOC_QBUF, &buf) != 0) {
      lost();
      return GrabStatus::kError;
    }

    std::int64_t lost = 0;
    info.sequence = sequence_.next(driver_sequence, lost);
    if (lost > 0) {
      // The driver's sequence skips only frames it had no buffer for.
      CameraHealthCounters::add(counters_.underruns, lost);
      CameraHealthCounters::add(counters_.skipped_frames, lost);
    }
    info.camera_ns = stamp;
    if (monotonic) {
      info.exposure_mono_ns = stamp;
    } else {
      info.exposure_mono_ns = clock_.to_monotonic(stamp, arrival_mono);
    }
    info.arrival_mono_ns = arrival_mono;
    info.arrival_wall_ns = arrival_wall;
    info.exposure_us = exposure_us_;
    return GrabStatus::kOk;
  }
}

CameraHealth V4l2Camera::health() const {
  return counters_.load();
}

}  // namespace laserline::hal
