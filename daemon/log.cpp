#include "daemon/log.hpp"

#include <sys/stat.h>

#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace laserline::daemon {

bool is_journal_stream(int fd) {
  const char* value = std::getenv("JOURNAL_STREAM");
  if (value == nullptr) return false;
  unsigned long long device = 0;
  unsigned long long inode = 0;
  int used = 0;
  if (std::sscanf(value, "%llu:%llu%n", &device, &inode, &used) != 2 || value[used] != '\0') {
    return false;
  }
  struct stat st {};
  if (fstat(fd, &st) != 0) return false;
  return st.st_dev == device && st.st_ino == inode;
}

void log(LogLevel level, const char* format, ...) {
  va_list args;
  va_start(args, format);
  va_list copy;
  va_copy(copy, args);
  const int length = std::vsnprintf(nullptr, 0, format, copy);
  va_end(copy);
  std::string text(length > 0 ? static_cast<std::size_t>(length) : 0, '\0');
  if (length > 0) std::vsnprintf(text.data(), text.size() + 1, format, args);
  va_end(args);

  std::FILE* stream = level == LogLevel::kInfo ? stdout : stderr;
  // Decided once per stream: the process keeps its standard streams.
  static const bool stdout_journal = is_journal_stream(1);
  static const bool stderr_journal = is_journal_stream(2);
  const bool journal = stream == stdout ? stdout_journal : stderr_journal;
  std::string out;
  out.reserve(text.size() + 8);
  const std::string prefix = journal ? "<" + std::to_string(static_cast<int>(level)) + ">" : "";
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    if (end == text.size() && start == end && start != 0) break;  // text ended with a newline
    out += prefix;
    out.append(text, start, end - start);
    out += '\n';
    start = end + 1;
  }
  // One write per message, so that lines of two threads do not interleave.
  std::fwrite(out.data(), 1, out.size(), stream);
  std::fflush(stream);
}

}  // namespace laserline::daemon
