// A ByteSource over a serial port (Boost.Asio serial_port): a USB-serial insole bridge, or the
// pseudo-terminal of `gaitmon fake-insole`.
#pragma once

#include <memory>

#include "drivers/byte_source.hpp"
#include "gaitmon/link_settings.hpp"

namespace gaitmon::drivers {

/// Opens settings.device, applies baud, parity, data and stop bits and flow control, and
/// delivers what it reads. When the device disappears (a read error, end of file, the path
/// gone) it reports Disconnected, then Connecting, and reopens the path after
/// reconnect_initial_ms, doubling the wait after each failed attempt up to reconnect_max_ms,
/// until it opens (Connected) or stop() is called. Only data resets the wait: a device that
/// opens but fails before its first byte keeps backing off. Only changes of state are
/// reported, and a failed attempt whose error differs from the last one's (Connecting again);
/// the detail names the device and the error.
///
/// Threading: run() on one thread (the driver thread), once per object; stop() from any thread.
class SerialSource final : public ByteSource {
 public:
  explicit SerialSource(SerialSettings settings);
  ~SerialSource() override;
  SerialSource(const SerialSource&) = delete;
  SerialSource& operator=(const SerialSource&) = delete;

  void run(const BytesHandler& on_bytes, const StateHandler& on_state) override;
  void stop() override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gaitmon::drivers
