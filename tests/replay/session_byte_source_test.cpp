// The in-process fake driver and the fault injector with the decoder: a session played through
// the real decoder comes back frame for frame; pacing, stop, and injected faults counted exactly.
#include "replay/session_byte_source.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "drivers/frame_decoder.hpp"
#include "gaitmon/error.hpp"
#include "monitor_support.hpp"
#include "replay/fault_injector.hpp"
#include "test_support.hpp"

namespace gaitmon::replay {
namespace {

namespace fs = std::filesystem;
using drivers::DecoderCounters;
using drivers::FrameDecoder;
using drivers::LinkState;
using drivers::WireFormat;

// A short two-foot session with recognisable readings.
fs::path small_session(const std::string& name, double duration_s) {
  const fs::path path = test::scratch_dir(name) / "small.csv";
  SessionHeader header;
  header.insole_size = InsoleSize::S41_42;
  header.sensors = session_sensor_count(header.insole_size);
  SessionWriter writer(path, header);
  Frame frame;
  frame.bits.resize(header.sensors);
  for (int i = 0; i * 0.01 < duration_s; ++i) {
    for (Foot foot : kFeet) {
      frame.t_s = i / 100.0;  // to the microsecond, as recordings are
      frame.foot = foot;
      for (std::size_t s = 0; s < frame.bits.size(); ++s) {
        frame.bits[s] =
            static_cast<std::uint8_t>((i + s * 3 + (foot == Foot::Right ? 100 : 0)) % 256);
      }
      writer.write(frame);
    }
  }
  writer.close();
  return path;
}

struct Played {
  std::vector<SensorFrame> frames;
  std::vector<std::pair<LinkState, std::string>> states;
  DecoderCounters counters;
};

Played play(SessionByteSource& source, const WireFormat& format = WireFormat()) {
  Played out;
  FrameDecoder decoder(format);
  source.run(
      [&](std::span<const std::uint8_t> bytes) {
        decoder.feed(bytes, [&](const SensorFrame& f) { out.frames.push_back(f); });
      },
      [&](LinkState state, std::string_view detail) { out.states.emplace_back(state, detail); });
  out.counters = decoder.counters();
  return out;
}

void expect_matches_file(const std::vector<SensorFrame>& got, const std::vector<Frame>& want) {
  ASSERT_EQ(got.size(), want.size());
  std::array<std::uint32_t, 2> sequence{};
  for (std::size_t i = 0; i < want.size(); ++i) {
    const auto foot = static_cast<std::size_t>(want[i].foot);
    ASSERT_EQ(got[i].foot, want[i].foot) << "frame " << i;
    ASSERT_EQ(got[i].sequence, sequence[foot]++) << "frame " << i;
    // The monitor recovers the recording's time exactly.
    ASSERT_EQ(got[i].device_time_us / 1e6, want[i].t_s) << "frame " << i;
    ASSERT_EQ(got[i].sensor_count, want[i].bits.size());
    ASSERT_TRUE(std::equal(want[i].bits.begin(), want[i].bits.end(), got[i].bits.begin()))
        << "frame " << i;
  }
}

TEST(SessionByteSource, PlaysTheDemoThroughTheDecoderFrameForFrame) {
  SessionByteSource source(test::demo_session(), WireFormat(), kMaxSpeed);
  const Played played = play(source);
  expect_matches_file(played.frames, test::file_frames(test::demo_session()));
  EXPECT_EQ(source.frames_sent(), played.frames.size());
  EXPECT_EQ(played.counters.garbage_bytes, 0U);
  EXPECT_EQ(played.counters.lost_frames_total(), 0U);
  ASSERT_EQ(played.states.size(), 3U);
  EXPECT_EQ(played.states[0].first, LinkState::Connecting);
  EXPECT_EQ(played.states[1].first, LinkState::Connected);
  EXPECT_EQ(played.states[2].first, LinkState::Disconnected);
  EXPECT_EQ(played.states[2].second, "end of session");
}

TEST(SessionByteSource, UsesTheConfiguredLayout) {
  WireSettings settings;
  settings.sync = {0x7E, 0x81, 0x7E};
  settings.crc = CrcKind::Crc32;
  const WireFormat format(settings);
  const fs::path path = small_session("layout", 0.5);
  SessionByteSource source(path, format, kMaxSpeed);
  expect_matches_file(play(source, format).frames, test::file_frames(path));
}

TEST(SessionByteSource, PacesAtTheRequestedSpeed) {
  const fs::path path = small_session("paced", 1.0);  // frames from 0 to 0.99 s
  SessionByteSource source(path, WireFormat(), 10.0);
  const auto start = std::chrono::steady_clock::now();
  const Played played = play(source);
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_GE(elapsed_s, 0.99 / 10.0);  // never early; how late is load-dependent
  expect_matches_file(played.frames, test::file_frames(path));
}

TEST(SessionByteSource, StopEndsAPacedReplaySoon) {
  SessionByteSource source(test::demo_session(), WireFormat(), 1.0);  // 60 s at real time
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    source.stop();
  });
  const auto start = std::chrono::steady_clock::now();
  const Played played = play(source);
  stopper.join();
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
  EXPECT_GT(played.frames.size(), 0U);
  EXPECT_LT(played.frames.size(), 12000U);
  EXPECT_EQ(played.frames.size(), source.frames_sent());
  EXPECT_EQ(played.states.back().second, "stopped");
}

TEST(SessionByteSource, RefusesABadSessionAndSpeed) {
  const fs::path bad = test::write_text(test::scratch_dir("bad") / "bad.csv", "t_s,foot\n");
  EXPECT_THROW(SessionByteSource(bad, WireFormat(), 1.0), InputError);
  EXPECT_THROW(SessionByteSource(test::demo_session(), WireFormat(), 0.0), std::invalid_argument);
}

// A replay publishes what it plays: a bad line near the end found while playing would come after
// the frames before it were out. The whole file is checked first; a header alone is no session.
TEST(SessionByteSource, ABadLastLineOrNoFrameIsFoundBeforeAnythingIsPlayed) {
  const fs::path good = small_session("bad-last-line", 0.5);
  std::ifstream in(good);
  std::string text;
  std::uint64_t lines = 0;
  for (std::string line; std::getline(in, line); ++lines) text += line + "\n";
  const fs::path bad =
      test::write_text(good.parent_path() / "bad.csv", text + "0.5,L,not-a-number\n");
  try {
    SessionByteSource source(bad, WireFormat(), kMaxSpeed);
    ADD_FAILURE() << "played " << play(source).frames.size() << " frames of a bad file";
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), lines + 1) << e.what();
  }
  const fs::path empty = test::write_text(good.parent_path() / "empty.csv", test::session_head());
  try {
    SessionByteSource source(empty, WireFormat(), kMaxSpeed);
    ADD_FAILURE() << "a session without frames was accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), empty.string() + ": no frames");
  }
}

TEST(FaultInjector, EveryInjectedFaultIsCountedByTheDecoder) {
  const WireFormat format;
  FaultOptions options;
  options.seed = 11;
  options.garbage_rate = 0.05;
  options.garbage_max_bytes = 40;
  options.crc_rate = 0.02;
  options.truncate_rate = 0.02;
  FaultInjector injector(options, format);
  const std::vector<Frame> frames = test::file_frames(test::demo_session());
  SessionEncoder encoder(format, InsoleSize::S37_38);
  std::vector<std::uint8_t> stream;
  std::vector<std::uint8_t> wire;
  for (const Frame& frame : frames) {
    const SensorFrame& sent = encoder.next(frame);
    wire.clear();
    encoder.append_wire(wire);
    injector.append(wire, sent.foot, sent.sequence, stream);
  }
  const FaultCounts& injected = injector.counts();
  ASSERT_GT(injected.garbage_bursts, 100U);
  ASSERT_GT(injected.crc_corrupted, 100U);
  ASSERT_GT(injected.truncated, 100U);

  FrameDecoder decoder(format);
  std::array<std::vector<std::uint32_t>, 2> decoded;
  for (std::size_t at = 0; at < stream.size(); at += 4096) {
    decoder.feed(std::span(stream).subspan(at, std::min<std::size_t>(4096, stream.size() - at)),
                 [&](const SensorFrame& f) {
                   decoded[static_cast<std::size_t>(f.foot)].push_back(f.sequence);
                 });
  }
  decoder.reset();
  const DecoderCounters c = decoder.counters();
  const std::uint64_t frame_bytes = format.frame_bytes(107);
  EXPECT_EQ(c.crc_errors, injected.crc_corrupted);
  EXPECT_EQ(c.truncated_frames, injected.truncated);
  EXPECT_EQ(c.header_errors, 0U);
  EXPECT_EQ(c.garbage_bytes, injected.garbage_bytes + frame_bytes * injected.crc_corrupted +
                                 frame_bytes * injected.truncated - injected.dropped_bytes);
  EXPECT_EQ(c.frames, frames.size() - injected.crc_corrupted - injected.truncated);
  for (std::size_t foot = 0; foot < 2; ++foot) {
    // Exactly the frames not faulted, in order.
    const auto& faulted = injected.faulted_sequences[foot];
    std::vector<std::uint32_t> expected;
    std::uint32_t total = 0;
    for (const Frame& f : frames) total += static_cast<std::size_t>(f.foot) == foot ? 1 : 0;
    for (std::uint32_t s = 0; s < total; ++s) {
      if (std::find(faulted.begin(), faulted.end(), s) == faulted.end()) expected.push_back(s);
    }
    EXPECT_EQ(decoded[foot], expected);
    const auto lost = static_cast<std::uint64_t>(std::count_if(
        faulted.begin(), faulted.end(), [&](std::uint32_t s) { return s < decoded[foot].back(); }));
    EXPECT_EQ(c.lost_frames[foot], lost);
  }
}

}  // namespace
}  // namespace gaitmon::replay
