#pragma once

#include <sys/ioctl.h>

#include <cerrno>

// Shared by the two halves of V4l2Camera (v4l2_camera.cpp opens and streams, v4l2_controls.cpp
// reads and sets controls); no other user.
namespace laserline::hal {

// ioctl(), asked again when a signal interrupted it.
inline int xioctl(int fd, unsigned long request, void* arg) {
  int r;
  do {
    r = ioctl(fd, request, arg);
  } while (r == -1 && errno == EINTR);
  return r;
}

}  // namespace laserline::hal
