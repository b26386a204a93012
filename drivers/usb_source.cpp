// The USB driver: one libusb context per source, a pool of bulk IN transfers resubmitted from
// their completion callback, and a reconnect loop. Exceptions never cross the libusb callback:
// the handlers must not throw (they are the driver thread's own code).
#include "drivers/usb_source.hpp"

#include <fmt/format.h>
#include <libusb.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <stdexcept>
#include <string>
#include <vector>

namespace gaitmon::drivers {

TransferAction on_transfer_complete(int status, std::span<const std::uint8_t> data, bool stopping,
                                    const ByteSource::BytesHandler& on_bytes) {
  if (!data.empty()) on_bytes(data);
  switch (status) {
    case LIBUSB_TRANSFER_COMPLETED:
    case LIBUSB_TRANSFER_TIMED_OUT:
    case LIBUSB_TRANSFER_OVERFLOW:  // the device sent more than asked; the rest is lost
      return stopping ? TransferAction::Retire : TransferAction::Resubmit;
    case LIBUSB_TRANSFER_CANCELLED:
      return stopping ? TransferAction::Retire : TransferAction::DeviceLost;
    default:  // NO_DEVICE, ERROR, STALL
      return TransferAction::DeviceLost;
  }
}

struct UsbSource::Impl {
  explicit Impl(UsbSettings s) : settings(s) {
    if (const int rc = libusb_init(&context); rc != 0) {
      throw std::runtime_error(std::string("libusb_init: ") + libusb_error_name(rc));
    }
  }
  ~Impl() { libusb_exit(context); }

  struct Slot {
    Impl* owner = nullptr;
    libusb_transfer* transfer = nullptr;
    std::vector<std::uint8_t> buffer;
    bool in_flight = false;
  };

  UsbSettings settings;
  libusb_context* context = nullptr;
  std::atomic<bool> stopping{false};
  std::atomic<std::uint64_t> transfers_overflowed{0};  ///< written by the driver thread only
  bool arrived = false;  ///< set by the hotplug callback on the driver thread
  bool lost = false;
  bool received = false;  ///< the current connection has delivered bytes
  /// A transfer stalled: the device keeps the endpoint halted, across a reopen too, until a
  /// clear.
  bool halted = false;
  std::string lost_reason;
  const BytesHandler* on_bytes = nullptr;
  std::vector<Slot> slots;

  static void LIBUSB_CALL completed(libusb_transfer* transfer) {
    auto* slot = static_cast<Slot*>(transfer->user_data);
    Impl& d = *slot->owner;
    slot->in_flight = false;
    if (transfer->actual_length > 0) d.received = true;
    if (transfer->status == LIBUSB_TRANSFER_STALL) d.halted = true;
    // Before the bytes are delivered, so that whoever has seen them also sees the count.
    if (transfer->status == LIBUSB_TRANSFER_OVERFLOW) {
      d.transfers_overflowed.fetch_add(1, std::memory_order_relaxed);
    }
    const std::span<const std::uint8_t> data(transfer->buffer,
                                             static_cast<std::size_t>(transfer->actual_length));
    const TransferAction action =
        on_transfer_complete(transfer->status, data, d.stopping.load() || d.lost, *d.on_bytes);
    if (action == TransferAction::Resubmit) {
      const int rc = libusb_submit_transfer(transfer);
      if (rc == 0) {
        slot->in_flight = true;
        return;
      }
      d.mark_lost(libusb_error_name(rc));
    } else if (action == TransferAction::DeviceLost) {
      d.mark_lost(libusb_error_name(transfer->status == LIBUSB_TRANSFER_NO_DEVICE
                                        ? LIBUSB_ERROR_NO_DEVICE
                                        : LIBUSB_ERROR_IO));
    }
  }

  static int LIBUSB_CALL hotplug(libusb_context*, libusb_device*, libusb_hotplug_event,
                                 void* user) {
    static_cast<Impl*>(user)->arrived = true;
    return 0;
  }

  void mark_lost(const std::string& reason) {
    if (!lost) lost_reason = reason;
    lost = true;
  }

  void handle_events_for(std::chrono::milliseconds span) {
    timeval tv{0, static_cast<long>(std::chrono::microseconds(span).count())};
    libusb_handle_events_timeout_completed(context, &tv, nullptr);
  }

  // Waits `backoff`, handling hotplug events; returns early on stop or an arrival.
  void wait(std::chrono::milliseconds backoff) {
    const auto until = std::chrono::steady_clock::now() + backoff;
    arrived = false;
    while (!stopping.load() && !arrived) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          until - std::chrono::steady_clock::now());
      if (left.count() <= 0) return;
      handle_events_for(std::min(left, std::chrono::milliseconds(100)));
    }
  }

  // Streams from an open, claimed device until it is lost or stop() is called. The slots stay
  // allocated until free_slots(), after the handle is closed.
  void stream(libusb_device_handle* handle) {
    lost = false;
    received = false;
    slots.assign(static_cast<std::size_t>(settings.transfers), Slot{});
    for (Slot& slot : slots) {
      slot.owner = this;
      // Out of memory is a lost connection, not an exception: the transfers already submitted
      // must be cancelled and the handle closed on the way out, as for any loss.
      try {
        slot.buffer.resize(static_cast<std::size_t>(settings.transfer_bytes));
      } catch (const std::bad_alloc&) {
        mark_lost("out of memory for the transfer buffers");
        break;
      }
      slot.transfer = libusb_alloc_transfer(0);
      if (slot.transfer == nullptr) {
        mark_lost("libusb_alloc_transfer: out of memory");
        break;
      }
      libusb_fill_bulk_transfer(slot.transfer, handle, settings.endpoint, slot.buffer.data(),
                                settings.transfer_bytes, &Impl::completed, &slot, 0);
      if (const int rc = libusb_submit_transfer(slot.transfer); rc != 0) {
        mark_lost(libusb_error_name(rc));
        break;
      }
      slot.in_flight = true;
    }
    while (!stopping.load() && !lost) handle_events_for(std::chrono::milliseconds(100));
    for (Slot& slot : slots) {
      if (slot.in_flight) libusb_cancel_transfer(slot.transfer);
    }
    // Cancelled transfers complete through the callback; a vanished device completes them
    // all at once. Bounded, so a wedged host controller cannot hang shutdown.
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(1);
    while (std::any_of(slots.begin(), slots.end(), [](const Slot& s) { return s.in_flight; }) &&
           std::chrono::steady_clock::now() < give_up) {
      handle_events_for(std::chrono::milliseconds(50));
    }
  }

  // A transfer that never came back from its cancellation is safe to free only once the handle
  // is closed: libusb then drops it from its in-flight list, and closing the usbfs file makes
  // the kernel kill its URB, so nothing writes into the buffer any more.
  void free_slots() {
    for (Slot& slot : slots) {
      if (slot.transfer != nullptr) libusb_free_transfer(slot.transfer);
    }
    slots.clear();
  }
};

UsbSource::UsbSource(UsbSettings settings) : impl_(std::make_unique<Impl>(settings)) {}

UsbSource::~UsbSource() = default;

void UsbSource::run(const BytesHandler& on_bytes, const StateHandler& on_state) {
  Impl& d = *impl_;
  if (d.stopping.load()) return;
  d.on_bytes = &on_bytes;
  const std::string name =
      fmt::format("usb {:04x}:{:04x} interface {} endpoint {:#04x}", d.settings.vendor_id,
                  d.settings.product_id, d.settings.interface, d.settings.endpoint);
  libusb_hotplug_callback_handle hotplug_handle = 0;
  const bool hotplug = libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) != 0 &&
                       libusb_hotplug_register_callback(
                           d.context, LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED, LIBUSB_HOTPLUG_NO_FLAGS,
                           d.settings.vendor_id, d.settings.product_id, LIBUSB_HOTPLUG_MATCH_ANY,
                           &Impl::hotplug, &d, &hotplug_handle) == 0;
  auto backoff = std::chrono::milliseconds(d.settings.reconnect_initial_ms);
  const auto max_backoff = std::chrono::milliseconds(d.settings.reconnect_max_ms);
  LinkState state = LinkState::Connecting;
  on_state(state, name);
  // A claim refused (another program holds the interface, no permission) says why once, not at
  // every attempt; a new reason says it again.
  std::string claim_error;
  while (!d.stopping.load()) {
    if (state == LinkState::Disconnected) {
      state = LinkState::Connecting;
      on_state(state, name);
    }
    libusb_device_handle* handle =
        libusb_open_device_with_vid_pid(d.context, d.settings.vendor_id, d.settings.product_id);
    if (handle != nullptr) {
      libusb_set_auto_detach_kernel_driver(handle, 1);
      const int claimed = libusb_claim_interface(handle, d.settings.interface);
      if (claimed != 0 && claim_error != libusb_error_name(claimed)) {
        claim_error = libusb_error_name(claimed);
        on_state(LinkState::Connecting, name + ": cannot claim the interface: " + claim_error);
      }
      if (claimed == 0) {
        claim_error.clear();
        // A clear that fails leaves the endpoint stalling: the link is lost again and retried.
        if (d.halted && libusb_clear_halt(handle, d.settings.endpoint) == 0) d.halted = false;
        state = LinkState::Connected;
        on_state(state, name);
        d.stream(handle);
        // Data, not a claim alone, shows the device works: one that fails its first transfer
        // keeps backing off.
        if (d.received) backoff = std::chrono::milliseconds(d.settings.reconnect_initial_ms);
        libusb_release_interface(handle, d.settings.interface);
        if (!d.stopping.load()) {
          state = LinkState::Disconnected;
          on_state(state, name + ": " + d.lost_reason);
        }
      }
      libusb_close(handle);
      d.free_slots();
    }
    if (d.stopping.load()) break;
    d.wait(backoff);
    backoff = std::min(backoff * 2, max_backoff);
  }
  if (hotplug) libusb_hotplug_deregister_callback(d.context, hotplug_handle);
  if (state != LinkState::Disconnected) on_state(LinkState::Disconnected, name + ": stopped");
}

SourceCounters UsbSource::counters() const {
  SourceCounters c;
  c.transfers_overflowed = impl_->transfers_overflowed.load(std::memory_order_relaxed);
  return c;
}

void UsbSource::stop() {
  impl_->stopping.store(true);
  libusb_interrupt_event_handler(impl_->context);
}

}  // namespace gaitmon::drivers
