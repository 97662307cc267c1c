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

// The command line of every laserline program, read with getopt_long: `--opt value` and
// `--opt=value` alike, `--` ends the options. `--help` (and `-h`) prints the usage and
// `--version` the program's version, each then exiting 0. An unknown option, a missing value
// or a value given to a flag is one line naming it, then exit status 2.
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

  // "PROGRAM: MESSAGE (see --help)" through the error writer, then exit status 2.
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
