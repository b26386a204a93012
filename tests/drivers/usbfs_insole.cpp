// The emulated USB insole: usbfs's ioctls answered from umockdev's handler thread.
#include "drivers/usbfs_insole.hpp"

#include <dlfcn.h>
#include <gtest/gtest.h>
#include <linux/ioctl.h>
#include <linux/usbdevice_fs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "drivers/wire_format.hpp"

// libusb frees a transfer's URB array when the URB is reaped. A test whose URBs are never given
// back leaves those arrays (56 bytes each, allocated inside libusb_submit_transfer) with libusb;
// the transfers themselves, which the driver owns, are freed and not covered by this.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:libusb_submit_transfer\n";
}

namespace gaitmon::test {
namespace {

constexpr const char* kSysPath = "/sys/devices/usb1/1-1";
constexpr const char* kDevNode = "/dev/bus/usb/001/002";

// One bulk IN endpoint 0x81 on interface 0; the ids of kUsbfsVendorId and kUsbfsProductId,
// little-endian, at bytes 8-11.
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

gboolean complete(UMockdevIoctlClient* client, long result, int error) {
  umockdev_ioctl_client_complete(client, result, error);
  return TRUE;
}

}  // namespace

UsbfsInsole::UsbfsInsole() : testbed_(umockdev_testbed_new()), handler_(umockdev_ioctl_base_new()) {
  g_signal_connect_after(handler_, "handle-ioctl", G_CALLBACK(&UsbfsInsole::on_ioctl), this);
  GError* error = nullptr;
  if (umockdev_testbed_attach_ioctl(testbed_, kDevNode, handler_, &error) == 0) {
    ADD_FAILURE() << "umockdev_testbed_attach_ioctl: " << error->message;
    g_error_free(error);
  }
}

UsbfsInsole::~UsbfsInsole() {
  g_object_unref(testbed_);  // detaches the handler, whose thread then ends
  g_object_unref(handler_);
  for (UMockdevIoctlData* urb : flying_) umockdev_ioctl_data_unref(urb);
  for (UMockdevIoctlData* urb : discarded_) umockdev_ioctl_data_unref(urb);
}

void UsbfsInsole::plug() {
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

void UsbfsInsole::unplug() {
  {
    std::lock_guard lock(mutex_);
    plugged_ = false;
    fail_next_urbs_ += static_cast<int>(flying_.size());
    urb_status_ = -ESHUTDOWN;
  }
  umockdev_testbed_uevent(testbed_, kSysPath, "remove");
  umockdev_testbed_remove_device(testbed_, kSysPath);
}

void UsbfsInsole::send(std::vector<std::uint8_t> chunk) {
  std::lock_guard lock(mutex_);
  chunks_.push_back(std::move(chunk));
}

void UsbfsInsole::fail_urbs(int count, int status) {
  std::lock_guard lock(mutex_);
  fail_next_urbs_ = count;
  urb_status_ = status;
}

void UsbfsInsole::refuse_submits(bool refuse) {
  std::lock_guard lock(mutex_);
  refuse_submits_ = refuse;
}

void UsbfsInsole::refuse_claims(bool refuse) {
  std::lock_guard lock(mutex_);
  refuse_claims_ = refuse;
}

void UsbfsInsole::keep_cancelled_urbs(bool keep) {
  std::lock_guard lock(mutex_);
  keep_cancelled_ = keep;
}

UsbfsInsole::Counts UsbfsInsole::counts() const {
  std::lock_guard lock(mutex_);
  Counts c = counts_;
  c.in_flight = static_cast<int>(flying_.size());
  c.chunks_waiting = chunks_.size();
  return c;
}

gboolean UsbfsInsole::on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer self) {
  return static_cast<UsbfsInsole*>(self)->handle(client);
}

gboolean UsbfsInsole::handle(UMockdevIoctlClient* client) {
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
    case USBDEVFS_CLEAR_HALT:
      ++counts_.clear_halts;
      halted_ = false;
      return complete(client, 0, 0);
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

gboolean UsbfsInsole::submit(UMockdevIoctlClient* client, UMockdevIoctlData* arg) {
  if (!plugged_ || refuse_submits_) {
    ++counts_.refused_submits;
    return complete(client, -1, plugged_ ? EIO : ENODEV);
  }
  UMockdevIoctlData* urb_data = umockdev_ioctl_data_resolve(arg, 0, sizeof(usbdevfs_urb), nullptr);
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

gboolean UsbfsInsole::reap(UMockdevIoctlClient* client, UMockdevIoctlData* arg) {
  UMockdevIoctlData* done = nullptr;
  if (!discarded_.empty()) {
    done = discarded_.front();
    discarded_.pop_front();
    auto* urb = reinterpret_cast<usbdevfs_urb*>(done->data);
    urb->status = -ENOENT;
    urb->actual_length = 0;
  } else if (!flying_.empty() && (fail_next_urbs_ > 0 || halted_)) {
    done = flying_.front();
    flying_.pop_front();
    auto* urb = reinterpret_cast<usbdevfs_urb*>(done->data);
    if (fail_next_urbs_ > 0) {
      --fail_next_urbs_;
      urb->status = urb_status_;
      if (urb_status_ == -EPIPE) halted_ = true;
    } else {
      urb->status = -EPIPE;
    }
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

std::vector<std::vector<std::uint8_t>> wire_transfers(const std::vector<SensorFrame>& frames,
                                                      std::size_t per_transfer) {
  const drivers::WireFormat format;
  std::vector<std::vector<std::uint8_t>> transfers;
  for (std::size_t first = 0; first < frames.size(); first += per_transfer) {
    std::vector<std::uint8_t> bytes;
    for (std::size_t i = first; i < std::min(first + per_transfer, frames.size()); ++i) {
      std::uint8_t frame[drivers::kMaxFrameBytes];
      bytes.insert(bytes.end(), frame, frame + drivers::encode_frame(format, frames[i], frame));
    }
    transfers.push_back(std::move(bytes));
  }
  return transfers;
}

int run_tests_with_umockdev(int argc, char** argv) {
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

}  // namespace gaitmon::test
