// A stand-in GPIO chip for tests, loaded with LD_PRELOAD (or linked into a test): presents
// /dev/gpiochip0 to the unmodified libgpiod 1.6 library and its tools (gpioinfo, gpioset) by
// answering the kernel's v1 GPIO character-device ioctls, and logs every change of a line with
// its host time. This machine has no GPIO kernel device; this is how the real library's code path
// runs here. Test-only: never installed.
//
// Environment:
//   LASERLINE_GPIO_SHIM_LINES  comma-separated line names (default: 8 unnamed lines)
//   LASERLINE_GPIO_SHIM_LOG    file to append one line per event to:
//                              "<mono_ns> <wall_ns> <offset> <physical level> <event> <consumer>"
//                              event = request | set | release; physical = level on the pin
//                              (active-low inverts it).
//                              A process opening the chip starts with the levels the log ends
//                              with: like the kernel, which keeps a line's level after its
//                              holder exited, however it exited (kill -9 included).
//
// Edge events (GPIO_GET_LINEEVENT_IOCTL): the line's event file is a pipe; a test that links the
// shim drives an input line with laserline_gpio_shim_drive_input(offset, level, time), which
// queues the edge's gpioevent_data with that exact timestamp (logged as event "input"), as the
// kernel does from its interrupt (logical level: active-low swaps rising and falling).
//
// What it does not cover: the v2 uAPI, line-config changes on a live handle, the kernel's
// 16-event queue limit, and chips other than gpiochip0. Like the kernel, releasing a line leaves
// its last level on the pin.
#include <dlfcn.h>
#include <fcntl.h>
#include <linux/gpio.h>
#include <sys/eventfd.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>

namespace {

constexpr const char* kChipPath = "/dev/gpiochip0";
constexpr const char* kSysfsDev = "/sys/bus/gpio/devices/gpiochip0/dev";
constexpr unsigned kMajor = 254;
constexpr unsigned kMinor = 0;
constexpr int kMaxLines = 64;
constexpr int kMaxHandles = 16;

struct Line {
  char name[GPIO_MAX_NAME_SIZE] = {};
  char consumer[GPIO_MAX_NAME_SIZE] = {};
  bool requested = false;
  bool output = false;
  bool active_low = false;
  int physical = 0;
};

struct Handle {
  int fd = -1;
  int count = 0;
  unsigned offsets[GPIOHANDLES_MAX] = {};
  // Line events (one line): the pipe's write end, and which edges were asked for.
  int event_write_fd = -1;
  std::uint32_t event_flags = 0;
};

struct Chip {
  std::mutex mutex;
  bool initialised = false;
  int num_lines = 8;
  Line lines[kMaxLines];
  Handle handles[kMaxHandles];
  int chip_fds[kMaxHandles];
  int log_fd = -1;
  char log_path[512] = {};
};

Chip& chip() {
  static Chip c;
  return c;
}

template <typename F>
F real(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
}

std::int64_t now(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Called with the mutex held. The log is opened again when its path changed since the last
// time the chip was opened (tests linking the shim use one log per test).
void open_log(Chip& c) {
  const char* log = std::getenv("LASERLINE_GPIO_SHIM_LOG");
  if (log == nullptr) log = "";
  if (std::strncmp(log, c.log_path, sizeof(c.log_path)) == 0) return;
  using CloseFn = int (*)(int);
  if (c.log_fd >= 0) real<CloseFn>("close")(c.log_fd);
  c.log_fd = -1;
  std::snprintf(c.log_path, sizeof(c.log_path), "%s", log);
  if (*log != '\0') {
    using OpenFn = int (*)(const char*, int, ...);
    c.log_fd = real<OpenFn>("open")(log, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  }
}

// Called with the mutex held, before any line is set: each line's level as the log leaves it.
void restore_levels(Chip& c) {
  if (c.log_path[0] == '\0') return;
  using OpenFn = int (*)(const char*, int, ...);
  using CloseFn = int (*)(int);
  const int fd = real<OpenFn>("open")(c.log_path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return;
  char line[256];
  std::size_t used = 0;
  char chunk[4096];
  ssize_t n;
  while ((n = read(fd, chunk, sizeof(chunk))) > 0) {
    for (ssize_t i = 0; i < n; ++i) {
      if (chunk[i] != '\n') {
        if (used + 1 < sizeof(line)) line[used++] = chunk[i];
        continue;
      }
      line[used] = '\0';
      used = 0;
      long long mono = 0, wall = 0;
      unsigned offset = 0;
      int level = 0;
      if (std::sscanf(line, "%lld %lld %u %d", &mono, &wall, &offset, &level) == 4 &&
          offset < static_cast<unsigned>(kMaxLines)) {
        c.lines[offset].physical = level != 0 ? 1 : 0;
      }
    }
  }
  real<CloseFn>("close")(fd);
}

// Called with the mutex held.
void initialise(Chip& c) {
  open_log(c);
  if (c.initialised) return;
  c.initialised = true;
  restore_levels(c);
  for (int& fd : c.chip_fds)
    fd = -1;
  if (const char* names = std::getenv("LASERLINE_GPIO_SHIM_LINES"); names != nullptr && *names) {
    c.num_lines = 0;
    const char* p = names;
    while (c.num_lines < kMaxLines) {
      const char* comma = std::strchr(p, ',');
      const std::size_t len =
          comma != nullptr ? static_cast<std::size_t>(comma - p) : std::strlen(p);
      std::snprintf(c.lines[c.num_lines].name, GPIO_MAX_NAME_SIZE, "%.*s", static_cast<int>(len),
                    p);
      ++c.num_lines;
      if (comma == nullptr) break;
      p = comma + 1;
    }
  }
}

// Called with the mutex held. One write() per event, so that processes sharing the log append
// whole lines.
void log_event(Chip& c, unsigned offset, const char* event) {
  if (c.log_fd < 0) return;
  char text[160];
  const int n = std::snprintf(
      text, sizeof(text), "%lld %lld %u %d %s %s\n", static_cast<long long>(now(CLOCK_MONOTONIC)),
      static_cast<long long>(now(CLOCK_REALTIME)), offset, c.lines[offset].physical, event,
      c.lines[offset].consumer[0] ? c.lines[offset].consumer : "-");
  if (n > 0) [[maybe_unused]]
    ssize_t w = write(c.log_fd, text, static_cast<std::size_t>(n));
}

bool is_chip_fd(Chip& c, int fd) {
  for (int f : c.chip_fds)
    if (f == fd) return true;
  return false;
}

Handle* find_handle(Chip& c, int fd) {
  for (Handle& h : c.handles)
    if (h.fd == fd) return &h;
  return nullptr;
}

int chip_ioctl(Chip& c, unsigned long request, void* arg) {
  switch (request) {
    case GPIO_GET_CHIPINFO_IOCTL: {
      auto* info = static_cast<gpiochip_info*>(arg);
      std::memset(info, 0, sizeof(*info));
      std::snprintf(info->name, sizeof(info->name), "gpiochip0");
      std::snprintf(info->label, sizeof(info->label), "laserline-shim");
      info->lines = static_cast<std::uint32_t>(c.num_lines);
      return 0;
    }
    case GPIO_GET_LINEINFO_IOCTL: {
      auto* info = static_cast<gpioline_info*>(arg);
      if (info->line_offset >= static_cast<std::uint32_t>(c.num_lines)) {
        errno = EINVAL;
        return -1;
      }
      const Line& l = c.lines[info->line_offset];
      info->flags = 0;
      if (l.requested) info->flags |= GPIOLINE_FLAG_KERNEL;
      if (l.output) info->flags |= GPIOLINE_FLAG_IS_OUT;
      if (l.active_low) info->flags |= GPIOLINE_FLAG_ACTIVE_LOW;
      std::memcpy(info->name, l.name, sizeof(info->name));
      std::memcpy(info->consumer, l.consumer, sizeof(info->consumer));
      return 0;
    }
    case GPIO_GET_LINEHANDLE_IOCTL: {
      auto* req = static_cast<gpiohandle_request*>(arg);
      if (req->lines == 0 || req->lines > GPIOHANDLES_MAX) {
        errno = EINVAL;
        return -1;
      }
      for (std::uint32_t i = 0; i < req->lines; ++i) {
        if (req->lineoffsets[i] >= static_cast<std::uint32_t>(c.num_lines)) {
          errno = EINVAL;
          return -1;
        }
        if (c.lines[req->lineoffsets[i]].requested) {
          errno = EBUSY;
          return -1;
        }
      }
      Handle* h = find_handle(c, -1);
      if (h == nullptr) {
        errno = ENOMEM;
        return -1;
      }
      const int fd = eventfd(0, EFD_CLOEXEC);
      if (fd < 0) return -1;
      h->fd = fd;
      h->count = static_cast<int>(req->lines);
      const bool output = (req->flags & GPIOHANDLE_REQUEST_OUTPUT) != 0;
      const bool active_low = (req->flags & GPIOHANDLE_REQUEST_ACTIVE_LOW) != 0;
      for (std::uint32_t i = 0; i < req->lines; ++i) {
        h->offsets[i] = req->lineoffsets[i];
        Line& l = c.lines[req->lineoffsets[i]];
        l.requested = true;
        l.output = output;
        l.active_low = active_low;
        std::snprintf(l.consumer, sizeof(l.consumer), "%s",
                      req->consumer_label[0] ? req->consumer_label : "?");
        if (output) l.physical = (req->default_values[i] != 0) != active_low ? 1 : 0;
        log_event(c, req->lineoffsets[i], "request");
      }
      req->fd = fd;
      return 0;
    }
    case GPIO_GET_LINEEVENT_IOCTL: {
      auto* req = static_cast<gpioevent_request*>(arg);
      if (req->lineoffset >= static_cast<std::uint32_t>(c.num_lines) ||
          (req->handleflags & GPIOHANDLE_REQUEST_OUTPUT) != 0 ||
          (req->eventflags & GPIOEVENT_REQUEST_BOTH_EDGES) == 0) {
        errno = EINVAL;
        return -1;
      }
      if (c.lines[req->lineoffset].requested) {
        errno = EBUSY;
        return -1;
      }
      Handle* h = find_handle(c, -1);
      if (h == nullptr) {
        errno = ENOMEM;
        return -1;
      }
      int fds[2];
      if (pipe2(fds, O_CLOEXEC) != 0) return -1;
      h->fd = fds[0];
      h->event_write_fd = fds[1];
      h->event_flags = req->eventflags;
      h->count = 1;
      h->offsets[0] = req->lineoffset;
      Line& l = c.lines[req->lineoffset];
      l.requested = true;
      l.output = false;
      l.active_low = (req->handleflags & GPIOHANDLE_REQUEST_ACTIVE_LOW) != 0;
      std::snprintf(l.consumer, sizeof(l.consumer), "%s",
                    req->consumer_label[0] ? req->consumer_label : "?");
      log_event(c, req->lineoffset, "request");
      req->fd = fds[0];
      return 0;
    }
    default:
      errno = ENOTTY;  // the v2 uAPI is not emulated
      return -1;
  }
}

int handle_ioctl(Chip& c, Handle& h, unsigned long request, void* arg) {
  auto* data = static_cast<gpiohandle_data*>(arg);
  switch (request) {
    case GPIOHANDLE_GET_LINE_VALUES_IOCTL:
      for (int i = 0; i < h.count; ++i) {
        const Line& l = c.lines[h.offsets[i]];
        data->values[i] = static_cast<std::uint8_t>((l.physical != 0) != l.active_low ? 1 : 0);
      }
      return 0;
    case GPIOHANDLE_SET_LINE_VALUES_IOCTL:
      for (int i = 0; i < h.count; ++i) {
        Line& l = c.lines[h.offsets[i]];
        if (!l.output) {
          errno = EPERM;
          return -1;
        }
        const int physical = (data->values[i] != 0) != l.active_low ? 1 : 0;
        if (physical != l.physical) {
          l.physical = physical;
          log_event(c, h.offsets[i], "set");
        }
      }
      return 0;
    default:
      errno = ENOTTY;
      return -1;
  }
}

bool is_path(const char* path, const char* expected) {
  return path != nullptr && std::strcmp(path, expected) == 0;
}

void fill_chip_stat(struct stat* st) {
  std::memset(st, 0, sizeof(*st));
  st->st_mode = S_IFCHR | 0660;
  st->st_rdev = makedev(kMajor, kMinor);
  st->st_nlink = 1;
}

int open_shim(const char* path, int flags, mode_t mode, bool* handled) {
  *handled = true;
  Chip& c = chip();
  std::lock_guard lock(c.mutex);
  if (is_path(path, kChipPath)) {
    initialise(c);  // here, so that a test linking the shim can set the environment first
    const int fd = memfd_create("gpiochip0", MFD_CLOEXEC);
    for (int& f : c.chip_fds) {
      if (f == -1) {
        f = fd;
        return fd;
      }
    }
    real<int (*)(int)>("close")(fd);  // our close() would take the mutex again
    errno = EMFILE;
    return -1;
  }
  if (is_path(path, kSysfsDev)) {
    const int fd = memfd_create("gpiochip0-dev", MFD_CLOEXEC);
    char text[32];
    const int n = std::snprintf(text, sizeof(text), "%u:%u\n", kMajor, kMinor);
    if (write(fd, text, static_cast<std::size_t>(n)) != n) return -1;
    lseek(fd, 0, SEEK_SET);
    return fd;
  }
  (void)flags;
  (void)mode;
  *handled = false;
  return -1;
}

using OpenFn = int (*)(const char*, int, ...);

// open() and open64() alike: the chip and its sysfs file here, any other path to `next`. The mode
// is in `rest` only where the flags create a file.
int open_or_forward(const char* path, int flags, va_list rest, OpenFn next) {
  mode_t mode = 0;
  if ((flags & O_CREAT) != 0 || (flags & O_TMPFILE) == O_TMPFILE) {
    mode = static_cast<mode_t>(va_arg(rest, int));
  }
  bool handled = false;
  const int fd = open_shim(path, flags, mode, &handled);
  if (handled) return fd;
  return next(path, flags, mode);
}

}  // namespace

extern "C" {

int open(const char* path, int flags, ...) {
  static const OpenFn next = real<OpenFn>("open");
  va_list ap;
  va_start(ap, flags);
  const int fd = open_or_forward(path, flags, ap, next);
  va_end(ap);
  return fd;
}

int open64(const char* path, int flags, ...) {
  static const OpenFn next = real<OpenFn>("open64");
  va_list ap;
  va_start(ap, flags);
  const int fd = open_or_forward(path, flags, ap, next);
  va_end(ap);
  return fd;
}

int close(int fd) {
  using CloseFn = int (*)(int);
  static const CloseFn next = real<CloseFn>("close");
  {
    Chip& c = chip();
    std::lock_guard lock(c.mutex);
    for (int& f : c.chip_fds)
      if (f == fd && fd >= 0) f = -1;
    if (Handle* h = fd >= 0 ? find_handle(c, fd) : nullptr) {
      for (int i = 0; i < h->count; ++i) {
        Line& l = c.lines[h->offsets[i]];
        log_event(c, h->offsets[i], "release");
        l.requested = false;
        l.output = false;
        l.active_low = false;
        l.consumer[0] = '\0';
      }
      if (h->event_write_fd >= 0) next(h->event_write_fd);
      h->fd = -1;
      h->count = 0;
      h->event_write_fd = -1;
      h->event_flags = 0;
    }
  }
  return next(fd);
}

int ioctl(int fd, unsigned long request, ...) {
  va_list ap;
  va_start(ap, request);
  void* arg = va_arg(ap, void*);
  va_end(ap);
  {
    Chip& c = chip();
    std::lock_guard lock(c.mutex);
    if (fd >= 0 && is_chip_fd(c, fd)) return chip_ioctl(c, request, arg);
    if (Handle* h = fd >= 0 ? find_handle(c, fd) : nullptr) {
      return handle_ioctl(c, *h, request, arg);
    }
  }
  using IoctlFn = int (*)(int, unsigned long, ...);
  static const IoctlFn next = real<IoctlFn>("ioctl");
  return next(fd, request, arg);
}

int stat(const char* path, struct stat* st) {
  if (is_path(path, kChipPath)) {
    fill_chip_stat(st);
    return 0;
  }
  using StatFn = int (*)(const char*, struct stat*);
  static const StatFn next = real<StatFn>("stat");
  return next(path, st);
}

int lstat(const char* path, struct stat* st) {
  if (is_path(path, kChipPath)) {
    fill_chip_stat(st);
    return 0;
  }
  using StatFn = int (*)(const char*, struct stat*);
  static const StatFn next = real<StatFn>("lstat");
  return next(path, st);
}

int access(const char* path, int how) {
  if (is_path(path, kChipPath) || is_path(path, kSysfsDev)) return 0;
  using AccessFn = int (*)(const char*, int);
  static const AccessFn next = real<AccessFn>("access");
  return next(path, how);
}

// The test's hand on an input line: its physical level becomes `physical_level` at host
// CLOCK_MONOTONIC `mono_ns`. A change is logged ("input") and, when the line is requested for
// that edge's events, queued on its event file with exactly that timestamp. Returns 0, or -1 for
// a line the chip does not have or one driven as an output.
int laserline_gpio_shim_drive_input(unsigned offset, int physical_level, long long mono_ns) {
  Chip& c = chip();
  std::lock_guard lock(c.mutex);
  initialise(c);
  if (offset >= static_cast<unsigned>(c.num_lines) || c.lines[offset].output) {
    errno = EINVAL;
    return -1;
  }
  Line& l = c.lines[offset];
  const int physical = physical_level != 0 ? 1 : 0;
  if (physical == l.physical) return 0;
  l.physical = physical;
  log_event(c, offset, "input");
  for (const Handle& h : c.handles) {
    if (h.fd < 0 || h.event_write_fd < 0 || h.offsets[0] != offset) continue;
    const bool rising = (physical != 0) != l.active_low;  // the logical level, as the kernel
    if ((h.event_flags &
         (rising ? GPIOEVENT_REQUEST_RISING_EDGE : GPIOEVENT_REQUEST_FALLING_EDGE)) == 0) {
      continue;
    }
    gpioevent_data event{};
    event.timestamp = static_cast<std::uint64_t>(mono_ns);
    event.id = rising ? GPIOEVENT_EVENT_RISING_EDGE : GPIOEVENT_EVENT_FALLING_EDGE;
    // One write of one record: a pipe writes it whole, so the reader sees whole events.
    if (write(h.event_write_fd, &event, sizeof event) != static_cast<ssize_t>(sizeof event)) {
      return -1;
    }
  }
  return 0;
}

}  // extern "C"
