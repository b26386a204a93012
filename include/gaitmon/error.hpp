// Exceptions thrown at the edges: bad input files and bad settings. They always name where.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace gaitmon {

/// Bad input data (a session file, a recording): names the file, the line (1-based, 0 if none)
/// and the reason. what() is "FILE:LINE: REASON", or "FILE: REASON" without a line.
class InputError : public std::runtime_error {
 public:
  InputError(std::string file, std::uint64_t line, std::string reason);
  const std::string& file() const noexcept { return file_; }
  std::uint64_t line() const noexcept { return line_; }
  const std::string& reason() const noexcept { return reason_; }

 private:
  std::string file_;
  std::uint64_t line_;
  std::string reason_;
};

/// A bad configuration file: names the file, the offending key (dotted TOML path) and the
/// reason. what() is "FILE: KEY: REASON".
class ConfigError : public std::runtime_error {
 public:
  ConfigError(std::string file, std::string key, std::string reason);
  const std::string& file() const noexcept { return file_; }
  const std::string& key() const noexcept { return key_; }
  const std::string& reason() const noexcept { return reason_; }

 private:
  std::string file_;
  std::string key_;
  std::string reason_;
};

}  // namespace gaitmon
