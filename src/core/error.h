// Typed errors that tell a user what went wrong and where.
#pragma once

#include <stdexcept>
#include <string>

namespace twinforge::core {

// Base of every error twinforge throws on purpose.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A config or task file is malformed: names the file (and line when known), the field and what
// was expected.
class ConfigError : public Error {
 public:
  ConfigError(std::string file, std::string field, std::string message);
  const std::string& file() const { return file_; }
  const std::string& field() const { return field_; }

 private:
  std::string file_;
  std::string field_;
};

// A file or directory could not be read or written.
class IoError : public Error {
 public:
  using Error::Error;
};

// A dataset file does not have the expected layout or contents.
class DatasetError : public Error {
 public:
  using Error::Error;
};

// A numeric input (action, observation, parameter) is NaN/inf or out of its domain.
class NumericError : public Error {
 public:
  using Error::Error;
};

}  // namespace twinforge::core
