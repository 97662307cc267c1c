#pragma once

#include <functional>
#include <string>
#include <vector>

namespace laserline::cli {

// One long option of a tool, written without its leading "--".
struct Option {
  const char* name;
  bool takes_value;
};

// Ends the program with `status` from wherever it is thrown below main; what the program had to
// say is already written. Thrown instead of calling std::exit so that the stack unwinds and every
// owner closes what it holds. No std::exception: a `catch (const std::exception&)` on the way
// must not take it for an error.
class Exit {
 public:
  explicit Exit(int status) : status_(status) {}
  int status() const { return status_; }

 private:
  int status_;
};

// Every program's main: `return laserline::cli::run(argc, argv, run_listen);` runs the program's
// body and returns its status, or that of an Exit thrown from it.
int run(int argc, char** argv, int (*body)(int argc, char** argv));

// "PROGRAM: MESSAGE (see --help)" on stderr, then Exit(2): a usage error found after the options
// were read.
[[noreturn]] void usage_error(const std::string& program, const std::string& message);

// The command line of every laserline program, read with getopt_long: `--opt value` and
// `--opt=value` alike, `--` ends the options. `--help` (and `-h`) prints the usage and
// `--version` the program's version, each then ending the program with status 0 (Exit). An
// unknown option, a missing value or a value given to a flag is one line naming it, then Exit(2).
//
//   Arguments args(argc, argv, "laserline-listen", kUsage, {{"url", true}, {"duration", true}});
//   while (args.next()) {
//     if (args.name() == "--url") url = args.value();
//     ...
//     else inputs.push_back(args.value());  // name() empty: an argument that is no option
//   }
class Arguments {
 public:
  Arguments(int argc, char** argv, std::string program, std::string usage,
            std::vector<Option> options);

  // Steps to the next option or other argument in the order given; false after the last.
  bool next();
  // "--url" for an option, empty for an argument that is no option.
  const std::string& name() const { return name_; }
  // The option's value, or the argument itself.
  const std::string& value() const { return value_; }

  // "PROGRAM: MESSAGE (see --help)" through the error writer, then Exit(2).
  [[noreturn]] void fail(const std::string& message) const;
  // Where the one-line errors go (default: stderr with a newline); laserlined sends them to its
  // journal-aware log.
  void set_error_writer(std::function<void(const std::string&)> writer) {
    write_error_ = std::move(writer);
  }

 private:
  int argc_;
  char** argv_;
  std::string program_;
  std::string usage_;
  std::vector<Option> options_;
  std::string name_;
  std::string value_;
  bool options_ended_ = false;
  std::function<void(const std::string&)> write_error_;
};

// The project's version (CMake's PROJECT_VERSION).
const char* version();

}  // namespace laserline::cli
