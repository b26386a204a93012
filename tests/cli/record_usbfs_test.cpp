// `gaitmon record --usb`: the built program records an insole on an emulated USB bus
// (usbfs_insole.hpp) that is unplugged halfway and plugged back in; the session file holds every
// frame the insole sent, as the session it streamed has them.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "drivers/usbfs_insole.hpp"
#include "gaitmon/session.hpp"
#include "lcm/bus_support.hpp"
#include "live_support.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using test::ChildProcess;
using Clock = std::chrono::steady_clock;

/// Waits until the insole has handed every chunk it was given to the driver.
bool all_taken(const test::UsbfsInsole& insole) {
  const auto until = Clock::now() + std::chrono::seconds(60);
  while (insole.counts().chunks_waiting > 0) {
    if (Clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

TEST(RecordUsb, RecordsAnEmulatedUsbInsoleUnpluggedHalfwayFrameForFrame) {
  const fs::path dir = test::scratch_dir("record-usbfs");
  const fs::path session = test::cut_session(test::demo_session(), dir / "demo10.csv", 10.0);
  const auto transfers = test::wire_transfers(test::session_frames(session), 10);
  const std::size_t half = transfers.size() / 2;
  const fs::path config = test::roomy_config(dir, {{"vendor_id = 0x0000", "vendor_id = 0x1209"},
                                                   {"product_id = 0x0000", "product_id = 0x0001"}});
  const fs::path out = dir / "recorded.csv";
  test::UsbfsInsole insole;
  insole.plug();
  ChildProcess record({test::gaitmon_binary().string(), "--config", config.string(), "--log-level",
                       "info", "record", "--usb", "--out", out.string()});
  const auto soon = [] { return Clock::now() + std::chrono::seconds(30); };
  ASSERT_FALSE(record.read_until(ChildProcess::Stderr, "link connected", soon()).empty())
      << "gaitmon record --usb did not connect";
  for (std::size_t i = 0; i < half; ++i) insole.send(transfers[i]);
  ASSERT_TRUE(all_taken(insole));
  insole.unplug();
  const auto lost = record.read_until(ChildProcess::Stderr, "link disconnected", soon());
  ASSERT_FALSE(lost.empty()) << "the unplug was not reported";
  EXPECT_NE(lost.back().find("LIBUSB_ERROR_NO_DEVICE"), std::string::npos) << lost.back();
  insole.plug();
  ASSERT_FALSE(record.read_until(ChildProcess::Stderr, "link connected", soon()).empty())
      << "the device's return was not picked up";
  for (std::size_t i = half; i < transfers.size(); ++i) insole.send(transfers[i]);
  ASSERT_TRUE(all_taken(insole));
  EXPECT_FALSE(fs::exists(out)) << "the recording is complete only when it ends";
  record.signal(SIGINT);
  const auto status = record.wait(Clock::now() + std::chrono::seconds(10));
  ASSERT_TRUE(status.has_value()) << "gaitmon record still running 10 s after SIGINT";
  EXPECT_EQ(*status, 0);

  const SessionHeader recorded_header = test::expect_recording_of(out, session);
  EXPECT_EQ(recorded_header.note, "recorded by gaitmon record from USB 1209:0001");
  const auto rest = record.read_rest(ChildProcess::Stdout, soon());
  std::string summary;
  for (const std::string& line : rest) summary += line + "\n";
  EXPECT_NE(summary.find("(" + std::to_string(test::file_frames(session).size()) +
                         " frames); 0 skipped, 0 dropped"),
            std::string::npos)
      << summary;
  // The unplug: one reconnect, and nothing the device sent lost or cut short.
  EXPECT_NE(summary.find("0 CRC errors, 0 truncated, 0 bad headers, 0 resyncs; 0 frames lost "
                         "(sequence gaps), 0 device restarts, 1 reconnects"),
            std::string::npos)
      << summary;
}

}  // namespace
}  // namespace gaitmon

int main(int argc, char** argv) {
  return gaitmon::test::run_tests_with_umockdev(argc, argv);
}
