// The serial driver against real pseudo-terminals made here: frames written to the master
// arrive decoded; a pty that closes and comes back under the same link path is reconnected, with
// waits that grow while the device sends nothing and start over once it has sent data.
#include "drivers/serial_source.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "drivers/frame_decoder.hpp"
#include "gaitmon/session.hpp"
#include "replay/pseudo_terminal.hpp"
#include "test_support.hpp"

namespace gaitmon::drivers {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

using replay::point_link;
using replay::PseudoTerminal;
using replay::write_all;

std::vector<std::uint8_t> frames_bytes(Foot foot, std::uint32_t first, std::uint32_t count) {
  const WireFormat format;
  std::vector<std::uint8_t> out;
  for (std::uint32_t seq = first; seq < first + count; ++seq) {
    SensorFrame frame;
    frame.foot = foot;
    frame.size = InsoleSize::S37_38;
    frame.sensor_count = 107;
    frame.sequence = seq;
    frame.device_time_us = seq * 10000;
    for (std::size_t i = 0; i < 107; ++i) frame.bits[i] = static_cast<std::uint8_t>(seq + i);
    std::vector<std::uint8_t> one(format.frame_bytes(107));
    encode_frame(format, frame, one);
    out.insert(out.end(), one.begin(), one.end());
  }
  return out;
}

// The driver on its own thread, feeding a decoder; what it delivers, guarded for the test.
class Harness {
 public:
  explicit Harness(SerialSettings settings) : source_(std::move(settings)) {
    thread_ = std::thread([this] {
      source_.run(
          [this](std::span<const std::uint8_t> bytes) {
            decoder_.feed(bytes, [this](const SensorFrame& frame) {
              std::lock_guard lock(mutex_);
              sequences_.push_back(frame.sequence);
              bits_ok_ = bits_ok_ && frame.bits[5] == static_cast<std::uint8_t>(frame.sequence + 5);
              changed_.notify_all();
            });
          },
          [this](LinkState state, std::string_view detail) {
            const auto now = Clock::now();
            if (state == LinkState::Disconnected) decoder_.reset();
            std::lock_guard lock(mutex_);
            states_.emplace_back(state, std::string(detail));
            state_times_.push_back(now);
            changed_.notify_all();
          });
    });
  }
  ~Harness() { stop(); }

  void stop() {
    source_.stop();
    if (thread_.joinable()) thread_.join();
  }
  bool wait_frames(std::size_t n) {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, 10s, [&] { return sequences_.size() >= n; });
  }
  bool wait_states(std::size_t n) {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, 10s, [&] { return states_.size() >= n; });
  }
  /// Waits until `state` has been reported `n` times.
  bool wait_state_count(LinkState state, std::size_t n) {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, 10s, [&] { return count_locked(state) >= n; });
  }
  /// When each report of `state` came, in order.
  std::vector<Clock::time_point> times_of(LinkState state) {
    std::lock_guard lock(mutex_);
    std::vector<Clock::time_point> times;
    for (std::size_t i = 0; i < states_.size(); ++i) {
      if (states_[i].first == state) times.push_back(state_times_[i]);
    }
    return times;
  }
  std::vector<std::uint32_t> sequences() {
    std::lock_guard lock(mutex_);
    return sequences_;
  }
  std::vector<std::pair<LinkState, std::string>> states() {
    std::lock_guard lock(mutex_);
    return states_;
  }
  bool bits_ok() {
    std::lock_guard lock(mutex_);
    return bits_ok_;
  }
  DecoderCounters counters() const { return decoder_.counters(); }

 private:
  std::size_t count_locked(LinkState state) const {
    return static_cast<std::size_t>(std::count_if(states_.begin(), states_.end(),
                                                  [&](const auto& s) { return s.first == state; }));
  }

  SerialSource source_;
  FrameDecoder decoder_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::uint32_t> sequences_;
  std::vector<std::pair<LinkState, std::string>> states_;
  std::vector<Clock::time_point> state_times_;  ///< when each of states_ was reported
  bool bits_ok_ = true;
  std::thread thread_;
};

SerialSettings settings_for(const fs::path& device) {
  SerialSettings settings;
  settings.device = device.string();
  settings.baud = 115200;
  settings.reconnect_initial_ms = 20;
  settings.reconnect_max_ms = 200;
  return settings;
}

TEST(SerialSource, DeliversFramesWrittenToAPty) {
  PseudoTerminal pty;
  Harness harness(settings_for(pty.path()));
  write_all(pty.fd(), frames_bytes(Foot::Left, 0, 300));
  ASSERT_TRUE(harness.wait_frames(300));
  const auto sequences = harness.sequences();
  for (std::uint32_t i = 0; i < 300; ++i) ASSERT_EQ(sequences[i], i);
  EXPECT_TRUE(harness.bits_ok());
  harness.stop();
  const auto states = harness.states();
  ASSERT_EQ(states.size(), 3U);
  EXPECT_EQ(states[0].first, LinkState::Connecting);
  EXPECT_EQ(states[1].first, LinkState::Connected);
  EXPECT_EQ(states[2].first, LinkState::Disconnected);
  EXPECT_EQ(harness.counters().garbage_bytes, 0U);
}

TEST(SerialSource, ReconnectsWhenThePtyComesBackUnderTheLink) {
  const fs::path link = test::scratch_dir("serial-reconnect") / "insole";
  auto first = std::make_unique<PseudoTerminal>();
  point_link(link, first->path());
  Harness harness(settings_for(link));
  write_all(first->fd(), frames_bytes(Foot::Right, 0, 50));
  ASSERT_TRUE(harness.wait_frames(50));

  // The device disappears, its link first (as udev's): a link left on the closed pty could be
  // reopened onto another process's pty that got the same number.
  fs::remove(link);
  first.reset();
  ASSERT_TRUE(harness.wait_states(3));
  EXPECT_EQ(harness.states()[2].first, LinkState::Disconnected);
  std::this_thread::sleep_for(100ms);  // a few failed reopen attempts
  auto second = std::make_unique<PseudoTerminal>();
  point_link(link, second->path());
  write_all(second->fd(), frames_bytes(Foot::Right, 50, 50));
  ASSERT_TRUE(harness.wait_frames(100));
  const auto sequences = harness.sequences();
  for (std::uint32_t i = 0; i < 100; ++i) ASSERT_EQ(sequences[i], i);
  harness.stop();

  const auto states = harness.states();
  ASSERT_GE(states.size(), 6U);
  EXPECT_EQ(states[0].first, LinkState::Connecting);
  EXPECT_EQ(states[1].first, LinkState::Connected);
  EXPECT_EQ(states[2].first, LinkState::Disconnected);
  EXPECT_NE(states[2].second.find(link.string()), std::string::npos) << states[2].second;
  EXPECT_EQ(states[3].first, LinkState::Connecting);
  // The failed reopen attempts, once.
  EXPECT_EQ(states[4],
            std::pair(LinkState::Connecting, link.string() + ": No such file or directory"));
  EXPECT_EQ(states[5].first, LinkState::Connected);
  EXPECT_EQ(harness.counters().lost_frames_total(), 0U);
  EXPECT_EQ(harness.counters().frames, 100U);
}

TEST(SerialSource, WaitsForAMissingDeviceAndStopsCleanly) {
  const fs::path link = test::scratch_dir("serial-missing") / "not-yet";
  Harness harness(settings_for(link));
  ASSERT_TRUE(harness.wait_states(1));
  std::this_thread::sleep_for(400ms);  // attempts after 50, 150 and 350 ms
  auto states = harness.states();
  // The first failed attempt says why; the same failure is not reported again and again.
  ASSERT_EQ(states.size(), 2U);
  EXPECT_EQ(states[0].first, LinkState::Connecting);
  EXPECT_EQ(states[1],
            std::pair(LinkState::Connecting, link.string() + ": No such file or directory"));

  PseudoTerminal pty;  // the device appears late
  point_link(link, pty.path());
  write_all(pty.fd(), frames_bytes(Foot::Left, 0, 10));
  ASSERT_TRUE(harness.wait_frames(10));

  const auto before = std::chrono::steady_clock::now();
  harness.stop();
  // A stop waits for no timer and no read: seconds would mean it hung on one.
  EXPECT_LT(std::chrono::steady_clock::now() - before, 5s);
  states = harness.states();
  ASSERT_EQ(states.size(), 4U);
  EXPECT_EQ(states[2].first, LinkState::Connected);
  EXPECT_EQ(states[3].first, LinkState::Disconnected);
}

// A path that is no serial device: the error is in the detail, where `run` and `record` log it.
TEST(SerialSource, ADeviceThatCannotBeConfiguredSaysWhy) {
  const fs::path file = test::write_text(test::scratch_dir("serial-not-a-tty") / "plain", "");
  Harness harness(settings_for(file));
  ASSERT_TRUE(harness.wait_states(2));
  const auto states = harness.states();
  EXPECT_EQ(states[1].first, LinkState::Connecting);
  EXPECT_EQ(states[1].second.rfind(file.string() + ": ", 0), 0U) << states[1].second;
  EXPECT_GT(states[1].second.size(), file.string().size() + 2) << "no error text";
}

// A device that opens but hangs up before sending a byte: each time the driver connects, the
// link moves to a fresh pty (first, so that the next attempt finds it) and the one the driver
// opened is closed, which fails its read. Returns false if the driver did not connect.
bool hang_up_at_connections(Harness& harness, const fs::path& link,
                            std::unique_ptr<PseudoTerminal>& pty, std::size_t from,
                            std::size_t to) {
  for (std::size_t k = from; k <= to; ++k) {
    if (!harness.wait_state_count(LinkState::Connected, k)) return false;
    auto next = std::make_unique<PseudoTerminal>();
    point_link(link, next->path());
    pty = std::move(next);
  }
  return true;
}

TEST(SerialSource, ADeviceThatHangsUpBeforeSendingIsRetriedWithGrowingWaits) {
  const fs::path link = test::scratch_dir("serial-no-data") / "insole";
  auto pty = std::make_unique<PseudoTerminal>();
  point_link(link, pty->path());
  SerialSettings settings = settings_for(link);
  settings.reconnect_initial_ms = 10;
  settings.reconnect_max_ms = 320;
  Harness harness(settings);
  ASSERT_TRUE(hang_up_at_connections(harness, link, pty, 1, 8));
  ASSERT_TRUE(harness.wait_state_count(LinkState::Connected, 9));
  harness.stop();

  // An open without data does not reset the backoff: waits of 10, 20, 40, 80, 160 ms, then
  // 320 ms on, where a reset per open would wait 10 ms each time. Each wait starts after the
  // Connected before it, so a gap is never shorter, however loaded the machine.
  const std::vector<Clock::time_point> connected = harness.times_of(LinkState::Connected);
  ASSERT_EQ(connected.size(), 9U);
  for (std::size_t i = 0; i + 1 < connected.size(); ++i) {
    const auto wait = std::chrono::milliseconds(std::min(10 << i, 320));
    EXPECT_GE(connected[i + 1] - connected[i], wait)
        << "between connections " << i + 1 << " and " << i + 2;
  }
  EXPECT_EQ(harness.times_of(LinkState::Disconnected).size(), 9U);
  EXPECT_EQ(harness.counters().bytes, 0U);
}

TEST(SerialSource, DataResetsTheBackoff) {
  const fs::path link = test::scratch_dir("serial-data-resets") / "insole";
  auto pty = std::make_unique<PseudoTerminal>();
  point_link(link, pty->path());
  SerialSettings settings = settings_for(link);
  settings.reconnect_initial_ms = 20;
  settings.reconnect_max_ms = 5000;
  Harness harness(settings);
  // Seven connections without data take the backoff to 2560 ms.
  ASSERT_TRUE(hang_up_at_connections(harness, link, pty, 1, 7));
  ASSERT_TRUE(harness.wait_state_count(LinkState::Connected, 8));
  write_all(pty->fd(), frames_bytes(Foot::Left, 0, 10));
  ASSERT_TRUE(harness.wait_frames(10));
  ASSERT_TRUE(hang_up_at_connections(harness, link, pty, 8, 8));
  ASSERT_TRUE(harness.wait_state_count(LinkState::Connected, 9));
  harness.stop();

  const std::vector<Clock::time_point> connected = harness.times_of(LinkState::Connected);
  const std::vector<Clock::time_point> lost = harness.times_of(LinkState::Disconnected);
  ASSERT_EQ(connected.size(), 9U);
  ASSERT_GE(lost.size(), 8U);
  EXPECT_GE(connected[7] - connected[6], 1280ms) << "the backoff did not grow";
  // The data reset it: the driver came back after 20 ms, where the backoff it had reached
  // would wait 2560 ms; 2 s leaves a loaded sanitizer build room to reopen the pty.
  EXPECT_LT(connected[8] - lost[7], 2s);
}

TEST(SerialSource, StopBeforeRunReturnsAtOnce) {
  SerialSource source(settings_for("/nonexistent/tty"));
  source.stop();
  int calls = 0;
  source.run([&](std::span<const std::uint8_t>) { ++calls; },
             [&](LinkState, std::string_view) { ++calls; });
  EXPECT_EQ(calls, 0);
}

TEST(ByteSource, NamesTheLinkStates) {
  EXPECT_EQ(link_state_name(LinkState::Connecting), "connecting");
  EXPECT_EQ(link_state_name(LinkState::Connected), "connected");
  EXPECT_EQ(link_state_name(LinkState::Disconnected), "disconnected");
}

}  // namespace
}  // namespace gaitmon::drivers
