// The project's insole frame layout (drivers/PROTOCOL.md): checksums, the layout resolved from
// [wire], and the encoder the fake device and the tests use.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "gaitmon/link_settings.hpp"
#include "gaitmon/sensor_frame.hpp"

namespace gaitmon::drivers {

/// The header version this code reads and writes.
inline constexpr std::uint8_t kWireVersion = 1;
/// version, foot, insole size, sensor count (1 byte each), sequence and device time (uint32 LE).
inline constexpr std::size_t kWireHeaderBytes = 12;
inline constexpr std::size_t kMaxSyncBytes = 4;
inline constexpr std::size_t kMaxCrcBytes = 4;
/// The longest frame any [wire] setting allows.
inline constexpr std::size_t kMaxFrameBytes =
    kMaxSyncBytes + kWireHeaderBytes + SensorFrame::kMaxSensors + kMaxCrcBytes;

/// CRC-16/CCITT-FALSE: polynomial 0x1021, initial 0xFFFF, no reflection, no final xor.
/// "123456789" gives 0x29B1.
std::uint16_t crc16_ccitt_false(std::span<const std::uint8_t> data);
/// CRC-32 as zlib and Ethernet compute it (ISO-HDLC). "123456789" gives 0xCBF43926.
std::uint32_t crc32_iso_hdlc(std::span<const std::uint8_t> data);

/// The frame layout resolved from [wire]: fixed size, so a decoder holds it without allocating.
class WireFormat {
 public:
  /// The project's default framing: sync A5 5A, CRC-16/CCITT-FALSE little-endian, sensor count
  /// fixed by the insole size.
  WireFormat() = default;
  /// Throws std::invalid_argument for a sync pattern of 0 or more than 4 bytes.
  explicit WireFormat(const WireSettings& settings);

  std::span<const std::uint8_t> sync() const { return {sync_.data(), sync_length_}; }
  CrcKind crc() const { return crc_; }
  bool crc_big_endian() const { return crc_big_endian_; }
  bool require_size_sensor_count() const { return require_size_sensor_count_; }
  std::size_t crc_bytes() const;
  /// Sync + header + sensor bytes + CRC.
  std::size_t frame_bytes(std::size_t sensor_count) const {
    return sync_length_ + kWireHeaderBytes + sensor_count + crc_bytes();
  }
  /// The check value of header and sensor bytes (0 for CrcKind::None).
  std::uint32_t checksum(std::span<const std::uint8_t> header_and_payload) const;

 private:
  // The defaults equal WireSettings{}; spelt out because g++ 12 warns (falsely) about
  // delegating to the constructor that copies the settings' vector.
  std::array<std::uint8_t, kMaxSyncBytes> sync_{0xA5, 0x5A};
  std::size_t sync_length_ = 2;
  CrcKind crc_ = CrcKind::Crc16CcittFalse;
  bool crc_big_endian_ = false;
  bool require_size_sensor_count_ = true;
};

/// Writes `frame` in the wire format to the start of `out` and returns the bytes written
/// (format.frame_bytes(frame.sensor_count)). host_time_ns is not sent. Throws
/// std::invalid_argument when sensor_count is 0 or above kMaxSensors, does not match the size
/// while the format requires it to, or `out` is too small.
std::size_t encode_frame(const WireFormat& format, const SensorFrame& frame,
                         std::span<std::uint8_t> out);

}  // namespace gaitmon::drivers
