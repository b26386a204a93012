// The USB driver against the real libusb, with the kernel's side emulated (usbfs_insole.hpp):
// the transfer pool, resubmission, device loss, cancellation at shutdown, reconnection with
// backoff and the hotplug wake-up, none of which the canned completions in usb_source_test reach.
#include <gtest/gtest.h>
#include <linux/usbdevice_fs.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/usb_source.hpp"
#include "drivers/usbfs_insole.hpp"

namespace gaitmon::drivers {
namespace {

using namespace std::chrono_literals;

/// A UsbSource run on its own thread, with what it delivered and reported.
class Driver {
 public:
  explicit Driver(UsbSettings settings) : source_(settings) {
    thread_ = std::thread([this] {
      source_.run(
          [this](std::span<const std::uint8_t> data) {
            std::lock_guard lock(mutex_);
            bytes_.insert(bytes_.end(), data.begin(), data.end());
            changed_.notify_all();
          },
          [this](LinkState state, std::string_view detail) {
            std::lock_guard lock(mutex_);
            states_.push_back(state);
            details_.emplace_back(detail);
            changed_.notify_all();
          });
    });
  }
  ~Driver() { stop(); }
  Driver(const Driver&) = delete;
  Driver& operator=(const Driver&) = delete;

  void stop() {
    source_.stop();
    if (thread_.joinable()) thread_.join();
  }

  /// Waits up to `limit` for `done` to hold; true if it did.
  bool wait_until(const std::function<bool()>& done, std::chrono::milliseconds limit = 5s) {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, limit, done);
  }
  bool wait_for_bytes(std::size_t count, std::chrono::milliseconds limit = 5s) {
    return wait_until([&] { return bytes_.size() >= count; }, limit);
  }
  bool wait_for_state_count(LinkState state, int count, std::chrono::milliseconds limit = 5s) {
    return wait_until([&] { return std::count(states_.begin(), states_.end(), state) >= count; },
                      limit);
  }
  bool wait_until_last_state(LinkState state) {
    return wait_until([&] { return !states_.empty() && states_.back() == state; });
  }

  std::vector<std::uint8_t> bytes() const {
    std::lock_guard lock(mutex_);
    return bytes_;
  }
  std::vector<LinkState> states() const {
    std::lock_guard lock(mutex_);
    return states_;
  }
  std::vector<std::string> details() const {
    std::lock_guard lock(mutex_);
    return details_;
  }
  SourceCounters counters() const { return source_.counters(); }

 private:
  UsbSource source_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::uint8_t> bytes_;
  std::vector<LinkState> states_;
  std::vector<std::string> details_;
  std::thread thread_;
};

/// Polls `done` (state the driver does not signal) every few milliseconds, up to `limit`.
bool eventually(const std::function<bool()>& done, std::chrono::milliseconds limit = 5s) {
  const auto until = std::chrono::steady_clock::now() + limit;
  while (!done()) {
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(5ms);
  }
  return true;
}

UsbSettings insole_settings() {
  UsbSettings settings;
  settings.vendor_id = test::kUsbfsVendorId;
  settings.product_id = test::kUsbfsProductId;
  settings.transfers = 4;
  settings.transfer_bytes = 512;
  settings.reconnect_initial_ms = 20;
  settings.reconnect_max_ms = 80;
  return settings;
}

/// `count` chunks of distinct lengths and contents, and their concatenation.
std::vector<std::vector<std::uint8_t>> chunks(int count, int first_value) {
  std::vector<std::vector<std::uint8_t>> out;
  for (int i = 0; i < count; ++i) {
    std::vector<std::uint8_t> chunk(static_cast<std::size_t>(1 + (i * 37) % 500));
    for (std::size_t j = 0; j < chunk.size(); ++j) {
      chunk[j] = static_cast<std::uint8_t>(first_value + i * 7 + static_cast<int>(j));
    }
    out.push_back(std::move(chunk));
  }
  return out;
}

std::vector<std::uint8_t> joined(const std::vector<std::vector<std::uint8_t>>& parts) {
  std::vector<std::uint8_t> out;
  for (const auto& part : parts) out.insert(out.end(), part.begin(), part.end());
  return out;
}

TEST(UsbSourceOnUsbfs, StreamsTheDevicesBytesInOrderThroughItsTransfersInFlight) {
  test::UsbfsInsole insole;
  insole.plug();
  UsbSettings settings = insole_settings();
  Driver driver(settings);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 1));
  const auto sent = chunks(200, 3);
  for (const auto& chunk : sent) insole.send(chunk);
  const std::vector<std::uint8_t> expected = joined(sent);
  ASSERT_TRUE(driver.wait_for_bytes(expected.size()));
  EXPECT_TRUE(eventually([&] { return insole.counts().in_flight == settings.transfers; }));
  driver.stop();

  EXPECT_EQ(driver.bytes(), expected);
  EXPECT_EQ(driver.states(), (std::vector<LinkState>{LinkState::Connecting, LinkState::Connected,
                                                     LinkState::Disconnected}));
  EXPECT_EQ(driver.details().back(), "usb 1209:0001 interface 0 endpoint 0x81: stopped");
  const test::UsbfsInsole::Counts counts = insole.counts();
  EXPECT_EQ(counts.claimed_interfaces, std::vector<unsigned>{0});
  EXPECT_EQ(counts.releases, 1);
  // Every completion was resubmitted: the pool's four, then one per chunk.
  EXPECT_EQ(counts.submits, settings.transfers + static_cast<int>(sent.size()));
  EXPECT_EQ(counts.max_in_flight, settings.transfers);
  for (int i = 0; i < counts.submits; ++i) {
    const auto k = static_cast<std::size_t>(i);
    EXPECT_EQ(counts.urb_lengths[k], settings.transfer_bytes);
    EXPECT_EQ(counts.urb_endpoints[k], 0x81);
    EXPECT_EQ(counts.urb_types[k], USBDEVFS_URB_TYPE_BULK);
  }
  // stop() cancelled the four in flight, and each came back before the handle was closed.
  EXPECT_EQ(counts.discards, settings.transfers);
  EXPECT_EQ(counts.in_flight, 0);
}

TEST(UsbSourceOnUsbfs, AnOverflowingTransferDeliversWhatFitIsCountedAndKeepsStreaming) {
  test::UsbfsInsole insole;
  insole.plug();
  const UsbSettings settings = insole_settings();
  Driver driver(settings);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 1));
  EXPECT_EQ(driver.counters().transfers_overflowed, 0u);
  insole.send(std::vector<std::uint8_t>(700, 0xAB));  // the buffer takes 512
  ASSERT_TRUE(driver.wait_for_bytes(512));
  // Counted before its bytes were delivered.
  EXPECT_EQ(driver.counters().transfers_overflowed, 1u);
  // The overflowing transfer went back in flight, and nothing was cancelled.
  EXPECT_TRUE(eventually([&] { return insole.counts().submits == settings.transfers + 1; }));
  insole.send({1, 2, 3});
  ASSERT_TRUE(driver.wait_for_bytes(515));
  EXPECT_EQ(driver.counters().transfers_overflowed, 1u);
  EXPECT_EQ(insole.counts().discards, 0);
  EXPECT_EQ(driver.states(), (std::vector<LinkState>{LinkState::Connecting, LinkState::Connected}));
  driver.stop();
  std::vector<std::uint8_t> expected(515, 0xAB);
  expected[512] = 1;
  expected[513] = 2;
  expected[514] = 3;
  EXPECT_EQ(driver.bytes(), expected);
}

TEST(UsbSourceOnUsbfs, AnUnpluggedDeviceIsReportedAndReconnectedOnItsHotplugArrival) {
  test::UsbfsInsole insole;
  insole.plug();
  UsbSettings settings = insole_settings();
  // Longer than the test waits: only the hotplug arrival can end the wait in time.
  settings.reconnect_initial_ms = 20000;
  settings.reconnect_max_ms = 20000;
  Driver driver(settings);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 1));
  const auto before = chunks(20, 11);
  for (const auto& chunk : before) insole.send(chunk);
  ASSERT_TRUE(driver.wait_for_bytes(joined(before).size()));

  insole.unplug();
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Disconnected, 1));
  std::this_thread::sleep_for(200ms);
  // Waiting out the backoff: no new attempt yet.
  EXPECT_EQ(driver.states(), (std::vector<LinkState>{LinkState::Connecting, LinkState::Connected,
                                                     LinkState::Disconnected}));
  EXPECT_EQ(driver.details()[2], "usb 1209:0001 interface 0 endpoint 0x81: LIBUSB_ERROR_NO_DEVICE");

  const auto replugged = std::chrono::steady_clock::now();
  insole.plug();
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 2, 10s));
  EXPECT_LT(std::chrono::steady_clock::now() - replugged, 5s);
  const auto after = chunks(20, 101);
  for (const auto& chunk : after) insole.send(chunk);
  std::vector<std::uint8_t> expected = joined(before);
  const std::vector<std::uint8_t> rest = joined(after);
  expected.insert(expected.end(), rest.begin(), rest.end());
  ASSERT_TRUE(driver.wait_for_bytes(expected.size()));
  driver.stop();
  EXPECT_EQ(driver.bytes(), expected);
  EXPECT_EQ(insole.counts().claims, 2);
  EXPECT_EQ(insole.counts().releases, 2);
}

TEST(UsbSourceOnUsbfs, AFailedTransferLosesTheLinkAndTheDriverReconnects) {
  struct Case {
    int status;
    const char* reason;
  };
  for (const Case& c : {Case{-EPIPE, "LIBUSB_ERROR_IO"}, Case{-EPROTO, "LIBUSB_ERROR_IO"},
                        Case{-ENODEV, "LIBUSB_ERROR_NO_DEVICE"}}) {
    SCOPED_TRACE(c.status);
    test::UsbfsInsole insole;
    insole.plug();
    Driver driver(insole_settings());
    ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 1));
    insole.fail_urbs(1, c.status);
    ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 2));
    EXPECT_EQ(driver.details()[2],
              std::string("usb 1209:0001 interface 0 endpoint 0x81: ") + c.reason);
    insole.send({7, 8, 9});
    ASSERT_TRUE(driver.wait_for_bytes(3));
    driver.stop();
    EXPECT_EQ(driver.bytes(), (std::vector<std::uint8_t>{7, 8, 9}));
    // A stall halts the endpoint until cleared: data flows again only because the driver
    // cleared it when it reconnected.
    EXPECT_EQ(insole.counts().clear_halts, c.status == -EPIPE ? 1 : 0);
    EXPECT_EQ(driver.states(),
              (std::vector<LinkState>{LinkState::Connecting, LinkState::Connected,
                                      LinkState::Disconnected, LinkState::Connecting,
                                      LinkState::Connected, LinkState::Disconnected}));
  }
}

TEST(UsbSourceOnUsbfs, ARefusedSubmissionLosesTheLinkAndIsRetriedWithBackoff) {
  test::UsbfsInsole insole;
  insole.plug();
  insole.refuse_submits(true);
  UsbSettings settings = insole_settings();
  settings.reconnect_initial_ms = 10;
  settings.reconnect_max_ms = 10000;
  Driver driver(settings);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Disconnected, 3));
  EXPECT_EQ(driver.details()[2], "usb 1209:0001 interface 0 endpoint 0x81: LIBUSB_ERROR_IO");
  ASSERT_TRUE(eventually([&] { return insole.counts().claim_times.size() >= 6; }, 10s));
  const std::vector<std::chrono::steady_clock::time_point> tries = insole.counts().claim_times;
  // A claim without data does not reset the backoff: waits of 10, 20, 40, 80, 160 ms between
  // the first six connections (a reset per claim would wait 10 ms each, 50 ms in all).
  EXPECT_GE(tries[5] - tries[0], 300ms);  // 310 ms, less the clocks' granularity
  EXPECT_GE(insole.counts().refused_submits, 3);
  EXPECT_EQ(insole.counts().submits, 0);
  insole.refuse_submits(false);
  insole.send({42});
  ASSERT_TRUE(driver.wait_for_bytes(1));
  // The completion that brought 42 resubmits its transfer after handing the bytes over; refusing
  // before that (under TSan it can come late) would leave no transfer for 43 to complete.
  ASSERT_TRUE(eventually([&] { return insole.counts().in_flight == settings.transfers; }, 10s));
  // A refused resubmission, from the completion callback, loses the link the same way.
  insole.refuse_submits(true);
  insole.send({43});
  ASSERT_TRUE(driver.wait_for_bytes(2));
  ASSERT_TRUE(driver.wait_until_last_state(LinkState::Disconnected));
  driver.stop();
  EXPECT_EQ(driver.bytes(), (std::vector<std::uint8_t>{42, 43}));
  const std::vector<LinkState> states = driver.states();
  const auto last_connect = std::find(states.rbegin(), states.rend(), LinkState::Connected);
  const auto lost = static_cast<std::size_t>(states.rend() - last_connect);
  ASSERT_LT(lost, states.size());
  EXPECT_EQ(states[lost], LinkState::Disconnected);
  EXPECT_EQ(driver.details()[lost], "usb 1209:0001 interface 0 endpoint 0x81: LIBUSB_ERROR_IO");
}

TEST(UsbSourceOnUsbfs, AnInterfaceInUseIsRetriedWithABackoffThatDataResets) {
  test::UsbfsInsole insole;
  insole.plug();
  insole.refuse_claims(true);
  UsbSettings settings = insole_settings();
  settings.reconnect_initial_ms = 10;
  settings.reconnect_max_ms = 10000;
  Driver driver(settings);
  ASSERT_TRUE(eventually([&] { return insole.counts().refused_claims >= 8; }, 10s));
  const std::vector<std::chrono::steady_clock::time_point> tries = insole.counts().claim_times;
  // Waits of 10, 20, 40, ..., 640 ms between the first eight attempts (a constant 10 ms backoff
  // would take 70 ms).
  EXPECT_GE(tries[7] - tries[0], 1200ms);  // 1270 ms, less the clocks' granularity
  // Why it does not connect is said once, not at each of the eight attempts.
  EXPECT_EQ(driver.states(),
            (std::vector<LinkState>{LinkState::Connecting, LinkState::Connecting}));
  EXPECT_EQ(driver.details()[1],
            "usb 1209:0001 interface 0 endpoint 0x81: cannot claim the interface: "
            "LIBUSB_ERROR_BUSY");

  insole.refuse_claims(false);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 1, 10s));
  // Data reset the backoff: after a loss the driver retries within 10 ms, where the backoff it
  // had reached would wait 2.56 s; 2 s leaves a loaded sanitizer build room to reconnect.
  insole.send({1});
  ASSERT_TRUE(driver.wait_for_bytes(1));
  insole.fail_urbs(1, -EPIPE);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Disconnected, 1));
  const auto lost = std::chrono::steady_clock::now();
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 2));
  EXPECT_LT(std::chrono::steady_clock::now() - lost, 2s);
  driver.stop();
  EXPECT_EQ(insole.counts().claims, 2);
}

TEST(UsbSourceOnUsbfs, ATransferThatIsNeverGivenBackDoesNotHangStop) {
  test::UsbfsInsole insole;
  insole.plug();
  insole.keep_cancelled_urbs(true);
  Driver driver(insole_settings());
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 1));
  insole.send({5});
  ASSERT_TRUE(driver.wait_for_bytes(1));
  const auto before = std::chrono::steady_clock::now();
  driver.stop();
  const auto took = std::chrono::steady_clock::now() - before;
  EXPECT_GE(took, 900ms);  // the driver waited its second for the cancellations
  EXPECT_LT(took, 5s);
  EXPECT_EQ(driver.states().back(), LinkState::Disconnected);
  EXPECT_EQ(insole.counts().discards, 4);
}

}  // namespace
}  // namespace gaitmon::drivers

int main(int argc, char** argv) {
  return gaitmon::test::run_tests_with_umockdev(argc, argv);
}
