#pragma once

#include <stdexcept>
#include <string>

namespace laserline::pipeline {

// An option outside what the pipeline supports. field() is the option's name as its struct spells
// it ("max_candidates_per_column"), problem() what is wrong ("must be between 1 and 255, got
// 300"); what() is both in one line. A configuration reader maps the field to its own key and
// line.
class OptionError : public std::invalid_argument {
 public:
  OptionError(const std::string& field, const std::string& problem);

  const std::string& field() const { return field_; }
  const std::string& problem() const { return problem_; }

 private:
  std::string field_;
  std::string problem_;
};

// The maxvalue detector's threshold: a grey level, 1..255. Throws OptionError otherwise.
void validate_maxvalue_threshold(int threshold);

}  // namespace laserline::pipeline
