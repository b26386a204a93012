// The pieces the live commands share: --speed, the link's state and counters in the status and
// its overflow warning, the console line per fitted step, and SIGINT / SIGTERM sent to the
// process for real.
#include "src/cli/live.hpp"

#include <gtest/gtest.h>
#include <signal.h>

#include <CLI/Error.hpp>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "drivers/wire_format.hpp"
#include "log_capture.hpp"
#include "monitor_support.hpp"
#include "replay/pacer.hpp"

namespace gaitmon::cli {
namespace {

TEST(Live, SpeedIsMaxOrANumberFromTheSlowest) {
  EXPECT_EQ(parse_speed("max"), replay::kMaxSpeed);
  EXPECT_EQ(parse_speed("2.5"), 2.5);
  EXPECT_EQ(parse_speed("1"), 1.0);
  EXPECT_EQ(parse_speed("0.001"), 0.001);
  for (const char* bad :
       {"0", "-1", "", "fast", "2x", "inf", "nan", "1e400", "MAX", "0.0009", "1e-12", "1e-300"}) {
    try {
      parse_speed(bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const CLI::ValidationError& e) {
      EXPECT_NE(std::string(e.what()).find(
                    std::string("must be a number >= 0.001 (x real time) or max, got ") + bad),
                std::string::npos)
          << e.what();
    }
  }
}

/// A source that delivers nothing and reports the overflows it is told of.
class OverflowingSource final : public drivers::ByteSource {
 public:
  void run(const BytesHandler&, const StateHandler&) override {}
  void stop() override {}
  drivers::SourceCounters counters() const override {
    return {.transfers_overflowed = overflowed.load()};
  }

  std::atomic<std::uint64_t> overflowed{0};
};

TEST(Live, StatusCountsEveryConnectionAfterTheFirstAsAReconnect) {
  drivers::FrameDecoder decoder;
  const OverflowingSource source;
  LinkStatus link(decoder, source);
  StatusReport status;
  link.fill(status);
  EXPECT_EQ(status.connection, "connecting");
  EXPECT_EQ(status.reconnects, 0u);

  link.on_state(drivers::LinkState::Connected, "/dev/pts/1");
  link.fill(status);
  EXPECT_EQ(status.connection, "connected");
  EXPECT_EQ(status.reconnects, 0u);

  for (int i = 0; i < 2; ++i) {
    link.on_state(drivers::LinkState::Disconnected, "read: EIO");
    link.fill(status);
    EXPECT_EQ(status.connection, "disconnected");
    link.on_state(drivers::LinkState::Connecting, "/dev/pts/1");
    link.on_state(drivers::LinkState::Connected, "/dev/pts/1");
  }
  link.fill(status);
  EXPECT_EQ(status.connection, "connected");
  EXPECT_EQ(status.reconnects, 2u);
  EXPECT_EQ(link.state(), drivers::LinkState::Connected);
}

TEST(Live, StatusTakesTheDecodersCounters) {
  const drivers::WireFormat format;
  SensorFrame frame;
  frame.foot = Foot::Right;
  frame.size = InsoleSize::S37_38;
  frame.sensor_count = 107;
  std::vector<std::uint8_t> stream{0x00, 0x01, 0x02};  // garbage before the first frame
  for (const std::uint32_t sequence : {1u, 2u, 5u}) {  // 3 and 4 lost
    frame.sequence = sequence;
    std::vector<std::uint8_t> bytes(4096);
    bytes.resize(drivers::encode_frame(format, frame, bytes));
    stream.insert(stream.end(), bytes.begin(), bytes.end());
  }
  drivers::FrameDecoder decoder(format);
  int frames = 0;
  decoder.feed(stream, [&](const SensorFrame&) { ++frames; });
  ASSERT_EQ(frames, 3);

  // Half a frame, then the link drops: a truncated frame. Then the device restarts at 1.
  frame.sequence = 6;
  std::vector<std::uint8_t> half(4096);
  half.resize(drivers::encode_frame(format, frame, half) / 2);
  decoder.feed(half, [&](const SensorFrame&) { ++frames; });
  decoder.reset();
  frame.sequence = 1;
  std::vector<std::uint8_t> restarted(4096);
  restarted.resize(drivers::encode_frame(format, frame, restarted));
  decoder.feed(restarted, [&](const SensorFrame&) { ++frames; });
  ASSERT_EQ(frames, 4);

  StatusReport status;
  const OverflowingSource source;
  LinkStatus(decoder, source).fill(status);
  EXPECT_EQ(status.bytes_received, stream.size() + half.size() + restarted.size());
  EXPECT_EQ(status.frames_decoded, 4u);
  EXPECT_EQ(status.frames_lost_sequence, 2u);
  EXPECT_EQ(status.crc_errors, 0u);
  EXPECT_EQ(status.frames_truncated, 1u);
  EXPECT_EQ(status.header_errors, 0u);
  EXPECT_EQ(status.sequence_restarts, 1u);
  EXPECT_EQ(status.transfers_overflowed, 0u);
}

TEST(Live, StatusAndSummaryCarryTheSourcesOverflowedTransfers) {
  drivers::FrameDecoder decoder;
  OverflowingSource source;
  const LinkStatus link(decoder, source);
  // A source without overflows (a serial link or a replay: they have none to count) is not said
  // to have had USB transfers.
  EXPECT_EQ(link.summary().find("USB"), std::string::npos) << link.summary();
  source.overflowed.store(5);
  StatusReport status;
  link.fill(status);
  EXPECT_EQ(status.transfers_overflowed, 5u);
  EXPECT_TRUE(link.summary().ends_with("0 reconnects, 5 USB transfers overflowed"))
      << link.summary();
}

TEST(Live, OverflowedTransfersAreWarnedOfWhenTheyGrowAtMostOnceASecond) {
  drivers::FrameDecoder decoder;
  OverflowingSource source;
  LinkStatus link(decoder, source);
  const test::LogCapture log;
  link.warn_of_overflows();
  EXPECT_EQ(log.text.str(), "");

  source.overflowed.store(3);
  link.warn_of_overflows();
  source.overflowed.store(5);
  link.warn_of_overflows();  // within the second: held back
  const auto warnings = [&] {
    const std::string text = log.text.str();
    std::vector<std::string> lines;
    for (std::size_t at = text.find("link: "); at != std::string::npos;
         at = text.find("link: ", at + 1)) {
      lines.push_back(text.substr(at, text.find('\n', at) - at));
    }
    return lines;
  };
  const std::string first =
      "link: 3 USB transfers overflowed, 3 in all: the device sent more than a transfer holds and "
      "the excess bytes were lost; raise [usb] transfer_bytes";
  EXPECT_EQ(warnings(), std::vector<std::string>{first});

  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  link.warn_of_overflows();
  link.warn_of_overflows();  // nothing new
  const std::vector<std::string> both{
      first,
      "link: 2 USB transfers overflowed, 5 in all: the device sent more than a transfer holds and "
      "the excess bytes were lost; raise [usb] transfer_bytes"};
  EXPECT_EQ(warnings(), both);
}

// Without a CRC nothing tells a partial frame joined to the next connection's bytes from a real
// frame: only the reset on Disconnected keeps the two connections apart.
TEST(Live, ADroppedLinkDiscardsThePartialFrameOfTheOldConnection) {
  WireSettings settings;
  settings.crc = CrcKind::None;
  const drivers::WireFormat format(settings);
  SensorFrame frame;
  frame.foot = Foot::Left;
  frame.size = InsoleSize::S37_38;
  frame.sensor_count = 107;
  const auto encoded = [&](std::uint32_t sequence) {
    frame.sequence = sequence;
    std::vector<std::uint8_t> bytes(4096);
    bytes.resize(drivers::encode_frame(format, frame, bytes));
    return bytes;
  };
  drivers::FrameDecoder decoder(format);
  const OverflowingSource source;
  LinkStatus link(decoder, source);
  std::vector<std::uint32_t> sequences;
  const auto feed = [&](std::span<const std::uint8_t> bytes) {
    decoder.feed(bytes, [&](const SensorFrame& f) { sequences.push_back(f.sequence); });
  };

  link.on_state(drivers::LinkState::Connected, "/dev/pts/1");
  const std::vector<std::uint8_t> first = encoded(1);
  feed(std::span(first).first(first.size() / 2));
  link.on_state(drivers::LinkState::Disconnected, "read: EIO");
  link.on_state(drivers::LinkState::Connecting, "/dev/pts/1");
  link.on_state(drivers::LinkState::Connected, "/dev/pts/1");
  for (const std::uint32_t sequence : {2u, 3u, 4u}) feed(encoded(sequence));

  EXPECT_EQ(sequences, (std::vector<std::uint32_t>{2, 3, 4}));
  const drivers::DecoderCounters c = decoder.counters();
  EXPECT_EQ(c.frames, 3u);
  EXPECT_EQ(c.truncated_frames, 1u);
}

FitReport sample_fit() {
  FitReport r;
  r.foot = Foot::Right;
  r.step = 12;
  r.t_heel_strike_s = 10.25;
  r.t_toe_off_s = 10.87;
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    r.regions[i].region = kRegions[i];
    r.regions[i].status = "no_contact";
  }
  r.regions[0] = {
      .region = Region::Heel, .status = "ok", .kbar_n_per_mm3 = 0.117, .cbar_ns_per_mm3 = 0.011};
  r.regions[3].status = "fit_failed:too_few_frames";
  return r;
}

TEST(Live, PrintsOneLinePerFittedStepAndForwardsEveryMessage) {
  test::RecordingPublisher next;
  StepPrinter printer(next);
  EffectsReport effects;
  effects.steps = 24;
  effects.t_first_heel_strike_s = 1.0;
  effects.t_last_toe_off_s = 14.5;
  effects.baseline_nrmse_pct = 2.0;
  effects.extended_nrmse_pct = 1.0;
  effects.baseline_heldout_nrmse_pct = 2.25;
  effects.extended_heldout_nrmse_pct = 1.5;
  effects.params = {
      {"impact_transient", "amplitude_n", 80.0, 2.5},
      {"impact_transient", "duration_s", 0.04, std::numeric_limits<double>::quiet_NaN()}};

  testing::internal::CaptureStdout();
  printer.publish(FrameReport{});
  printer.publish(StepEvent{});
  printer.publish(sample_fit());
  FitReport inside = sample_fit();
  inside.effects_inside = "stress_relaxation,hysteresis";
  printer.publish(inside);
  FitReport running = sample_fit();
  running.regions[0].m_steps = 40;
  running.regions[4].m_steps = 38;
  printer.publish(running);
  printer.publish(StatusReport{});
  printer.publish(RawFrameReport{});
  printer.publish(effects);
  effects.final_estimate = true;
  printer.publish(effects);
  const std::string out = testing::internal::GetCapturedStdout();

  using Kind = test::RecordingPublisher::Kind;
  EXPECT_EQ(next.order(),
            (std::vector<Kind>{Kind::Frame, Kind::Step, Kind::Fit, Kind::Fit, Kind::Fit,
                               Kind::Status, Kind::Raw, Kind::Effects, Kind::Effects}));
  EXPECT_EQ(out,
            "R step   12  stance 0.620 s  kbar N/mm3 | cbar Ns/mm3:  heel 0.1170|0.01100  "
            "midfoot_posterior no_contact  midfoot_anterior no_contact  met1_2 "
            "fit_failed:too_few_frames  met3_5 no_contact  toe1 no_contact  toe2 no_contact  "
            "toes3_5 no_contact\n"
            "R step   12  stance 0.620 s  kbar N/mm3 | cbar Ns/mm3:  heel 0.1170|0.01100  "
            "midfoot_posterior no_contact  midfoot_anterior no_contact  met1_2 "
            "fit_failed:too_few_frames  met3_5 no_contact  toe1 no_contact  toe2 no_contact  "
            "toes3_5 no_contact  (stress_relaxation,hysteresis inside)\n"
            "R step   12  stance 0.620 s  kbar N/mm3 | cbar Ns/mm3:  heel 0.1170|0.01100  "
            "midfoot_posterior no_contact  midfoot_anterior no_contact  met1_2 "
            "fit_failed:too_few_frames  met3_5 no_contact  toe1 no_contact  toe2 no_contact  "
            "toes3_5 no_contact  (at the running m of up to 40 steps)\n"
            "effects over 24 steps (1.0-14.5 s): impact_transient.amplitude_n = 80 +- 2.5; "
            "impact_transient.duration_s = 0.04 (no SE); pooled NRMSE 2.00 % -> 1.00 % (held-out "
            "2.25 % -> 1.50 %)\n"
            "effects, final, over 24 steps (1.0-14.5 s): impact_transient.amplitude_n = 80 +- "
            "2.5; impact_transient.duration_s = 0.04 (no SE); pooled NRMSE 2.00 % -> 1.00 % "
            "(held-out 2.25 % -> 1.50 %)\n");
}

// Waits up to 5 s for `done`.
template <typename Done>
bool eventually(Done done) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!done()) {
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

// Signals still pending for this thread, taken so that they cannot reach a later test.
std::vector<int> take_pending() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  const timespec now{0, 0};
  std::vector<int> taken;
  for (int s; (s = sigtimedwait(&set, nullptr, &now)) > 0;) taken.push_back(s);
  return taken;
}

TEST(Live, TheFirstSignalStopsTheCommandOnceAndLaterOnesWaitBlocked) {
  std::atomic<int> calls{0};
  std::atomic<int> seen{0};
  StopOnSignal stop("the test", [&](int signal) {
    seen = signal;
    ++calls;
  });
  EXPECT_EQ(stop.received(), 0);
  ASSERT_EQ(kill(getpid(), SIGTERM), 0);
  ASSERT_TRUE(eventually([&] { return calls.load() == 1; }));
  EXPECT_EQ(seen.load(), SIGTERM);
  EXPECT_EQ(stop.received(), SIGTERM);

  ASSERT_EQ(kill(getpid(), SIGINT), 0);  // taken by the watcher and ignored
  ASSERT_TRUE(eventually([] {
    sigset_t pending;
    sigpending(&pending);
    return sigismember(&pending, SIGINT) == 0;
  })) << "the watcher did not take the second signal";
  stop.finish();
  EXPECT_EQ(calls.load(), 1);
  EXPECT_EQ(stop.received(), SIGTERM);

  // After finish() a signal is not acted on, and it does not kill the process either: it stays
  // pending, blocked.
  ASSERT_EQ(kill(getpid(), SIGINT), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(calls.load(), 1);
  EXPECT_EQ(take_pending(), std::vector<int>{SIGINT});
}

TEST(Live, AStopThatThrowsIsLoggedAndTheWatcherStillEnds) {
  std::atomic<int> calls{0};
  const test::LogCapture log;
  {
    StopOnSignal stop("the test", [&](int) {
      ++calls;
      throw std::runtime_error("the driver would not close");
    });
    ASSERT_EQ(kill(getpid(), SIGINT), 0);
    ASSERT_TRUE(eventually([&] { return stop.received() == SIGINT; }));
    ASSERT_TRUE(eventually([&] { return calls.load() == 1; }));
  }  // the destructor joins the watcher
  EXPECT_EQ(calls.load(), 1);
  EXPECT_TRUE(take_pending().empty());
  const std::string text = log.text.str();
  EXPECT_NE(text.find("SIGINT: stopping (the test)"), std::string::npos) << text;
  EXPECT_NE(text.find("stopping failed: the driver would not close"), std::string::npos) << text;
}

// A command that throws unwinds what the callback touches before the watcher it declared first:
// the guard, declared after those, stops the watcher before they go.
TEST(Live, TheGuardStopsTheWatcherWhenTheCommandThrows) {
  std::atomic<int> calls{0};
  StopOnSignal stop("the test", [&](int) { ++calls; });
  try {
    const FinishOnExit watching(stop);
    throw std::runtime_error("the driver failed");
  } catch (const std::runtime_error&) {
  }
  ASSERT_EQ(kill(getpid(), SIGINT), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(calls.load(), 0);
  EXPECT_EQ(stop.received(), 0);
  EXPECT_EQ(take_pending(), std::vector<int>{SIGINT});
}

}  // namespace
}  // namespace gaitmon::cli
