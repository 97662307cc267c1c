#pragma once

#include <cstddef>
#include <cstdint>

namespace laserline::pipeline {

// A non-owning view of a mono8 image (row-major, `stride` bytes per row).
struct ImageView {
  const std::uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  int stride = 0;

  const std::uint8_t* row(int v) const { return data + static_cast<std::ptrdiff_t>(v) * stride; }
  std::uint8_t at(int u, int v) const { return row(v)[u]; }
};

}  // namespace laserline::pipeline
