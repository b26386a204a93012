// An insole on an emulated USB bus, for tests of the USB driver against the real libusb:
// umockdev's preload redirects /sys and /dev/bus/usb to a test bed, and the handler here answers
// usbfs's ioctls (claim, URB submit, reap and discard) as the device and the kernel would.
// Child processes started after the test bed inherit it through the environment.
#pragma once

#include <umockdev.h>

#include <chrono>
#include <cstdint>
#include <deque>
#include <mutex>
#include <vector>

#include "gaitmon/sensor_frame.hpp"

namespace gaitmon::test {

/// pid.codes' test ids, which the emulated insole has.
inline constexpr std::uint16_t kUsbfsVendorId = 0x1209;
inline constexpr std::uint16_t kUsbfsProductId = 0x0001;

/// A device with one bulk IN endpoint 0x81 on interface 0. Streams the chunks it is given, one
/// per completed URB, in submission order; can be unplugged, made to fail URBs or submissions,
/// or made never to give back a cancelled URB. The handler runs on umockdev's thread; the test
/// reads the counts under the mutex.
class UsbfsInsole {
 public:
  UsbfsInsole();
  ~UsbfsInsole();
  UsbfsInsole(const UsbfsInsole&) = delete;
  UsbfsInsole& operator=(const UsbfsInsole&) = delete;

  void plug();
  /// As the kernel does on an unplug: URBs in flight end with -ESHUTDOWN, new ones are refused
  /// with ENODEV, and the device leaves sysfs with a remove uevent.
  void unplug();

  void send(std::vector<std::uint8_t> chunk);
  /// The next `count` URBs to complete end with `status` (a negative errno) and no data. -EPIPE
  /// (a stall) also halts the endpoint, as a device does: every later URB stalls too, across a
  /// reopen, until USBDEVFS_CLEAR_HALT.
  void fail_urbs(int count, int status);
  void refuse_submits(bool refuse);
  void refuse_claims(bool refuse);
  void keep_cancelled_urbs(bool keep);

  struct Counts {
    int submits = 0;
    int refused_submits = 0;
    int claims = 0;
    int refused_claims = 0;
    std::vector<std::chrono::steady_clock::time_point> claim_times;  ///< refused or not
    int releases = 0;
    int discards = 0;
    int clear_halts = 0;
    int max_in_flight = 0;
    int in_flight = 0;
    std::size_t chunks_waiting = 0;  ///< sent but not yet in a completed URB
    std::vector<unsigned> claimed_interfaces;
    std::vector<int> urb_lengths;    ///< buffer_length of each submitted URB
    std::vector<int> urb_endpoints;  ///< endpoint of each submitted URB
    std::vector<int> urb_types;
  };
  Counts counts() const;

 private:
  static gboolean on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer self);
  gboolean handle(UMockdevIoctlClient* client);
  gboolean submit(UMockdevIoctlClient* client, UMockdevIoctlData* arg);
  gboolean reap(UMockdevIoctlClient* client, UMockdevIoctlData* arg);

  UMockdevTestbed* testbed_;
  UMockdevIoctlBase* handler_;
  mutable std::mutex mutex_;
  bool plugged_ = false;
  bool refuse_submits_ = false;
  bool refuse_claims_ = false;
  bool keep_cancelled_ = false;
  bool halted_ = false;
  int fail_next_urbs_ = 0;
  int urb_status_ = 0;
  std::deque<UMockdevIoctlData*> flying_;
  std::deque<UMockdevIoctlData*> discarded_;
  std::deque<std::vector<std::uint8_t>> chunks_;
  Counts counts_;
};

/// Frames in the wire format with the default framing, `per_transfer` to a bulk transfer (the
/// last one may have fewer), as a device that buffers would send them.
std::vector<std::vector<std::uint8_t>> wire_transfers(const std::vector<SensorFrame>& frames,
                                                      std::size_t per_transfer);

/// The main() of a test program that uses UsbfsInsole: re-executes the program with
/// libumockdev-preload.so.0 in LD_PRELOAD (as `umockdev-wrapper` would; the preload must be in
/// place when the process starts), then runs the GoogleTest tests.
int run_tests_with_umockdev(int argc, char** argv);

}  // namespace gaitmon::test
