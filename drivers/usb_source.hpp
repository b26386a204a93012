// A ByteSource over USB: libusb-1.0 asynchronous bulk IN transfers, several in flight, with
// reconnection when the device returns.
#pragma once

#include <cstdint>
#include <memory>
#include <span>

#include "drivers/byte_source.hpp"
#include "gaitmon/link_settings.hpp"

namespace gaitmon::drivers {

/// What the driver does with a completed bulk transfer. Kept apart from libusb so that tests
/// can feed it canned completions.
enum class TransferAction : std::uint8_t {
  Resubmit,    ///< data (if any) delivered; queue the transfer again
  DeviceLost,  ///< the device is gone or failed: retire the transfer and reconnect
  Retire,      ///< cancelled for shutdown: retire the transfer
};

/// `status` is a libusb_transfer_status. Delivers `data` (the transfer's actual_length bytes)
/// through on_bytes when there are any, whatever the status.
TransferAction on_transfer_complete(int status, std::span<const std::uint8_t> data, bool stopping,
                                    const ByteSource::BytesHandler& on_bytes);

/// Opens the first device with settings.vendor_id:product_id, claims settings.interface
/// (detaching a kernel driver where libusb can), and keeps settings.transfers bulk IN transfers
/// of transfer_bytes each in flight on settings.endpoint. When the device goes away it reports
/// Disconnected, cancels and retires its transfers, and tries again after reconnect_initial_ms,
/// doubling up to reconnect_max_ms (only data resets the wait, not an open or a claim); a
/// hotplug arrival (where libusb supports hotplug) ends the wait early. Events are handled with a
/// 100 ms timeout, so stop() takes effect promptly.
///
/// A transfer that overflows (the device sent more than transfer_bytes: libusb delivers what fit
/// and the rest is lost) keeps the link up but is counted in counters().transfers_overflowed, so
/// that the loss is visible; a larger transfer_bytes avoids it.
///
/// Threading: run() on one thread, once per object; stop() and counters() from any thread.
class UsbSource final : public ByteSource {
 public:
  /// Throws std::runtime_error if libusb cannot be initialised.
  explicit UsbSource(UsbSettings settings);
  ~UsbSource() override;
  UsbSource(const UsbSource&) = delete;
  UsbSource& operator=(const UsbSource&) = delete;

  void run(const BytesHandler& on_bytes, const StateHandler& on_state) override;
  void stop() override;
  SourceCounters counters() const override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gaitmon::drivers
