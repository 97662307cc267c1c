#pragma once

// The frames file of the cross-architecture profile check (scripts/test-arm64.sh): simulated
// scenarios rendered once on the build machine, read by profile_parity on each architecture so
// that every detector sees the same bytes there. Native byte order (x86-64 and arm64 are both
// little-endian): the magic line, then per scenario its name, geometry and frames.

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "pipeline/geometry.hpp"

namespace laserline::parity {

inline constexpr char kFramesMagic[] = "laserline parity frames 1\n";

struct ParityFrame {
  std::uint64_t sequence = 0;
  bool laser_on = true;
  std::vector<std::uint8_t> pixels;  // mono8, geometry.width per row
};

struct ParityScenario {
  std::string name;
  pipeline::ScannerGeometry geometry;
  std::vector<ParityFrame> frames;
};

class FramesWriter {
 public:
  explicit FramesWriter(const std::string& path) : path_(path), out_(path, std::ios::binary) {
    if (!out_) throw std::runtime_error(path + ": cannot be written");
    bytes(kFramesMagic, sizeof kFramesMagic - 1);
  }
  void add(const ParityScenario& s) {
    value(static_cast<std::uint32_t>(s.name.size()));
    bytes(s.name.data(), s.name.size());
    const pipeline::ScannerGeometry& g = s.geometry;
    value(std::int32_t{g.width});
    value(std::int32_t{g.height});
    for (double d : {g.fx, g.fy, g.cx, g.cy, g.sheet_width_m})
      value(d);
    for (double d : g.distortion)
      value(d);
    for (double d : g.laser_plane)
      value(d);
    value(static_cast<std::uint32_t>(s.frames.size()));
    for (const ParityFrame& f : s.frames) {
      value(f.sequence);
      value(std::uint8_t{f.laser_on});
      bytes(f.pixels.data(), f.pixels.size());
    }
  }
  void close() {
    out_.close();
    if (!out_) throw std::runtime_error(path_ + ": could not be written whole");
  }

 private:
  template <class T>
  void value(T v) {
    bytes(&v, sizeof v);
  }
  void bytes(const void* data, std::size_t size) {
    out_.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  std::string path_;
  std::ofstream out_;
};

// Reads a frames file whole; anything wrong is a std::runtime_error "FILE: byte N: problem".
class FramesReader {
 public:
  explicit FramesReader(const std::string& path) : path_(path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error(path + ": cannot be read");
    data_.assign(std::istreambuf_iterator<char>(in), {});
    const std::size_t magic_size = sizeof kFramesMagic - 1;
    if (data_.size() < magic_size || std::memcmp(data_.data(), kFramesMagic, magic_size) != 0)
      fail("not a laserline parity frames file (its first line is not \"" +
           std::string(kFramesMagic, magic_size - 1) + "\")");
    at_ = magic_size;
  }
  // The next scenario into `s` (its buffers reused); false at the end of the file.
  bool next(ParityScenario& s) {
    if (at_ == data_.size()) return false;
    const auto name_size = value<std::uint32_t>("scenario name length");
    if (name_size == 0 || name_size > 256)
      fail("scenario name length " + std::to_string(name_size));
    s.name.assign(take(name_size, "scenario name"), name_size);
    pipeline::ScannerGeometry& g = s.geometry;
    g.width = value<std::int32_t>("width");
    g.height = value<std::int32_t>("height");
    if (g.width <= 0 || g.height <= 0 || g.width > 16384 || g.height > 16384)
      fail(s.name + ": frame size " + std::to_string(g.width) + "x" + std::to_string(g.height));
    for (double* d : {&g.fx, &g.fy, &g.cx, &g.cy, &g.sheet_width_m})
      *d = value<double>("geometry");
    for (double& d : g.distortion)
      d = value<double>("distortion");
    for (double& d : g.laser_plane)
      d = value<double>("laser plane");
    const auto frames = value<std::uint32_t>("frame count");
    if (frames == 0 || frames > 1000) fail(s.name + ": frame count " + std::to_string(frames));
    s.frames.resize(frames);
    const auto frame_bytes = static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height);
    for (ParityFrame& f : s.frames) {
      f.sequence = value<std::uint64_t>("frame sequence");
      f.laser_on = value<std::uint8_t>("laser state") != 0;
      const char* pixels = take(frame_bytes, s.name + " frame " + std::to_string(f.sequence));
      f.pixels.assign(pixels, pixels + frame_bytes);
    }
    return true;
  }

 private:
  [[noreturn]] void fail(const std::string& problem) const {
    throw std::runtime_error(path_ + ": byte " + std::to_string(at_) + ": " + problem);
  }
  const char* take(std::size_t size, const std::string& what) {
    if (data_.size() - at_ < size)
      fail(what + ": needs " + std::to_string(size) + " bytes, the file ends after " +
           std::to_string(data_.size() - at_));
    const char* p = data_.data() + at_;
    at_ += size;
    return p;
  }
  template <class T>
  T value(const std::string& what) {
    T v;
    std::memcpy(&v, take(sizeof v, what), sizeof v);
    return v;
  }
  std::string path_;
  std::vector<char> data_;
  std::size_t at_ = 0;
};

}  // namespace laserline::parity
