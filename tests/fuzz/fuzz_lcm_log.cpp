// libFuzzer: an LCM log (messages::LcmLogReader) read to the end, every event decoded as the
// type its fingerprint names. The reader must account for every byte: events and damage add up
// to the file's size.
#include <cstdio>

#include "lcmtypes/checked_decode.hpp"
#include "lcmtypes/lcm_log.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  std::FILE* file = fmemopen(const_cast<std::uint8_t*>(data), size, "rb");
  if (file == nullptr) return 0;
  laserline::messages::LcmLogReader log;
  log.adopt(file, static_cast<std::int64_t>(size));
  laserline::messages::LcmLogReader::Event event;
  laserline::messages::LcmLogReader::Damage damage;
  laserline::messages::Limits limits;
  std::int64_t accounted = 0;
  laserline::profile_t profile;
  laserline::status_t status;
  laserline::image_t image;
  laserline::point_t point;
  laserline::calibration_t calibration;
  std::string problem;
  while (true) {
    const bool more = log.next(&event, &damage);
    accounted += damage.bytes;
    if (!more) break;
    accounted += 28 + static_cast<std::int64_t>(event.channel.size() + event.data.size());
    const std::int64_t hash =
        laserline::messages::message_hash(event.data.data(), event.data.size());
    if (hash == laserline::profile_t::getHash()) {
      laserline::messages::decode(event.data.data(), event.data.size(), &profile, limits, &problem);
    } else if (hash == laserline::status_t::getHash()) {
      laserline::messages::decode(event.data.data(), event.data.size(), &status, limits, &problem);
    } else if (hash == laserline::image_t::getHash()) {
      laserline::messages::decode(event.data.data(), event.data.size(), &image, limits, &problem);
    } else if (hash == laserline::point_t::getHash()) {
      laserline::messages::decode(event.data.data(), event.data.size(), &point, limits, &problem);
    } else if (hash == laserline::calibration_t::getHash()) {
      laserline::messages::decode(event.data.data(), event.data.size(), &calibration, limits,
                                  &problem);
    }
  }
  if (accounted != static_cast<std::int64_t>(size)) std::abort();
  return 0;
}
