// Table-driven checksums and the frame encoder of the project's wire format.
#include "drivers/wire_format.hpp"

#include <stdexcept>
#include <string>

#include "gaitmon/types.hpp"

namespace gaitmon::drivers {
namespace {

// Slicing-by-8 tables: table[k][x] is the CRC contribution of byte x followed by k zero
// bytes, so eight bytes are folded in with eight independent lookups (CRC dominated the
// decoder's profile with one lookup per byte).
constexpr std::array<std::array<std::uint16_t, 256>, 8> make_crc16_tables() {
  std::array<std::array<std::uint16_t, 256>, 8> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t crc = i << 8;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 0x8000U) != 0 ? (crc << 1) ^ 0x1021U : crc << 1;
    t[0][i] = static_cast<std::uint16_t>(crc);
  }
  for (std::size_t k = 1; k < 8; ++k) {
    for (std::size_t i = 0; i < 256; ++i) {
      const std::uint16_t prev = t[k - 1][i];
      t[k][i] = static_cast<std::uint16_t>((prev << 8) ^ t[0][prev >> 8]);
    }
  }
  return t;
}

constexpr std::array<std::array<std::uint32_t, 256>, 8> make_crc32_tables() {
  std::array<std::array<std::uint32_t, 256>, 8> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t crc = i;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 1U) != 0 ? (crc >> 1) ^ 0xEDB88320U : crc >> 1;
    t[0][i] = crc;
  }
  for (std::size_t k = 1; k < 8; ++k) {
    for (std::size_t i = 0; i < 256; ++i) {
      const std::uint32_t prev = t[k - 1][i];
      t[k][i] = (prev >> 8) ^ t[0][prev & 0xFFU];
    }
  }
  return t;
}

constexpr auto kCrc16 = make_crc16_tables();
constexpr auto kCrc32 = make_crc32_tables();

std::uint32_t get_u32_le(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

void put_u32_le(std::uint8_t* out, std::uint32_t value) {
  for (int i = 0; i < 4; ++i) out[i] = static_cast<std::uint8_t>(value >> (8 * i));
}

}  // namespace

std::uint16_t crc16_ccitt_false(std::span<const std::uint8_t> data) {
  std::uint32_t crc = 0xFFFF;
  const std::uint8_t* p = data.data();
  std::size_t n = data.size();
  for (; n >= 8; n -= 8, p += 8) {
    crc = kCrc16[7][p[0] ^ (crc >> 8)] ^ kCrc16[6][p[1] ^ (crc & 0xFFU)] ^ kCrc16[5][p[2]] ^
          kCrc16[4][p[3]] ^ kCrc16[3][p[4]] ^ kCrc16[2][p[5]] ^ kCrc16[1][p[6]] ^ kCrc16[0][p[7]];
  }
  for (; n > 0; --n, ++p) crc = ((crc << 8) & 0xFFFFU) ^ kCrc16[0][(crc >> 8) ^ *p];
  return static_cast<std::uint16_t>(crc);
}

std::uint32_t crc32_iso_hdlc(std::span<const std::uint8_t> data) {
  std::uint32_t crc = 0xFFFFFFFFU;
  const std::uint8_t* p = data.data();
  std::size_t n = data.size();
  for (; n >= 8; n -= 8, p += 8) {
    const std::uint32_t lo = crc ^ get_u32_le(p);
    const std::uint32_t hi = get_u32_le(p + 4);
    crc = kCrc32[7][lo & 0xFFU] ^ kCrc32[6][(lo >> 8) & 0xFFU] ^ kCrc32[5][(lo >> 16) & 0xFFU] ^
          kCrc32[4][lo >> 24] ^ kCrc32[3][hi & 0xFFU] ^ kCrc32[2][(hi >> 8) & 0xFFU] ^
          kCrc32[1][(hi >> 16) & 0xFFU] ^ kCrc32[0][hi >> 24];
  }
  for (; n > 0; --n, ++p) crc = (crc >> 8) ^ kCrc32[0][(crc ^ *p) & 0xFFU];
  return crc ^ 0xFFFFFFFFU;
}

WireFormat::WireFormat(const WireSettings& settings)
    : sync_length_(settings.sync.size()),
      crc_(settings.crc),
      crc_big_endian_(settings.crc_big_endian),
      require_size_sensor_count_(settings.require_size_sensor_count) {
  if (sync_length_ == 0 || sync_length_ > kMaxSyncBytes) {
    throw std::invalid_argument("wire format: the sync pattern must have 1 to 4 bytes, got " +
                                std::to_string(sync_length_));
  }
  for (std::size_t i = 0; i < sync_length_; ++i) sync_[i] = settings.sync[i];
}

std::size_t WireFormat::crc_bytes() const {
  switch (crc_) {
    case CrcKind::None:
      return 0;
    case CrcKind::Crc16CcittFalse:
      return 2;
    case CrcKind::Crc32:
      return 4;
  }
  return 0;
}

std::uint32_t WireFormat::checksum(std::span<const std::uint8_t> header_and_payload) const {
  switch (crc_) {
    case CrcKind::None:
      return 0;
    case CrcKind::Crc16CcittFalse:
      return crc16_ccitt_false(header_and_payload);
    case CrcKind::Crc32:
      return crc32_iso_hdlc(header_and_payload);
  }
  return 0;
}

std::size_t encode_frame(const WireFormat& format, const SensorFrame& frame,
                         std::span<std::uint8_t> out) {
  const std::size_t count = frame.sensor_count;
  if (count == 0 || count > SensorFrame::kMaxSensors) {
    throw std::invalid_argument("encode_frame: sensor_count must be 1 to 162, got " +
                                std::to_string(count));
  }
  if (format.require_size_sensor_count() && count != session_sensor_count(frame.size)) {
    throw std::invalid_argument("encode_frame: sensor_count " + std::to_string(count) +
                                " does not match insole size " +
                                std::string(insole_size_name(frame.size)));
  }
  const std::size_t total = format.frame_bytes(count);
  if (out.size() < total) {
    throw std::invalid_argument("encode_frame: the output holds " + std::to_string(out.size()) +
                                " bytes, the frame needs " + std::to_string(total));
  }
  std::uint8_t* p = out.data();
  for (std::uint8_t byte : format.sync()) *p++ = byte;
  std::uint8_t* const header = p;
  *p++ = kWireVersion;
  *p++ = static_cast<std::uint8_t>(frame.foot);
  *p++ = static_cast<std::uint8_t>(index_of(frame.size));
  *p++ = static_cast<std::uint8_t>(count);
  put_u32_le(p, frame.sequence);
  put_u32_le(p + 4, frame.device_time_us);
  p += 8;
  for (std::size_t i = 0; i < count; ++i) *p++ = frame.bits[i];
  const std::uint32_t crc = format.checksum({header, static_cast<std::size_t>(p - header)});
  const std::size_t crc_bytes = format.crc_bytes();
  for (std::size_t i = 0; i < crc_bytes; ++i) {
    const std::size_t shift = format.crc_big_endian() ? crc_bytes - 1 - i : i;
    *p++ = static_cast<std::uint8_t>(crc >> (8 * shift));
  }
  return total;
}

}  // namespace gaitmon::drivers
