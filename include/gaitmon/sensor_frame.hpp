// One decoded insole frame as it travels from a driver through the ring buffer to the detector.
// Fixed size and trivially copyable, so the hot path never allocates.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "gaitmon/types.hpp"

namespace gaitmon {

struct SensorFrame {
  static constexpr std::size_t kMaxSensors = 162;

  Foot foot = Foot::Left;
  InsoleSize size = InsoleSize::S37_38;
  std::uint16_t sensor_count = 0;    ///< valid entries of bits
  std::uint32_t sequence = 0;        ///< the device's frame counter (wraps)
  std::uint32_t device_time_us = 0;  ///< the device's clock, microseconds (wraps after 71 min)
  std::int64_t host_time_ns = 0;     ///< std::chrono::steady_clock when the frame was decoded
  std::array<std::uint8_t, kMaxSensors> bits{};
};

}  // namespace gaitmon
