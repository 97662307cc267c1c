# Cross build for 64-bit ARM (Debian's g++-aarch64-linux-gnu, the arm64 libraries installed with
# `dpkg --add-architecture arm64`, their headers in /usr/include shared with the host); the
# programs run here under qemu-user (package qemu-user), which is how ctest runs the tests.
# scripts/test-arm64.sh uses it through the preset "arm64".
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

# Libraries and package files of the target only: never the host's x86-64 ones beside them.
set(CMAKE_SYSTEM_IGNORE_PATH /usr/lib/x86_64-linux-gnu /lib/x86_64-linux-gnu)
set(ENV{PKG_CONFIG_LIBDIR} /usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig)

# The target's dynamic loader and C++ runtime from the cross toolchain's sysroot; libraries only
# multiarch packages bring (e.g. libhwy1:arm64) qemu finds in /usr/lib/aarch64-linux-gnu.
find_program(LASERLINE_QEMU_AARCH64 qemu-aarch64 REQUIRED)
set(CMAKE_CROSSCOMPILING_EMULATOR ${LASERLINE_QEMU_AARCH64} -L /usr/aarch64-linux-gnu)
