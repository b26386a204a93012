// The USB driver against the real libusb, with the kernel's side emulated: umockdev's preload
// redirects /sys and /dev/bus/usb to a test bed, and an ioctl handler here plays an insole on
// usbfs (claim, URB submit, reap and discard). This runs the transfer pool, resubmission, device
// loss, cancellation at shutdown, reconnection with backoff and the hotplug wake-up, none of
// which the canned completions in usb_source_test reach. The process re-executes itself with the
// preload, as `umockdev-wrapper` would.
#include <dlfcn.h>
#include <gtest/gtest.h>
#include <linux/ioctl.h>
#include <linux/usbdevice_fs.h>
#include <umockdev.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/usb_source.hpp"

namespace gaitmon::drivers {
namespace {

using namespace std::chrono_literals;

constexpr std::uint16_t kVendor = 0x1209;  // pid.codes' test ids
constexpr std::uint16_t kProduct = 0x0001;
constexpr const char* kSysPath = "/sys/devices/usb1/1-1";
constexpr const char* kDevNode = "/dev/bus/usb/001/002";

// One bulk IN endpoint 0x81 on interface 0; the ids above, little-endian, at bytes 8-11.
constexpr const char* kDevice =
    "P: /devices/usb1/1-1\n"
    "N: bus/usb/001/002\n"
    "E: SUBSYSTEM=usb\n"
    "E: DEVNAME=/dev/bus/usb/001/002\n"
    "E: DEVTYPE=usb_device\n"
    "E: BUSNUM=001\n"
    "E: DEVNUM=002\n"
    "A: busnum=1\\n\n"
    "A: devnum=2\\n\n"
    "A: speed=480\\n\n"
    "A: bConfigurationValue=1\\n\n"
    "H: descriptors=120100020000004009120100000100000001"
    "090219000101008032090400000100000000070581020002"
    "00\n";

/// An insole on usbfs. Streams the chunks it is given, one per completed URB, in submission
/// order; can be unplugged, made to fail URBs or submissions, or made never to give back a
/// cancelled URB. Runs on umockdev's ioctl thread; the test thread reads it under the mutex.
class EmulatedInsole {
 public:
  EmulatedInsole() : testbed_(umockdev_testbed_new()), handler_(umockdev_ioctl_base_new()) {
    g_signal_connect_after(handler_, "handle-ioctl", G_CALLBACK(&EmulatedInsole::on_ioctl), this);
    GError* error = nullptr;
    if (umockdev_testbed_attach_ioctl(testbed_, kDevNode, handler_, &error) == 0) {
      ADD_FAILURE() << "umockdev_testbed_attach_ioctl: " << error->message;
      g_error_free(error);
    }
  }
  ~EmulatedInsole() {
    g_object_unref(testbed_);  // detaches the handler, whose thread then ends
    g_object_unref(handler_);
    for (UMockdevIoctlData* urb : flying_) umockdev_ioctl_data_unref(urb);
    for (UMockdevIoctlData* urb : discarded_) umockdev_ioctl_data_unref(urb);
  }
  EmulatedInsole(const EmulatedInsole&) = delete;
  EmulatedInsole& operator=(const EmulatedInsole&) = delete;

  void plug() {
    {
      std::lock_guard lock(mutex_);
      plugged_ = true;
    }
    GError* error = nullptr;
    if (umockdev_testbed_add_from_string(testbed_, kDevice, &error) == 0) {
      ADD_FAILURE() << "umockdev_testbed_add_from_string: " << error->message;
      g_error_free(error);
    }
  }

  /// As the kernel does on an unplug: URBs in flight end with -ESHUTDOWN, new ones are
  /// refused with ENODEV, and the device leaves sysfs with a remove uevent.
  void unplug() {
    {
      std::lock_guard lock(mutex_);
      plugged_ = false;
      fail_next_urbs_ += static_cast<int>(flying_.size());
      urb_status_ = -ESHUTDOWN;
    }
    umockdev_testbed_uevent(testbed_, kSysPath, "remove");
    umockdev_testbed_remove_device(testbed_, kSysPath);
  }

  void send(std::vector<std::uint8_t> chunk) {
    std::lock_guard lock(mutex_);
    chunks_.push_back(std::move(chunk));
  }
  /// The next `count` URBs to complete end with `status` (a negative errno) and no data.
  void fail_urbs(int count, int status) {
    std::lock_guard lock(mutex_);
    fail_next_urbs_ = count;
    urb_status_ = status;
  }
  void refuse_submits(bool refuse) {
    std::lock_guard lock(mutex_);
    refuse_submits_ = refuse;
  }
  void refuse_claims(bool refuse) {
    std::lock_guard lock(mutex_);
    refuse_claims_ = refuse;
  }
  void keep_cancelled_urbs(bool keep) {
    std::lock_guard lock(mutex_);
    keep_cancelled_ = keep;
  }

  struct Counts {
    int submits = 0;
    int refused_submits = 0;
    int claims = 0;
    int refused_claims = 0;
    std::vector<std::chrono::steady_clock::time_point> claim_times;  ///< refused or not
    int releases = 0;
    int discards = 0;
    int max_in_flight = 0;
    int in_flight = 0;
    std::vector<unsigned> claimed_interfaces;
    std::vector<int> urb_lengths;    ///< buffer_length of each submitted URB
    std::vector<int> urb_endpoints;  ///< endpoint of each submitted URB
    std::vector<int> urb_types;
  };
  Counts counts() const {
    std::lock_guard lock(mutex_);
    Counts c = counts_;
    c.in_flight = static_cast<int>(flying_.size());
    return c;
  }

 private:
  static gboolean on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer self) {
    return static_cast<EmulatedInsole*>(self)->handle(client);
  }

  gboolean handle(UMockdevIoctlClient* client) {
    std::lock_guard lock(mutex_);
    UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
    switch (umockdev_ioctl_client_get_request(client)) {
      case USBDEVFS_GET_CAPABILITIES: {
        UMockdevIoctlData* caps = umockdev_ioctl_data_resolve(arg, 0, sizeof(guint32), nullptr);
        const guint32 value = USBDEVFS_CAP_BULK_CONTINUATION | USBDEVFS_CAP_NO_PACKET_SIZE_LIM |
                              USBDEVFS_CAP_REAP_AFTER_DISCONNECT;
        std::memcpy(caps->data, &value, sizeof value);
        umockdev_ioctl_data_unref(caps);
        return complete(client, 0, 0);
      }
      case USBDEVFS_CLAIMINTERFACE:
      case USBDEVFS_DISCONNECT_CLAIM: {
        UMockdevIoctlData* which = umockdev_ioctl_data_resolve(arg, 0, sizeof(unsigned), nullptr);
        unsigned interface = 0;
        std::memcpy(&interface, which->data, sizeof interface);
        umockdev_ioctl_data_unref(which);
        counts_.claim_times.push_back(std::chrono::steady_clock::now());
        if (refuse_claims_) {
          ++counts_.refused_claims;
          return complete(client, -1, EBUSY);
        }
        ++counts_.claims;
        counts_.claimed_interfaces.push_back(interface);
        return complete(client, 0, 0);
      }
      case USBDEVFS_RELEASEINTERFACE:
        ++counts_.releases;
        return complete(client, 0, 0);
      case USBDEVFS_SUBMITURB:
        return submit(client, arg);
      case USBDEVFS_REAPURB:
      case USBDEVFS_REAPURBNDELAY:
        return reap(client, arg);
      case USBDEVFS_DISCARDURB: {
        ++counts_.discards;
        const auto address = *reinterpret_cast<const gulong*>(arg->data);
        const auto it = std::find_if(flying_.begin(), flying_.end(), [&](UMockdevIoctlData* urb) {
          return urb->client_addr == address;
        });
        if (it == flying_.end()) return complete(client, -1, EINVAL);
        if (keep_cancelled_) return complete(client, 0, 0);  // accepted, never given back
        discarded_.push_back(*it);
        flying_.erase(it);
        return complete(client, 0, 0);
      }
      default:  // reattaching a kernel driver and the like: nothing to emulate
        return complete(client, 0, 0);
    }
  }

  static gboolean complete(UMockdevIoctlClient* client, long result, int error) {
    umockdev_ioctl_client_complete(client, result, error);
    return TRUE;
  }

  gboolean submit(UMockdevIoctlClient* client, UMockdevIoctlData* arg) {
    if (!plugged_ || refuse_submits_) {
      ++counts_.refused_submits;
      return complete(client, -1, plugged_ ? EIO : ENODEV);
    }
    UMockdevIoctlData* urb_data =
        umockdev_ioctl_data_resolve(arg, 0, sizeof(usbdevfs_urb), nullptr);
    const auto* urb = reinterpret_cast<const usbdevfs_urb*>(urb_data->data);
    // Fetches the buffer too, so that the reply can write into it.
    umockdev_ioctl_data_unref(
        umockdev_ioctl_data_resolve(urb_data, G_STRUCT_OFFSET(usbdevfs_urb, buffer),
                                    static_cast<gsize>(urb->buffer_length), nullptr));
    ++counts_.submits;
    counts_.urb_lengths.push_back(urb->buffer_length);
    counts_.urb_endpoints.push_back(urb->endpoint);
    counts_.urb_types.push_back(urb->type);
    flying_.push_back(urb_data);
    counts_.max_in_flight = std::max(counts_.max_in_flight, static_cast<int>(flying_.size()));
    return complete(client, 0, 0);
  }

  gboolean reap(UMockdevIoctlClient* client, UMockdevIoctlData* arg) {
    UMockdevIoctlData* done = nullptr;
    if (!discarded_.empty()) {
      done = discarded_.front();
      discarded_.pop_front();
      auto* urb = reinterpret_cast<usbdevfs_urb*>(done->data);
      urb->status = -ENOENT;
      urb->actual_length = 0;
    } else if (!flying_.empty() && fail_next_urbs_ > 0) {
      done = flying_.front();
      flying_.pop_front();
      --fail_next_urbs_;
      auto* urb = reinterpret_cast<usbdevfs_urb*>(done->data);
      urb->status = urb_status_;
      urb->actual_length = 0;
    } else if (!flying_.empty() && !chunks_.empty() && plugged_) {
      done = flying_.front();
      flying_.pop_front();
      auto* urb = reinterpret_cast<usbdevfs_urb*>(done->data);
      const std::vector<std::uint8_t>& chunk = chunks_.front();
      const std::size_t n = std::min(chunk.size(), static_cast<std::size_t>(urb->buffer_length));
      std::memcpy(urb->buffer, chunk.data(), n);
      urb->actual_length = static_cast<int>(n);
      urb->status = chunk.size() > n ? -EOVERFLOW : 0;
      chunks_.pop_front();
    }
    if (done == nullptr) return complete(client, -1, EAGAIN);
    UMockdevIoctlData* out = umockdev_ioctl_data_resolve(arg, 0, sizeof(gpointer), nullptr);
    umockdev_ioctl_data_set_ptr(out, 0, done);
    umockdev_ioctl_data_unref(out);
    umockdev_ioctl_data_unref(done);
    return complete(client, 0, 0);
  }

  UMockdevTestbed* testbed_;
  UMockdevIoctlBase* handler_;
  mutable std::mutex mutex_;
  bool plugged_ = false;
  bool refuse_submits_ = false;
  bool refuse_claims_ = false;
  bool keep_cancelled_ = false;
  int fail_next_urbs_ = 0;
  int urb_status_ = 0;
  std::deque<UMockdevIoctlData*> flying_;
  std::deque<UMockdevIoctlData*> discarded_;
  std::deque<std::vector<std::uint8_t>> chunks_;
  Counts counts_;
};

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
  settings.vendor_id = kVendor;
  settings.product_id = kProduct;
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
  EmulatedInsole insole;
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
  const EmulatedInsole::Counts counts = insole.counts();
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

TEST(UsbSourceOnUsbfs, AnOverflowingTransferDeliversWhatFitAndKeepsStreaming) {
  EmulatedInsole insole;
  insole.plug();
  const UsbSettings settings = insole_settings();
  Driver driver(settings);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 1));
  insole.send(std::vector<std::uint8_t>(700, 0xAB));  // the buffer takes 512
  ASSERT_TRUE(driver.wait_for_bytes(512));
  // The overflowing transfer went back in flight, and nothing was cancelled.
  EXPECT_TRUE(eventually([&] { return insole.counts().submits == settings.transfers + 1; }));
  insole.send({1, 2, 3});
  ASSERT_TRUE(driver.wait_for_bytes(515));
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
  EmulatedInsole insole;
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
    EmulatedInsole insole;
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
    EXPECT_EQ(driver.states(),
              (std::vector<LinkState>{LinkState::Connecting, LinkState::Connected,
                                      LinkState::Disconnected, LinkState::Connecting,
                                      LinkState::Connected, LinkState::Disconnected}));
  }
}

TEST(UsbSourceOnUsbfs, ARefusedSubmissionLosesTheLinkAndIsRetriedWithBackoff) {
  EmulatedInsole insole;
  insole.plug();
  insole.refuse_submits(true);
  Driver driver(insole_settings());
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Disconnected, 3));
  EXPECT_EQ(driver.details()[2], "usb 1209:0001 interface 0 endpoint 0x81: LIBUSB_ERROR_IO");
  EXPECT_GE(insole.counts().refused_submits, 3);
  EXPECT_EQ(insole.counts().submits, 0);
  insole.refuse_submits(false);
  insole.send({42});
  ASSERT_TRUE(driver.wait_for_bytes(1));
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

TEST(UsbSourceOnUsbfs, AnInterfaceInUseIsRetriedWithABackoffThatAConnectionResets) {
  EmulatedInsole insole;
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
  EXPECT_EQ(driver.states(), std::vector<LinkState>{LinkState::Connecting});

  insole.refuse_claims(false);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 1, 10s));
  // The connection reset the backoff: after a loss the driver retries within 10 ms, where the
  // backoff it had reached would wait 2.56 s.
  insole.fail_urbs(1, -EPIPE);
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Disconnected, 1));
  const auto lost = std::chrono::steady_clock::now();
  ASSERT_TRUE(driver.wait_for_state_count(LinkState::Connected, 2));
  EXPECT_LT(std::chrono::steady_clock::now() - lost, 1s);
  driver.stop();
  EXPECT_EQ(insole.counts().claims, 2);
}

TEST(UsbSourceOnUsbfs, ATransferThatIsNeverGivenBackDoesNotHangStop) {
  EmulatedInsole insole;
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

// libusb frees a transfer's URB array when the URB is reaped. The one test whose URBs are never
// given back leaves those arrays (56 bytes each, allocated inside libusb_submit_transfer) with
// libusb; the transfers themselves, which the driver owns, are freed and not covered by this.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:libusb_submit_transfer\n";
}

// The preload must be in place before the process starts. With ASan, its runtime then no longer
// comes first in the library list, which is harmless here.
int main(int argc, char** argv) {
  constexpr const char* preload = "libumockdev-preload.so.0";
  if (dlopen(preload, RTLD_LAZY | RTLD_NOLOAD) == nullptr) {
    if (std::getenv("GAITMON_UMOCKDEV_REEXEC") != nullptr) {
      std::fprintf(stderr, "%s could not be preloaded: install Debian's umockdev package\n",
                   preload);
      return 1;
    }
    setenv("GAITMON_UMOCKDEV_REEXEC", "1", 1);
    std::string libraries = preload;
    if (const char* old = std::getenv("LD_PRELOAD"); old != nullptr && *old != '\0') {
      libraries += std::string(":") + old;
    }
    setenv("LD_PRELOAD", libraries.c_str(), 1);
    std::string asan = "verify_asan_link_order=0";
    if (const char* old = std::getenv("ASAN_OPTIONS")) asan = std::string(old) + ":" + asan;
    setenv("ASAN_OPTIONS", asan.c_str(), 1);
    execv("/proc/self/exe", argv);
    std::perror("re-executing with libumockdev-preload.so.0");
    return 1;
  }
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
