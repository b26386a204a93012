// The settings of the link to an insole ([wire], [serial] and [usb] of the config): all the
// drivers take from the config, in a header of its own so that device I/O sees nothing of steps
// or the tissue model.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace gaitmon {

/// The check value that ends every insole frame (drivers/PROTOCOL.md).
enum class CrcKind { None, Crc16CcittFalse, Crc32 };

/// [wire]: the insole frame layout (drivers/PROTOCOL.md) where a bridge or vendor differs from
/// the project's default framing.
struct WireSettings {
  std::vector<std::uint8_t> sync{0xA5, 0x5A};  ///< 1-4 bytes that start every frame
  CrcKind crc = CrcKind::Crc16CcittFalse;
  bool crc_big_endian = false;  ///< byte order of the CRC field (the header is little-endian)
  /// The header's sensor count must equal the session format's count for its insole size;
  /// false accepts any count from 1 to SensorFrame::kMaxSensors.
  bool require_size_sensor_count = true;
};

enum class SerialParity { None, Odd, Even };
enum class SerialFlowControl { None, Software, Hardware };

/// [serial]: the serial link to an insole (or to a bridge) and how it reconnects.
struct SerialSettings {
  std::string device = "/dev/ttyUSB0";
  unsigned baud = 921600;
  SerialParity parity = SerialParity::None;
  int data_bits = 8;  ///< 5-8
  int stop_bits = 1;  ///< 1 or 2
  SerialFlowControl flow_control = SerialFlowControl::None;
  int reconnect_initial_ms = 50;  ///< first wait after a failure; doubles per failure
  int reconnect_max_ms = 2000;    ///< the longest wait between attempts
};

/// [usb]: an insole (or bridge) read over USB bulk transfers, and how it reconnects.
struct UsbSettings {
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  int interface = 0;
  std::uint8_t endpoint = 0x81;  ///< a bulk IN endpoint address (bit 7 set)
  int transfers = 4;             ///< bulk transfers kept in flight
  int transfer_bytes = 16384;    ///< size of each transfer's buffer
  int reconnect_initial_ms = 50;
  int reconnect_max_ms = 2000;
};

}  // namespace gaitmon
