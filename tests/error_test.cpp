// The edge exceptions' what(): "FILE:LINE: REASON", "FILE: REASON" when the line is 0, and
// "FILE: KEY: REASON" for configuration, with the parts kept for callers that need them.
#include "gaitmon/error.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>

namespace gaitmon {
namespace {

TEST(Error, InputErrorNamesFileLineAndReason) {
  const InputError error("walk.csv", 12, "time goes backwards");
  EXPECT_EQ(std::string(error.what()), "walk.csv:12: time goes backwards");
  EXPECT_EQ(error.file(), "walk.csv");
  EXPECT_EQ(error.line(), 12U);
  EXPECT_EQ(error.reason(), "time goes backwards");
}

TEST(Error, InputErrorWithoutALineLeavesItOut) {
  const InputError error("/data/walk.csv", 0, "no frames");
  EXPECT_EQ(std::string(error.what()), "/data/walk.csv: no frames");
  EXPECT_EQ(error.line(), 0U);
  EXPECT_EQ(error.reason(), "no frames");
}

// Lines are 1-based and 64-bit: both ends are written in full.
TEST(Error, InputErrorLineLimits) {
  EXPECT_EQ(std::string(InputError("a.csv", 1, "r").what()), "a.csv:1: r");
  EXPECT_EQ(std::string(InputError("a.csv", std::numeric_limits<std::uint64_t>::max(), "r").what()),
            "a.csv:18446744073709551615: r");
}

TEST(Error, ConfigErrorNamesFileKeyAndReason) {
  const ConfigError error("gaitmon.toml", "wire.sync", "must have 1 to 4 bytes");
  EXPECT_EQ(std::string(error.what()), "gaitmon.toml: wire.sync: must have 1 to 4 bytes");
  EXPECT_EQ(error.file(), "gaitmon.toml");
  EXPECT_EQ(error.key(), "wire.sync");
  EXPECT_EQ(error.reason(), "must have 1 to 4 bytes");
}

// Callers that report any failure catch std::runtime_error and print what().
TEST(Error, BothAreRuntimeErrors) {
  try {
    throw InputError("a.csv", 3, "bad");
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), "a.csv:3: bad");
  }
  try {
    throw ConfigError("c.toml", "k", "bad");
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), "c.toml: k: bad");
  }
}

}  // namespace
}  // namespace gaitmon
