// A foot's session time from its device's 32-bit microsecond counter, which wraps after 71 min
// and restarts when the device does.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace gaitmon {

/// Unwraps the counter so that time only increases. Not thread-safe (one per foot and thread).
class DeviceClock {
 public:
  enum class Tick : std::uint8_t {
    First,     ///< the first reading: time = the counter
    Forward,   ///< advanced (across a wrap too): time advanced as much
    Repeated,  ///< the same reading again: time unchanged, the frame is a duplicate
    WentBack,  ///< the counter went back (the device restarted): time advanced one period
  };

  /// Throws std::invalid_argument unless the sample rate is positive and finite.
  explicit DeviceClock(double sample_rate_hz)
      : period_us_(std::max<std::int64_t>(1, std::llround(1e6 / checked(sample_rate_hz)))) {}

  Tick advance(std::uint32_t device_time_us) {
    Tick tick = Tick::First;
    if (!started_) {
      started_ = true;
      time_us_ = device_time_us;
    } else {
      // Modulo 2^32 a step forward, across a wrap or not, is below 2^31; anything else went back.
      const std::uint32_t delta = device_time_us - last_;
      if (delta == 0) return Tick::Repeated;
      if (delta < 0x80000000u) {
        time_us_ += delta;
        tick = Tick::Forward;
      } else {
        time_us_ += period_us_;
        tick = Tick::WentBack;
      }
    }
    last_ = device_time_us;
    return tick;
  }

  /// The unwrapped time of the latest reading, microseconds.
  std::int64_t time_us() const { return time_us_; }
  /// The same in seconds: exactly t_s for a counter written as round(t_s x 1e6).
  double t_s() const { return static_cast<double>(time_us_) / 1e6; }
  /// One sample period, the time a WentBack advances, microseconds.
  std::int64_t period_us() const { return period_us_; }

 private:
  static double checked(double rate) {
    if (!(rate > 0.0) || !std::isfinite(rate)) {
      throw std::invalid_argument("DeviceClock: the sample rate must be positive");
    }
    return rate;
  }

  std::int64_t period_us_;
  bool started_ = false;
  std::uint32_t last_ = 0;
  std::int64_t time_us_ = 0;
};

}  // namespace gaitmon
