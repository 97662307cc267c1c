#include "tools/cli.hpp"

#include <getopt.h>

#include <cstdio>
#include <string>
#include <utility>

namespace laserline::cli {

namespace {

// getopt_long's codes: each option is kFirstOption + its index; below 256 nothing clashes with
// a short option's character.
constexpr int kFirstOption = 256;
constexpr int kHelp = 'h';
constexpr int kVersion = kFirstOption - 1;
constexpr int kNotAnOption = 1;  // what a leading '-' in the short options makes of an argument

}  // namespace

Arguments::Arguments(int argc, char** argv, std::string program, std::string usage,
                     std::vector<Option> options)
    : argc_(argc),
      argv_(argv),
      program_(std::move(program)),
      usage_(std::move(usage)),
      options_(std::move(options)),
      write_error_([](const std::string& line) { std::fprintf(stderr, "%s\n", line.c_str()); }) {
  optind = 0;  // 0: getopt starts afresh, should anything have parsed before
  opterr = 0;  // its own messages are replaced by one line of ours
}

bool Arguments::next() {
  if (options_ended_) {
    if (optind >= argc_) return false;
    name_.clear();
    value_ = argv_[optind++];
    return true;
  }
  std::vector<option> table;
  table.reserve(options_.size() + 3);
  for (std::size_t i = 0; i < options_.size(); ++i) {
    table.push_back({options_[i].name, options_[i].takes_value ? required_argument : no_argument,
                     nullptr, kFirstOption + static_cast<int>(i)});
  }
  table.push_back({"help", no_argument, nullptr, kHelp});
  table.push_back({"version", no_argument, nullptr, kVersion});
  table.push_back({nullptr, 0, nullptr, 0});
  // '-': arguments that are no option come back in their place; ':': a missing value is told
  // apart from an unknown option.
  const int code = getopt_long(argc_, argv_, "-:h", table.data(), nullptr);
  // The argument getopt looked at, for the messages: "--name" of "--name=value".
  auto offending = [&]() {
    std::string arg = argv_[optind - 1];
    if (const auto eq = arg.find('='); eq != std::string::npos) arg.resize(eq);
    return arg;
  };
  auto option_name = [&](int c) -> std::string {
    if (c == kHelp) return "--help";
    if (c == kVersion) return "--version";
    if (c >= kFirstOption && c < kFirstOption + static_cast<int>(options_.size())) {
      return std::string("--") + options_[static_cast<std::size_t>(c - kFirstOption)].name;
    }
    return offending();
  };
  switch (code) {
    case -1:
      // "--" or the end: what is left are arguments.
      options_ended_ = true;
      return next();
    case kNotAnOption:
      name_.clear();
      value_ = optarg;
      return true;
    case kHelp:
      std::fputs(usage_.c_str(), stdout);
      throw Exit(0);
    case kVersion:
      std::printf("%s %s\n", program_.c_str(), version());
      throw Exit(0);
    case ':':
      fail(option_name(optopt) + ": missing value");
    case '?':
      // A long option known but given a value it does not take leaves its code in optopt.
      if (optopt != 0 && std::string(argv_[optind - 1]).rfind("--", 0) == 0) {
        fail(option_name(optopt) + ": takes no value");
      }
      fail("unknown option '" + offending() + "'");
    default:
      name_ = option_name(code);
      value_ = optarg != nullptr ? optarg : "";
      return true;
  }
}

void Arguments::fail(const std::string& message) const {
  write_error_(program_ + ": " + message + " (see --help)");
  throw Exit(2);
}

int run(int argc, char** argv, int (*body)(int argc, char** argv)) {
  try {
    return body(argc, argv);
  } catch (const Exit& request) {
    return request.status();
  }
}

void usage_error(const std::string& program, const std::string& message) {
  std::fprintf(stderr, "%s: %s (see --help)\n", program.c_str(), message.c_str());
  throw Exit(2);
}

const char* version() {
  return LASERLINE_VERSION;
}

}  // namespace laserline::cli
