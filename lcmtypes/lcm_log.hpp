#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace laserline::messages {

// Reads an LCM log file (the format lcm-logger writes: per event a big-endian header of sync word
// 0xEDA1DA01, event number, timestamp, channel length and data length, then the channel and the
// data). Unlike lcm_eventlog_read_next_event it never trusts a length beyond the bytes left in the
// file or the limits below, resynchronises on the next sync word after damage, says where damage
// is and how long, and keeps the whole event before a damaged region. Buffers grow to the largest
// event and are reused. Thread context: one thread.
class LcmLogReader {
 public:
  // Limits a sane event stays within; a header beyond them is damage, not a huge allocation.
  static constexpr std::int32_t kMaxChannelBytes = 256;
  static constexpr std::int32_t kMaxEventBytes = 256 << 20;

  struct Event {
    std::int64_t offset = 0;  // byte offset of the event in the file
    std::int64_t number = 0;  // the event number lcm-logger gave it
    std::int64_t utime = 0;   // when lcm-logger received it
    std::string channel;
    std::vector<std::uint8_t> data;
  };
  struct Damage {
    std::int64_t offset = 0;   // first damaged byte
    std::int64_t bytes = 0;    // damaged bytes skipped
    std::int64_t records = 0;  // records lost in them (sync words that began no whole event)
  };
  // All damage met so far.
  struct Totals {
    std::int64_t events = 0;
    std::int64_t damaged_regions = 0;
    std::int64_t damaged_bytes = 0;
    std::int64_t damaged_records = 0;
    std::int64_t first_damage_offset = -1;  // -1: none
    bool truncated = false;  // the file ends inside an event or in damage (a recording cut short)
  };

  LcmLogReader() = default;
  LcmLogReader(const LcmLogReader&) = delete;
  LcmLogReader& operator=(const LcmLogReader&) = delete;
  ~LcmLogReader();

  // False with a one-line reason in *error (naming the path).
  bool open(const std::string& path, std::string* error);
  // Reads from an open stream of `size` bytes (e.g. fmemopen), which the reader then closes.
  void adopt(std::FILE* file, std::int64_t size);
  std::int64_t file_size() const { return size_; }
  // Reads the next whole event into *event; false at the end of the file. Damaged bytes skipped
  // before it (or before the end) are put in *damage (bytes == 0 when there were none).
  bool next(Event* event, Damage* damage);
  const Totals& totals() const { return totals_; }
  // One line: "N damaged regions (R records, B bytes skipped, the first at byte O)[; the file ends
  // inside an event ...]",
  // empty when the log was whole.
  std::string damage_summary() const;

 private:
  bool read_at(std::int64_t offset, Event* event);
  bool starts_with_marker(std::int64_t offset);
  std::int64_t find_marker(std::int64_t from);  // offset of the next marker, or the file size

  std::vector<std::uint8_t> scan_;
  std::FILE* file_ = nullptr;
  std::int64_t size_ = 0;
  std::int64_t position_ = 0;
  Totals totals_;
};

}  // namespace laserline::messages
