#include "lcmtypes/lcm_log.hpp"

#include <sys/types.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include "lcmtypes/big_endian.hpp"

namespace laserline::messages {

namespace {

// Sync word, event number, timestamp, channel length, data length: the LCM log event header.
constexpr std::int64_t kEventHeaderBytes = 4 + 8 + 8 + 4 + 4;
constexpr std::uint32_t kEventMarker = 0xEDA1DA01;

}  // namespace

LcmLogReader::~LcmLogReader() {
  if (file_ != nullptr) std::fclose(file_);
}

bool LcmLogReader::open(const std::string& path, std::string* error) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) {
    *error = "cannot read log '" + path + "': " + ec.message();
    return false;
  }
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (file == nullptr) {
    *error = "cannot open log '" + path + "': " + std::strerror(errno);
    return false;
  }
  adopt(file, static_cast<std::int64_t>(size));
  return true;
}

void LcmLogReader::adopt(std::FILE* file, std::int64_t size) {
  if (file_ != nullptr) std::fclose(file_);
  file_ = file;
  size_ = size;
  position_ = 0;
  totals_ = {};
}

bool LcmLogReader::read_at(std::int64_t offset, Event* event) {
  std::uint8_t header[kEventHeaderBytes];
  if (offset + kEventHeaderBytes > size_ || fseeko(file_, offset, SEEK_SET) != 0 ||
      std::fread(header, 1, sizeof header, file_) != sizeof header) {
    return false;
  }
  if (big_endian(header, 4) != kEventMarker) return false;
  const auto channel_bytes = static_cast<std::int32_t>(big_endian(header + 20, 4));
  const auto data_bytes = static_cast<std::int32_t>(big_endian(header + 24, 4));
  if (channel_bytes <= 0 || channel_bytes > kMaxChannelBytes || data_bytes < 0 ||
      data_bytes > kMaxEventBytes ||
      offset + kEventHeaderBytes + channel_bytes + data_bytes > size_) {
    return false;
  }
  event->channel.resize(static_cast<std::size_t>(channel_bytes));
  event->data.resize(static_cast<std::size_t>(data_bytes));
  if (std::fread(event->channel.data(), 1, event->channel.size(), file_) != event->channel.size() ||
      std::fread(event->data.data(), 1, event->data.size(), file_) != event->data.size()) {
    return false;
  }
  event->offset = offset;
  event->number = static_cast<std::int64_t>(big_endian(header + 4, 8));
  event->utime = static_cast<std::int64_t>(big_endian(header + 12, 8));
  position_ = offset + kEventHeaderBytes + channel_bytes + data_bytes;
  return true;
}

bool LcmLogReader::starts_with_marker(std::int64_t offset) {
  std::uint8_t word[4];
  return fseeko(file_, offset, SEEK_SET) == 0 && std::fread(word, 1, 4, file_) == 4 &&
         big_endian(word, 4) == kEventMarker;
}

std::int64_t LcmLogReader::find_marker(std::int64_t from) {
  constexpr std::size_t kChunk = 64 * 1024;
  scan_.resize(kChunk + 3);
  for (std::int64_t base = from; base < size_; base += kChunk) {
    if (fseeko(file_, base, SEEK_SET) != 0) return size_;
    // 3 bytes of overlap so that a marker across two chunks is found.
    const std::size_t got = std::fread(scan_.data(), 1, scan_.size(), file_);
    for (std::size_t i = 0; i + 4 <= got; ++i) {
      if (big_endian(scan_.data() + i, 4) == kEventMarker) {
        return base + static_cast<std::int64_t>(i);
      }
    }
  }
  return size_;
}

bool LcmLogReader::next(Event* event, Damage* damage) {
  *damage = {};
  if (file_ == nullptr) return false;
  const std::int64_t start = position_;
  std::int64_t failed_markers = 0;  // sync words in the damage: records that could not be read
  auto note = [&](std::int64_t bytes) {
    *damage = {start, bytes, std::max<std::int64_t>(failed_markers, 1)};
    ++totals_.damaged_regions;
    totals_.damaged_records += damage->records;
    totals_.damaged_bytes += bytes;
    if (totals_.first_damage_offset < 0) totals_.first_damage_offset = start;
  };
  // At an event boundary the next event starts here; after damage, at the next marker that
  // begins a whole event.
  for (std::int64_t at = start; at < size_; at = find_marker(at + 1)) {
    if (read_at(at, event)) {
      if (at > start) note(at - start);
      ++totals_.events;
      return true;
    }
    if (at > start || starts_with_marker(at)) ++failed_markers;
  }
  if (size_ > start) {
    note(size_ - start);
    totals_.truncated = true;
  }
  position_ = size_;
  return false;
}

std::string LcmLogReader::damage_summary() const {
  if (totals_.damaged_regions == 0) return "";
  std::string s = std::to_string(totals_.damaged_regions) + " damaged region" +
                  (totals_.damaged_regions == 1 ? "" : "s") + " (" +
                  std::to_string(totals_.damaged_records) + " records, " +
                  std::to_string(totals_.damaged_bytes) + " bytes skipped, the first at byte " +
                  std::to_string(totals_.first_damage_offset) + ")";
  if (totals_.truncated) s += "; the file ends inside an event (recording cut short?)";
  return s;
}

}  // namespace laserline::messages
