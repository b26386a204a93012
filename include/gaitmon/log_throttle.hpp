// Rate limiting for warnings that can repeat many times a second (dropped frames, rejected
// frames, failed fits): one message per period, saying how many were held back.
#pragma once

#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>

namespace gaitmon {

/// Thread-safe. Typical use:
///   if (auto held = throttle.allow()) spdlog::warn("... ({} more suppressed)", *held);
class LogThrottle {
 public:
  using Clock = std::chrono::steady_clock;

  explicit LogThrottle(Clock::duration period = std::chrono::seconds(1)) : period_(period) {}

  /// Counts one occurrence. Returns the number of occurrences suppressed since the last message
  /// when a message may be logged now, nullopt when this one is to be suppressed.
  std::optional<std::uint64_t> allow(Clock::time_point now = Clock::now()) {
    const std::lock_guard lock(mutex_);
    if (logged_once_ && now - last_ < period_) {
      ++suppressed_;
      return std::nullopt;
    }
    logged_once_ = true;
    last_ = now;
    const std::uint64_t held = suppressed_;
    suppressed_ = 0;
    return held;
  }

 private:
  std::mutex mutex_;
  Clock::duration period_;
  Clock::time_point last_{};
  bool logged_once_ = false;
  std::uint64_t suppressed_ = 0;
};

}  // namespace gaitmon
