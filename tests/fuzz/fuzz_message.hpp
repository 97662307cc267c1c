#pragma once

#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "lcmtypes/checked_decode.hpp"

// The harness for one message type: the checked decode must never crash, throw or allocate
// beyond its limits, and what it accepts must be exactly one encoding of the type: encoded
// again, the same bytes.
template <typename Message>
int fuzz_message(const std::uint8_t* data, std::size_t size) {
  Message message;
  std::string problem;
  laserline::messages::Limits limits;
  limits.max_image_bytes = 1 << 20;
  if (!laserline::messages::decode(data, size, &message, limits, &problem)) {
    if (problem.empty()) std::abort();  // a refusal always says why
    return 0;
  }
  const int encoded_size = message.getEncodedSize();
  if (encoded_size < 0 || static_cast<std::size_t>(encoded_size) != size) std::abort();
  std::vector<std::uint8_t> again(size);
  if (message.encode(again.data(), 0, encoded_size) != encoded_size) std::abort();
  for (std::size_t i = 0; i < size; ++i)
    if (again[i] != data[i]) std::abort();
  return 0;
}
