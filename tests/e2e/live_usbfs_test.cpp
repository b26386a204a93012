// `gaitmon run --usb` end to end: the program's own USB driver on the real libusb reads an
// insole emulated on usbfs (usbfs_insole.hpp) that streams a session in the wire format, is
// unplugged halfway and plugged back in, and the monitor publishes over LCM udpm to a Lua client
// built from the lcm-gen types. Nothing is lost across the unplug: the fits equal
// `gaitmon analyze` on the same session. A transfer the device overfills loses what did not fit,
// and that loss is counted twice over: as an overflowed transfer and as the frames missing from
// the sequence.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <functional>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "drivers/usbfs_insole.hpp"
#include "lcm/bus_support.hpp"
#include "live_support.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using test::ChildProcess;
using Clock = std::chrono::steady_clock;

/// Reads the Lua client's messages, collecting the fits, until a status satisfies `done`;
/// returns that status, or null after `limit`.
json read_bus_until(ChildProcess& lua, std::vector<json>& fits,
                    const std::function<bool(const json&)>& done, std::chrono::seconds limit) {
  const auto deadline = Clock::now() + limit;
  while (Clock::now() < deadline) {
    const auto line = lua.read_line(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(1));
    if (!line || line->empty() || line->front() != '{') continue;
    const json message = json::parse(*line);
    if (message.contains("error")) {
      ADD_FAILURE() << *line;
      return nullptr;
    }
    if (message["channel"] == "GAITMON_FIT") fits.push_back(message["message"]);
    if (message["channel"] == "GAITMON_STATUS" && done(message["message"])) {
      return message["message"];
    }
  }
  return nullptr;
}

/// SIGINTs `gaitmon run`, which must exit with 0 within 10 s, and returns its final status (the
/// one whose connection is "finished"), collecting the fits before it; null if none came.
json interrupt(ChildProcess& run, ChildProcess& lua, std::vector<json>& fits) {
  run.signal(SIGINT);
  const auto run_status = run.wait(Clock::now() + std::chrono::seconds(10));
  if (!run_status) {
    ADD_FAILURE() << "gaitmon run still running 10 s after SIGINT";
    return nullptr;
  }
  EXPECT_EQ(*run_status, 0);
  // The workers finish every queued fit before the final status.
  return read_bus_until(
      lua, fits, [](const json& s) { return s["connection"] == "finished"; },
      std::chrono::seconds(10));
}

/// The shipped config with the emulated insole's ids, and `changes` on top.
fs::path usbfs_config(const fs::path& dir,
                      std::vector<std::pair<std::string, std::string>> changes = {}) {
  changes.insert(changes.begin(), {{"vendor_id = 0x0000", "vendor_id = 0x1209"},
                                   {"product_id = 0x0000", "product_id = 0x0001"}});
  return test::roomy_config(dir, changes);
}

TEST(LiveRunUsb, AnEmulatedUsbInsoleUnpluggedHalfwayLosesNothing) {
  const test::Bus& bus = test::private_bus();
  std::cout << "LCM bus: " << bus.description << std::endl;
  const fs::path dir = test::scratch_dir("live-usbfs");
  const fs::path session = test::cut_session(test::demo_session(), dir / "demo20.csv", 20.0);
  const std::vector<SensorFrame> frames = test::session_frames(session);

  const std::vector<std::vector<std::uint8_t>> transfers = test::wire_transfers(frames, 10);
  const std::size_t half = transfers.size() / 2;

  const fs::path config = usbfs_config(dir);
  test::UsbfsInsole insole;
  insole.plug();
  const std::unique_ptr<ChildProcess> lua = test::fit_and_status_client(bus);
  ASSERT_TRUE(lua);
  const std::string binary = test::gaitmon_binary().string();
  ChildProcess run({binary, "--config", config.string(), "--log-level", "info", "run", "--usb",
                    "--lcm-url", bus.url});
  const auto soon = [] { return Clock::now() + std::chrono::seconds(30); };
  ASSERT_FALSE(run.read_until(ChildProcess::Stderr, "link connected", soon()).empty())
      << "gaitmon run --usb did not connect";

  std::vector<json> fits;
  for (std::size_t i = 0; i < half; ++i) insole.send(transfers[i]);
  ASSERT_FALSE(
      read_bus_until(
          *lua, fits,
          [&](const json& s) { return s["frames_decoded"].get<std::size_t>() == half * 10; },
          std::chrono::seconds(120))
          .is_null())
      << "the first half never arrived";

  insole.unplug();
  const auto lost = run.read_until(ChildProcess::Stderr, "link disconnected", soon());
  ASSERT_FALSE(lost.empty()) << "the unplug was not reported";
  EXPECT_NE(lost.back().find("usb 1209:0001 interface 0 endpoint 0x81: LIBUSB_ERROR_NO_DEVICE"),
            std::string::npos)
      << lost.back();
  insole.plug();
  ASSERT_FALSE(run.read_until(ChildProcess::Stderr, "link connected", soon()).empty())
      << "the device's return was not picked up";
  for (std::size_t i = half; i < transfers.size(); ++i) insole.send(transfers[i]);
  ASSERT_FALSE(
      read_bus_until(
          *lua, fits,
          [&](const json& s) { return s["frames_decoded"].get<std::size_t>() == frames.size(); },
          std::chrono::seconds(240))
          .is_null())
      << "gaitmon run never reported all " << frames.size() << " frames";

  const json final_status = interrupt(run, *lua, fits);
  ASSERT_FALSE(final_status.is_null()) << "no final status";
  EXPECT_EQ(final_status["reconnects"], 1);
  EXPECT_EQ(final_status["transfers_overflowed"], 0);
  EXPECT_EQ(final_status["crc_errors"], 0);
  EXPECT_EQ(final_status["frames_lost_sequence"], 0);
  EXPECT_EQ(final_status["ring_drops"], 0);
  EXPECT_EQ(final_status["step_drops"], 0);
  EXPECT_EQ(final_status["frames_processed"].get<std::size_t>(), frames.size());
  EXPECT_EQ(final_status["fits_published"].get<std::size_t>(), fits.size());
  EXPECT_EQ(insole.counts().chunks_waiting, 0u);
  EXPECT_EQ(insole.counts().claims, 2);

  std::string output;
  ASSERT_EQ(test::run_command(
                binary + " analyze " + session.string() + " --out " + (dir / "analyze").string(),
                &output),
            0)
      << output;
  test::expect_fits_match_regions(fits, dir / "analyze" / "regions.csv", 12);
}

TEST(LiveRunUsb, AnOverfilledTransferIsCountedAndWarnedOfAndItsFramesCountedLost) {
  const test::Bus& bus = test::private_bus();
  std::cout << "LCM bus: " << bus.description << std::endl;
  const fs::path dir = test::scratch_dir("live-usbfs-overflow");
  const fs::path session = test::cut_session(test::demo_session(), dir / "demo10.csv", 10.0);
  const std::vector<SensorFrame> frames = test::session_frames(session);
  std::vector<std::vector<std::uint8_t>> transfers = test::wire_transfers(frames, 10);
  // Each transfer's buffer holds ten frames exactly; one chunk of twenty overfills its transfer,
  // which delivers the first ten: the next ten never arrive.
  const std::size_t over = transfers.size() / 2;
  ASSERT_EQ(transfers[over].size(), transfers[over + 1].size());
  const std::size_t buffer = transfers[over].size();
  transfers[over].insert(transfers[over].end(), transfers[over + 1].begin(),
                         transfers[over + 1].end());
  transfers.erase(transfers.begin() + static_cast<std::ptrdiff_t>(over) + 1);

  const fs::path config =
      usbfs_config(dir, {{"transfer_bytes = 16384", "transfer_bytes = " + std::to_string(buffer)}});
  test::UsbfsInsole insole;
  insole.plug();
  const std::unique_ptr<ChildProcess> lua = test::fit_and_status_client(bus);
  ASSERT_TRUE(lua);
  ChildProcess run({test::gaitmon_binary().string(), "--config", config.string(), "--log-level",
                    "info", "run", "--usb", "--lcm-url", bus.url});
  const auto soon = [] { return Clock::now() + std::chrono::seconds(30); };
  ASSERT_FALSE(run.read_until(ChildProcess::Stderr, "link connected", soon()).empty())
      << "gaitmon run --usb did not connect";
  for (const auto& t : transfers) insole.send(t);
  std::vector<json> fits;
  ASSERT_FALSE(read_bus_until(
                   *lua, fits,
                   [&](const json& s) {
                     return s["frames_decoded"].get<std::size_t>() == frames.size() - 10;
                   },
                   std::chrono::seconds(120))
                   .is_null())
      << "gaitmon run never reported the " << frames.size() - 10 << " frames that arrived";
  const auto warned = run.read_until(ChildProcess::Stderr, "USB transfers overflowed", soon());
  ASSERT_FALSE(warned.empty()) << "no warning of the overflow";
  EXPECT_NE(warned.back().find("link: 1 USB transfers overflowed, 1 in all"), std::string::npos)
      << warned.back();

  const json final_status = interrupt(run, *lua, fits);
  ASSERT_FALSE(final_status.is_null()) << "no final status";
  EXPECT_EQ(final_status["transfers_overflowed"], 1);
  EXPECT_EQ(final_status["frames_lost_sequence"], 10);
  EXPECT_EQ(final_status["crc_errors"], 0);
  EXPECT_EQ(final_status["reconnects"], 0);
  EXPECT_EQ(final_status["frames_processed"].get<std::size_t>(), frames.size() - 10);
  EXPECT_EQ(insole.counts().chunks_waiting, 0u);
}

}  // namespace
}  // namespace gaitmon

int main(int argc, char** argv) {
  return gaitmon::test::run_tests_with_umockdev(argc, argv);
}
