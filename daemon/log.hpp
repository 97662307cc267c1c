#pragma once

namespace laserline::daemon {

// Syslog levels as sd-daemon.h's SD_ERR, SD_WARNING and SD_INFO prefixes give them.
enum class LogLevel : int { kError = 3, kWarning = 4, kInfo = 6 };

// Writes one message of the daemon: errors and warnings to stderr, information to stdout, a
// newline added. When that stream is the journal's (JOURNAL_STREAM names its device and inode,
// sd-daemon(3)), every line starts with "<N>", the level, so that `journalctl -p err` finds the
// errors; elsewhere (a terminal, a file, a pipe) the text is written as it is.
// Thread context: any thread except a signal handler (it formats into the heap).
void log(LogLevel level, const char* format, ...) __attribute__((format(printf, 2, 3)));

// True when the file descriptor is the stream JOURNAL_STREAM names.
bool is_journal_stream(int fd);

}  // namespace laserline::daemon
