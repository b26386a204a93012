// The USB driver without a device: the completion handler fed canned transfers, and a device
// that is absent (Connecting until stop(), which is prompt). Streaming, device loss and
// reconnection run against an emulated usbfs in usb_source_usbfs_test.
#include "drivers/usb_source.hpp"

#include <gtest/gtest.h>
#include <libusb.h>

#include <chrono>
#include <mutex>
#include <thread>
#include <vector>

namespace gaitmon::drivers {
namespace {

using namespace std::chrono_literals;

struct Delivered {
  std::vector<std::uint8_t> bytes;
  int calls = 0;
  ByteSource::BytesHandler handler() {
    return [this](std::span<const std::uint8_t> data) {
      bytes.insert(bytes.end(), data.begin(), data.end());
      ++calls;
    };
  }
};

TEST(UsbTransfer, ACompletedTransferIsDeliveredAndResubmitted) {
  Delivered out;
  const std::vector<std::uint8_t> data{0xA5, 0x5A, 1, 2, 3};
  EXPECT_EQ(on_transfer_complete(LIBUSB_TRANSFER_COMPLETED, data, false, out.handler()),
            TransferAction::Resubmit);
  EXPECT_EQ(out.bytes, data);
  EXPECT_EQ(on_transfer_complete(LIBUSB_TRANSFER_COMPLETED, {}, false, out.handler()),
            TransferAction::Resubmit);
  EXPECT_EQ(out.calls, 1);  // an empty transfer delivers nothing
}

TEST(UsbTransfer, TimeoutsAndOverflowsKeepStreaming) {
  Delivered out;
  const std::vector<std::uint8_t> partial{7, 8};
  EXPECT_EQ(on_transfer_complete(LIBUSB_TRANSFER_TIMED_OUT, partial, false, out.handler()),
            TransferAction::Resubmit);
  EXPECT_EQ(on_transfer_complete(LIBUSB_TRANSFER_OVERFLOW, {}, false, out.handler()),
            TransferAction::Resubmit);
  EXPECT_EQ(out.bytes, partial);
}

TEST(UsbTransfer, AVanishedOrFailedDeviceIsLost) {
  Delivered out;
  for (int status : {LIBUSB_TRANSFER_NO_DEVICE, LIBUSB_TRANSFER_ERROR, LIBUSB_TRANSFER_STALL}) {
    EXPECT_EQ(on_transfer_complete(status, {}, false, out.handler()), TransferAction::DeviceLost)
        << status;
  }
  // A cancellation nobody asked for (another process reset the device) is a loss too.
  EXPECT_EQ(on_transfer_complete(LIBUSB_TRANSFER_CANCELLED, {}, false, out.handler()),
            TransferAction::DeviceLost);
  EXPECT_EQ(out.calls, 0);
}

TEST(UsbTransfer, StoppingRetiresTransfersButStillDeliversTheirData) {
  Delivered out;
  const std::vector<std::uint8_t> last{9};
  EXPECT_EQ(on_transfer_complete(LIBUSB_TRANSFER_CANCELLED, last, true, out.handler()),
            TransferAction::Retire);
  EXPECT_EQ(on_transfer_complete(LIBUSB_TRANSFER_COMPLETED, {}, true, out.handler()),
            TransferAction::Retire);
  EXPECT_EQ(out.bytes, last);
}

TEST(UsbSource, WaitsForAnAbsentDeviceAndStopsPromptly) {
  UsbSettings settings;
  settings.vendor_id = 0xFFFF;  // reserved: no real device has it
  settings.product_id = 0xFFFF;
  settings.reconnect_initial_ms = 10;
  settings.reconnect_max_ms = 40;
  UsbSource source(settings);
  std::mutex mutex;
  std::vector<LinkState> states;
  std::thread driver([&] {
    source.run([](std::span<const std::uint8_t>) {},
               [&](LinkState state, std::string_view) {
                 std::lock_guard lock(mutex);
                 states.push_back(state);
               });
  });
  // Time for waits of 10, 20, 40, 40, ... ms; the retries themselves are counted against an
  // emulated device in usb_source_usbfs_test. Here: no state but Connecting meanwhile, and a
  // stop that ends whichever wait it meets.
  std::this_thread::sleep_for(300ms);
  {
    std::lock_guard lock(mutex);
    EXPECT_EQ(states, std::vector<LinkState>{LinkState::Connecting});
  }
  const auto before = std::chrono::steady_clock::now();
  source.stop();
  driver.join();
  // Events are handled with a 100 ms timeout: seconds would mean a wait that stop() misses.
  EXPECT_LT(std::chrono::steady_clock::now() - before, 5s);
  EXPECT_EQ(states, (std::vector<LinkState>{LinkState::Connecting, LinkState::Disconnected}));
}

TEST(UsbSource, StopBeforeRunReturnsAtOnce) {
  UsbSource source(UsbSettings{});
  source.stop();
  int calls = 0;
  source.run([&](std::span<const std::uint8_t>) { ++calls; },
             [&](LinkState, std::string_view) { ++calls; });
  EXPECT_EQ(calls, 0);
}

}  // namespace
}  // namespace gaitmon::drivers
