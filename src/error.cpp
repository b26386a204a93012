// Formats the location into what() once, so every caller reports errors the same way.
#include "gaitmon/error.hpp"

#include <utility>

namespace gaitmon {

InputError::InputError(std::string file, std::uint64_t line, std::string reason)
    : std::runtime_error(file + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " +
                         reason),
      file_(std::move(file)),
      line_(line),
      reason_(std::move(reason)) {}

ConfigError::ConfigError(std::string file, std::string key, std::string reason)
    : std::runtime_error(file + ": " + key + ": " + reason),
      file_(std::move(file)),
      key_(std::move(key)),
      reason_(std::move(reason)) {}

}  // namespace gaitmon
