// The seam between a device and the frame decoder: anything that delivers bytes (a serial port,
// a USB bulk endpoint, a recorded session played back) behind one interface.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string_view>

namespace gaitmon::drivers {

enum class LinkState : std::uint8_t { Connecting, Connected, Disconnected };
std::string_view link_state_name(LinkState state);  ///< "connecting", "connected", "disconnected"

/// What a source lost or survived below the bytes it delivered: totals since construction, across
/// reconnections. A source without such a fault reports zeros.
struct SourceCounters {
  /// USB bulk transfers that ended in LIBUSB_TRANSFER_OVERFLOW: the device sent more than the
  /// transfer's buffer holds, and the bytes beyond it are lost.
  std::uint64_t transfers_overflowed = 0;
};

class ByteSource {
 public:
  using BytesHandler = std::function<void(std::span<const std::uint8_t>)>;
  using StateHandler = std::function<void(LinkState, std::string_view detail)>;

  virtual ~ByteSource() = default;

  /// Delivers bytes until stop() is called (or, for a finite source, until it is exhausted),
  /// reconnecting with backoff when the device disappears. Handlers run on the calling thread,
  /// the driver thread, and must not block.
  virtual void run(const BytesHandler& on_bytes, const StateHandler& on_state) = 0;

  /// Makes run() return soon. Safe from any thread, and more than once.
  virtual void stop() = 0;

  /// Thread-safe and non-blocking: callable from any thread while run() delivers. Each value is
  /// consistent on its own, not across values.
  virtual SourceCounters counters() const { return {}; }
};

}  // namespace gaitmon::drivers
