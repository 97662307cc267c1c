#pragma once

#include <cstdint>

namespace laserline::messages {

// The unsigned integer in the `bytes` (1..8) big-endian bytes at p: LCM's byte order for messages
// and log headers.
inline std::uint64_t big_endian(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i)
    v = (v << 8) | p[i];
  return v;
}

}  // namespace laserline::messages
