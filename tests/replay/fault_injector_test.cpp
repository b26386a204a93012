// The fault injector's documented faults, one frame at a time: garbage bursts of 1..max bytes
// that never hold the first sync byte and never follow a truncation, one flipped bit or a cut
// tail that never touch sync and header, counts and faulted sequences that match what was done,
// and the same faults for the same seed. Decoding an injected stream: session_byte_source_test.
#include "replay/fault_injector.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace gaitmon::replay {
namespace {

using Bytes = std::vector<std::uint8_t>;
using drivers::WireFormat;
using ::testing::HasSubstr;

Bytes wire_frame(const WireFormat& format, std::uint32_t sequence) {
  SensorFrame frame;
  frame.size = InsoleSize::S35_36;
  frame.sensor_count = 93;
  frame.sequence = sequence;
  for (std::size_t i = 0; i < 93; ++i) frame.bits[i] = static_cast<std::uint8_t>(i * 3);
  Bytes out(format.frame_bytes(93));
  drivers::encode_frame(format, frame, out);
  return out;
}

// What one append wrote (garbage, then the frame as sent).
struct Appended {
  Bytes garbage;
  Bytes frame;
};

Appended append_one(FaultInjector& injector, const Bytes& wire, Foot foot, std::uint32_t seq) {
  Bytes out;
  injector.append(wire, foot, seq, out);
  // Garbage never holds the first sync byte, so the frame starts at the first one.
  const auto start = std::find(out.begin(), out.end(), wire[0]);
  return {Bytes(out.begin(), start), Bytes(start, out.end())};
}

std::string refusal(const FaultOptions& options, const WireFormat& format) {
  try {
    FaultInjector injector(options, format);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  ADD_FAILURE() << "the options were accepted";
  return {};
}

TEST(FaultInjector, RefusesImpossibleOptions) {
  FaultOptions options;
  options.crc_rate = 0.7;
  options.truncate_rate = 0.7;
  EXPECT_THAT(refusal(options, WireFormat()), HasSubstr("add up to at most 1"));
  options = {};
  options.garbage_rate = 1.5;
  EXPECT_THAT(refusal(options, WireFormat()), HasSubstr("[0, 1]"));
  options = {};
  options.truncate_rate = -0.1;
  EXPECT_THAT(refusal(options, WireFormat()), HasSubstr("[0, 1]"));
  options = {};
  options.crc_rate = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(refusal(options, WireFormat()), HasSubstr("[0, 1]"));
  options = {};
  options.garbage_max_bytes = 0;
  EXPECT_THAT(refusal(options, WireFormat()), HasSubstr("at least 1 byte"));
  options = {};
  options.crc_rate = 0.1;
  WireSettings none;
  none.crc = CrcKind::None;
  EXPECT_THAT(refusal(options, WireFormat(none)), HasSubstr("a wire format with a CRC"));
}

TEST(FaultInjector, AcceptsTheLimitsOfItsOptions) {
  FaultOptions options;
  options.garbage_rate = 1.0;
  options.crc_rate = 0.5;
  options.truncate_rate = 0.5;
  options.garbage_max_bytes = 1;
  EXPECT_NO_THROW(FaultInjector(options, WireFormat()));
  WireSettings none;
  none.crc = CrcKind::None;
  options.crc_rate = 0.0;
  options.truncate_rate = 1.0;
  EXPECT_NO_THROW(FaultInjector(options, WireFormat(none)));
}

TEST(FaultInjector, WithoutFaultsFramesPassThroughUnchanged) {
  const WireFormat format;
  FaultInjector injector(FaultOptions{}, format);
  Bytes stream;
  Bytes expected;
  for (std::uint32_t seq = 0; seq < 50; ++seq) {
    const Bytes wire = wire_frame(format, seq);
    injector.append(wire, seq % 2 == 0 ? Foot::Left : Foot::Right, seq, stream);
    expected.insert(expected.end(), wire.begin(), wire.end());
  }
  EXPECT_EQ(stream, expected);
  const FaultCounts& counts = injector.counts();
  EXPECT_EQ(counts.frames, 50U);
  EXPECT_EQ(counts.garbage_bursts + counts.crc_corrupted + counts.truncated, 0U);
  EXPECT_EQ(counts.garbage_bytes + counts.dropped_bytes, 0U);
  EXPECT_TRUE(counts.faulted_sequences[0].empty());
  EXPECT_TRUE(counts.faulted_sequences[1].empty());
}

// The byte after sync0 is shifted down onto it, so sync0 = 0x00 and 0xFF are the edges of that
// arithmetic; every burst length from 1 to the maximum occurs.
TEST(FaultInjector, GarbageBurstsAvoidTheFirstSyncByte) {
  for (std::uint8_t sync0 : {std::uint8_t{0x00}, std::uint8_t{0xA5}, std::uint8_t{0xFF}}) {
    WireSettings settings;
    settings.sync = {sync0, 0x5A};
    const WireFormat format(settings);
    FaultOptions options;
    options.garbage_rate = 1.0;
    options.garbage_max_bytes = 4;
    FaultInjector injector(options, format);
    const Bytes wire = wire_frame(format, 0);
    std::vector<std::size_t> lengths(options.garbage_max_bytes + 1);
    std::uint64_t garbage_bytes = 0;
    std::vector<bool> seen(256);
    for (std::uint32_t seq = 0; seq < 2000; ++seq) {
      Bytes out;
      injector.append(wire, Foot::Left, seq, out);
      ASSERT_GT(out.size(), wire.size()) << "every frame gets a burst";
      const std::size_t n = out.size() - wire.size();
      ASSERT_LE(n, options.garbage_max_bytes);
      ++lengths[n];
      garbage_bytes += n;
      EXPECT_TRUE(
          std::equal(wire.begin(), wire.end(), out.begin() + static_cast<std::ptrdiff_t>(n)));
      for (std::size_t i = 0; i < n; ++i) seen[out[i]] = true;
    }
    EXPECT_FALSE(seen[sync0]) << int{sync0};
    EXPECT_EQ(std::count(seen.begin(), seen.end(), true), 255) << int{sync0};
    for (std::size_t n = 1; n <= options.garbage_max_bytes; ++n) EXPECT_GT(lengths[n], 0U) << n;
    const FaultCounts& counts = injector.counts();
    EXPECT_EQ(counts.garbage_bursts, 2000U);
    EXPECT_EQ(counts.garbage_bytes, garbage_bytes);
    EXPECT_TRUE(counts.faulted_sequences[0].empty()) << "garbage is not a frame fault";
  }
}

// One bit flipped in the readings or the CRC, never in the 4-byte sync or the header; both
// parts are hit over many frames.
TEST(FaultInjector, CrcCorruptionFlipsOneBitAfterTheHeader) {
  WireSettings settings;
  settings.sync = {0xA5, 0x5A, 0xC3, 0x3C};
  settings.crc = CrcKind::Crc32;
  const WireFormat format(settings);
  constexpr std::size_t kPrefix = 4 + drivers::kWireHeaderBytes;
  FaultOptions options;
  options.seed = 5;
  options.crc_rate = 1.0;
  FaultInjector injector(options, format);
  const Bytes wire = wire_frame(format, 0);
  bool hit_readings = false;
  bool hit_crc = false;
  for (std::uint32_t seq = 0; seq < 500; ++seq) {
    Bytes out;
    injector.append(wire, Foot::Right, seq, out);
    ASSERT_EQ(out.size(), wire.size());
    int flipped = 0;
    for (std::size_t i = 0; i < wire.size(); ++i) {
      const auto diff = static_cast<std::uint8_t>(out[i] ^ wire[i]);
      if (diff == 0) continue;
      flipped += std::popcount(diff);
      EXPECT_GE(i, kPrefix) << "sync or header touched";
      (i >= wire.size() - 4 ? hit_crc : hit_readings) = true;
    }
    EXPECT_EQ(flipped, 1) << seq;
  }
  EXPECT_TRUE(hit_readings);
  EXPECT_TRUE(hit_crc);
  const FaultCounts& counts = injector.counts();
  EXPECT_EQ(counts.crc_corrupted, 500U);
  EXPECT_EQ(counts.truncated, 0U);
  EXPECT_TRUE(counts.faulted_sequences[0].empty());
  ASSERT_EQ(counts.faulted_sequences[1].size(), 500U);
  for (std::uint32_t seq = 0; seq < 500; ++seq) EXPECT_EQ(counts.faulted_sequences[1][seq], seq);
}

// The cut keeps sync and header and drops 1 to all of the readings and CRC: both extremes occur.
TEST(FaultInjector, TruncationDropsPartOfTheTailOnly) {
  const WireFormat format;
  constexpr std::size_t kPrefix = 2 + drivers::kWireHeaderBytes;
  FaultOptions options;
  options.seed = 9;
  options.truncate_rate = 1.0;
  FaultInjector injector(options, format);
  const Bytes wire = wire_frame(format, 0);
  std::uint64_t dropped = 0;
  std::size_t shortest = wire.size();
  std::size_t longest = 0;
  for (std::uint32_t seq = 0; seq < 3000; ++seq) {
    Bytes out;
    injector.append(wire, Foot::Left, seq, out);
    ASSERT_GE(out.size(), kPrefix);
    ASSERT_LT(out.size(), wire.size());
    EXPECT_TRUE(std::equal(out.begin(), out.end(), wire.begin()));
    dropped += wire.size() - out.size();
    shortest = std::min(shortest, out.size());
    longest = std::max(longest, out.size());
  }
  EXPECT_EQ(shortest, kPrefix);
  EXPECT_EQ(longest, wire.size() - 1);
  const FaultCounts& counts = injector.counts();
  EXPECT_EQ(counts.truncated, 3000U);
  EXPECT_EQ(counts.dropped_bytes, dropped);
  EXPECT_EQ(counts.faulted_sequences[0].size(), 3000U);
}

// Garbage after a cut frame would hide the truncation from the decoder, so none follows one;
// after a whole frame, garbage at rate 1 always comes.
TEST(FaultInjector, NoGarbageFollowsATruncatedFrame) {
  const WireFormat format;
  FaultOptions options;
  options.seed = 3;
  options.garbage_rate = 1.0;
  options.truncate_rate = 0.5;
  FaultInjector injector(options, format);
  const Bytes wire = wire_frame(format, 0);
  bool last_truncated = false;
  std::uint64_t truncated = 0;
  for (std::uint32_t seq = 0; seq < 400; ++seq) {
    const Appended got = append_one(injector, wire, Foot::Left, seq);
    EXPECT_EQ(got.garbage.empty(), last_truncated) << seq;
    last_truncated = got.frame.size() < wire.size();
    truncated += last_truncated ? 1 : 0;
  }
  EXPECT_GT(truncated, 100U);
  EXPECT_LT(truncated, 300U);
  EXPECT_EQ(injector.counts().truncated, truncated);
}

// The rates are per-frame probabilities: over many frames each fault's share is near its rate.
TEST(FaultInjector, FaultSharesFollowTheRates) {
  const WireFormat format;
  FaultOptions options;
  options.seed = 21;
  options.garbage_rate = 0.3;
  options.crc_rate = 0.1;
  options.truncate_rate = 0.2;
  FaultInjector injector(options, format);
  const Bytes wire = wire_frame(format, 0);
  Bytes stream;
  constexpr std::uint32_t kFrames = 10000;
  for (std::uint32_t seq = 0; seq < kFrames; ++seq) injector.append(wire, Foot::Left, seq, stream);
  const FaultCounts& counts = injector.counts();
  EXPECT_EQ(counts.frames, kFrames);
  EXPECT_NEAR(static_cast<double>(counts.crc_corrupted) / kFrames, 0.1, 0.02);
  EXPECT_NEAR(static_cast<double>(counts.truncated) / kFrames, 0.2, 0.02);
  // Garbage is drawn only after the frames that were not cut.
  EXPECT_NEAR(static_cast<double>(counts.garbage_bursts) / kFrames, 0.3 * 0.8, 0.02);
  EXPECT_EQ(counts.faulted_sequences[0].size(), counts.crc_corrupted + counts.truncated);
  EXPECT_EQ(stream.size(), kFrames * wire.size() + counts.garbage_bytes - counts.dropped_bytes);
}

TEST(FaultInjector, TheSeedFixesTheFaults) {
  const WireFormat format;
  FaultOptions options;
  options.garbage_rate = 0.2;
  options.crc_rate = 0.1;
  options.truncate_rate = 0.1;
  auto stream_of = [&](std::uint64_t seed) {
    options.seed = seed;
    FaultInjector injector(options, format);
    Bytes stream;
    for (std::uint32_t seq = 0; seq < 300; ++seq) {
      injector.append(wire_frame(format, seq), Foot::Left, seq, stream);
    }
    return stream;
  };
  EXPECT_EQ(stream_of(7), stream_of(7));
  EXPECT_NE(stream_of(7), stream_of(8));
}

}  // namespace
}  // namespace gaitmon::replay
