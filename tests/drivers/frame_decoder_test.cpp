// The frame decoder: round trips for every size and layout, any split of the stream, and every
// fault the decoder must survive and count (the wire format itself: wire_format_test.cpp).
#include "drivers/frame_decoder.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <random>
#include <thread>
#include <vector>

#include "allocation_count.hpp"
#include "gaitmon/session.hpp"

namespace gaitmon::drivers {
namespace {

using Bytes = std::vector<std::uint8_t>;

SensorFrame make_frame(Foot foot, InsoleSize size, std::uint32_t sequence, std::uint32_t seed) {
  SensorFrame frame;
  frame.foot = foot;
  frame.size = size;
  frame.sensor_count = static_cast<std::uint16_t>(session_sensor_count(size));
  frame.sequence = sequence;
  frame.device_time_us = sequence * 10000U + seed;
  for (std::size_t i = 0; i < frame.sensor_count; ++i) {
    frame.bits[i] = static_cast<std::uint8_t>((i * 7 + seed * 13 + sequence) % 256);
  }
  return frame;
}

Bytes encode(const WireFormat& format, const SensorFrame& frame) {
  Bytes out(format.frame_bytes(frame.sensor_count));
  EXPECT_EQ(encode_frame(format, frame, out), out.size());
  return out;
}

void append(Bytes& to, const Bytes& more) {
  to.insert(to.end(), more.begin(), more.end());
}

// Everything a decoded frame carries except the host time.
void expect_same(const SensorFrame& got, const SensorFrame& want) {
  EXPECT_EQ(got.foot, want.foot);
  EXPECT_EQ(got.size, want.size);
  EXPECT_EQ(got.sensor_count, want.sensor_count);
  EXPECT_EQ(got.sequence, want.sequence);
  EXPECT_EQ(got.device_time_us, want.device_time_us);
  EXPECT_EQ(got.bits, want.bits);
}

// Feeds `stream` in pieces of the given sizes (cycled) and collects the frames.
std::vector<SensorFrame> decode(FrameDecoder& decoder, const Bytes& stream,
                                const std::vector<std::size_t>& pieces = {}) {
  std::vector<SensorFrame> frames;
  auto sink = [&](const SensorFrame& frame) { frames.push_back(frame); };
  if (pieces.empty()) {
    decoder.feed(stream, sink);
    return frames;
  }
  std::size_t at = 0;
  for (std::size_t i = 0; at < stream.size(); ++i) {
    const std::size_t n = std::min(pieces[i % pieces.size()], stream.size() - at);
    decoder.feed(std::span(stream).subspan(at, n), sink);
    at += n;
  }
  return frames;
}

TEST(FrameDecoder, RoundTripsEveryInsoleSizeAndFoot) {
  const WireFormat format;
  Bytes stream;
  std::vector<SensorFrame> sent;
  std::uint32_t seq = 0;
  for (InsoleSize size : kInsoleSizes) {
    for (Foot foot : kFeet) {
      sent.push_back(make_frame(foot, size, seq, static_cast<std::uint32_t>(index_of(size))));
      append(stream, encode(format, sent.back()));
    }
    ++seq;
  }
  FrameDecoder decoder(format);
  const std::vector<SensorFrame> got = decode(decoder, stream);
  ASSERT_EQ(got.size(), sent.size());
  for (std::size_t i = 0; i < got.size(); ++i) expect_same(got[i], sent[i]);
  const DecoderCounters c = decoder.counters();
  EXPECT_EQ(c.bytes, stream.size());
  EXPECT_EQ(c.frames, sent.size());
  EXPECT_EQ(c.garbage_bytes, 0U);
  EXPECT_EQ(c.resyncs, 0U);
  EXPECT_EQ(c.crc_errors, 0U);
  EXPECT_EQ(c.lost_frames_total(), 0U);
}

TEST(FrameDecoder, RoundTripsEveryLayout) {
  for (const Bytes& sync :
       {Bytes{0x7E}, Bytes{0xA5, 0x5A}, Bytes{1, 2, 3}, Bytes{0xFF, 0, 0xFF, 0}}) {
    for (CrcKind crc : {CrcKind::None, CrcKind::Crc16CcittFalse, CrcKind::Crc32}) {
      for (bool big : {false, true}) {
        WireSettings settings;
        settings.sync = sync;
        settings.crc = crc;
        settings.crc_big_endian = big;
        const WireFormat format(settings);
        Bytes stream;
        std::vector<SensorFrame> sent;
        for (std::uint32_t i = 0; i < 20; ++i) {
          sent.push_back(
              make_frame(i % 2 == 0 ? Foot::Left : Foot::Right, InsoleSize::S45_46, i / 2, i));
          append(stream, encode(format, sent.back()));
        }
        FrameDecoder decoder(format);
        const auto got = decode(decoder, stream, {37});
        ASSERT_EQ(got.size(), sent.size())
            << sync.size() << " sync bytes, crc " << static_cast<int>(crc) << ", big " << big;
        for (std::size_t i = 0; i < got.size(); ++i) expect_same(got[i], sent[i]);
        EXPECT_EQ(decoder.counters().garbage_bytes, 0U);
      }
    }
  }
}

TEST(FrameDecoder, AcceptsAnyCountWhenTheSizeDoesNotFixIt) {
  WireSettings settings;
  settings.require_size_sensor_count = false;
  const WireFormat loose(settings);
  SensorFrame frame = make_frame(Foot::Right, InsoleSize::S45_46, 5, 1);
  frame.sensor_count = 162;  // the seed's Table 1 count for 45-46
  frame.bits[161] = 77;
  const Bytes bytes = encode(loose, frame);
  FrameDecoder decoder(loose);
  const auto got = decode(decoder, bytes);
  ASSERT_EQ(got.size(), 1U);
  expect_same(got[0], frame);

  FrameDecoder strict;
  EXPECT_TRUE(decode(strict, bytes).empty());
  EXPECT_EQ(strict.counters().header_errors, 1U);
}

TEST(FrameDecoder, SplitsAtEveryBoundaryGiveTheSameFrames) {
  const WireFormat format;
  Bytes stream;
  std::vector<SensorFrame> sent;
  for (std::uint32_t i = 0; i < 12; ++i) {
    sent.push_back(make_frame(Foot::Left, InsoleSize::S37_38, i, i));
    append(stream, encode(format, sent.back()));
  }
  for (std::size_t piece : {1, 2, 3, 5, 13, 114, 115, 116, 229, 1000}) {
    FrameDecoder decoder(format);
    const auto got = decode(decoder, stream, {piece});
    ASSERT_EQ(got.size(), sent.size()) << "pieces of " << piece;
    for (std::size_t i = 0; i < got.size(); ++i) expect_same(got[i], sent[i]);
    EXPECT_EQ(decoder.counters().garbage_bytes, 0U);
  }
  std::mt19937 rng(7);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<std::size_t> pieces;
    for (int i = 0; i < 30; ++i) pieces.push_back(1 + rng() % 300);
    FrameDecoder decoder(format);
    EXPECT_EQ(decode(decoder, stream, pieces).size(), sent.size());
  }
}

TEST(FrameDecoder, ResynchronisesAfterGarbage) {
  const WireFormat format;
  const SensorFrame a = make_frame(Foot::Left, InsoleSize::S39_40, 0, 1);
  const SensorFrame b = make_frame(Foot::Left, InsoleSize::S39_40, 1, 2);
  const SensorFrame c = make_frame(Foot::Left, InsoleSize::S39_40, 2, 3);
  Bytes stream{0x00, 0x5A, 0x13};                    // 3 bytes before the first frame
  append(stream, encode(format, a));                 //
  append(stream, Bytes{0xA5, 0x00, 0xA5});           // a lone first sync byte, twice
  append(stream, encode(format, b));                 //
  append(stream, Bytes{0xA5, 0x5A, 0x09, 0, 0, 0});  // a sync with an impossible header
  append(stream, Bytes(9, 0));
  append(stream, encode(format, c));
  for (std::size_t piece : {std::size_t{1}, std::size_t{7}, stream.size()}) {
    FrameDecoder decoder(format);
    const auto got = decode(decoder, stream, {piece});
    ASSERT_EQ(got.size(), 3U);
    expect_same(got[0], a);
    expect_same(got[1], b);
    expect_same(got[2], c);
    const DecoderCounters counters = decoder.counters();
    EXPECT_EQ(counters.garbage_bytes, 3U + 3U + 15U) << "pieces of " << piece;
    EXPECT_EQ(counters.resyncs, 3U);
    EXPECT_EQ(counters.header_errors, 1U);
    EXPECT_EQ(counters.crc_errors, 0U);
    EXPECT_EQ(counters.lost_frames_total(), 0U);
  }
}

TEST(FrameDecoder, RejectsACorruptedCrcAndResyncsFromTheNextByte) {
  const WireFormat format;
  std::vector<Bytes> frames;
  for (std::uint32_t i = 0; i < 5; ++i) {
    frames.push_back(encode(format, make_frame(Foot::Right, InsoleSize::S41_42, i, i)));
  }
  frames[1][40] ^= 0x10;     // a sensor byte
  frames[3].back() ^= 0x01;  // the CRC itself
  Bytes stream;
  for (const Bytes& f : frames) append(stream, f);
  for (std::size_t piece : {std::size_t{1}, std::size_t{64}, stream.size()}) {
    FrameDecoder decoder(format);
    const auto got = decode(decoder, stream, {piece});
    ASSERT_EQ(got.size(), 3U);
    EXPECT_EQ(got[0].sequence, 0U);
    EXPECT_EQ(got[1].sequence, 2U);
    EXPECT_EQ(got[2].sequence, 4U);
    const DecoderCounters c = decoder.counters();
    EXPECT_EQ(c.crc_errors, 2U);
    EXPECT_EQ(c.truncated_frames, 0U);
    EXPECT_EQ(c.resyncs, 2U);
    EXPECT_EQ(c.garbage_bytes, frames[1].size() + frames[3].size());
    EXPECT_EQ(c.lost_frames[1], 2U);
  }
}

// After rejecting a frame the decoder resumes one byte after its sync, so it finds a valid
// frame that was inside the rejected one's claimed span.
TEST(FrameDecoder, FindsAFrameHiddenInsideARejectedOne) {
  WireSettings settings;
  settings.require_size_sensor_count = false;
  const WireFormat loose(settings);
  const SensorFrame inner = make_frame(Foot::Left, InsoleSize::S35_36, 9, 4);
  const Bytes inner_bytes = encode(loose, inner);
  SensorFrame outer = make_frame(Foot::Left, InsoleSize::S45_46, 8, 4);
  outer.sensor_count = 161;
  std::copy(inner_bytes.begin(), inner_bytes.end(), outer.bits.begin() + 20);
  Bytes stream = encode(loose, outer);
  stream[2 + 12 + 6] ^= 0xFF;  // a sensor byte before the inner frame: the outer CRC fails
  FrameDecoder decoder(loose);
  const auto got = decode(decoder, stream, {1});
  ASSERT_EQ(got.size(), 1U);
  expect_same(got[0], inner);
  EXPECT_EQ(decoder.counters().truncated_frames, 1U);  // a frame began inside its span
}

TEST(FrameDecoder, CountsTruncatedFrames) {
  const WireFormat format;
  std::vector<Bytes> frames;
  for (std::uint32_t i = 0; i < 6; ++i) {
    frames.push_back(encode(format, make_frame(Foot::Left, InsoleSize::S43_44, i, i)));
  }
  const std::size_t cut1 = 1;                      // only the last CRC byte
  const std::size_t cut4 = frames[4].size() - 20;  // most of the sensor bytes
  frames[1].resize(frames[1].size() - cut1);
  frames[4].resize(frames[4].size() - cut4);
  Bytes stream;
  for (const Bytes& f : frames) append(stream, f);
  for (std::size_t piece : {std::size_t{1}, std::size_t{100}, stream.size()}) {
    FrameDecoder decoder(format);
    const auto got = decode(decoder, stream, {piece});
    ASSERT_EQ(got.size(), 4U);
    const DecoderCounters c = decoder.counters();
    EXPECT_EQ(c.truncated_frames, 2U);
    EXPECT_EQ(c.crc_errors, 0U);
    EXPECT_EQ(c.garbage_bytes, frames[1].size() + frames[4].size());
    EXPECT_EQ(c.lost_frames[0], 2U);
  }
}

TEST(FrameDecoder, ResetCountsAHeldFrameAsTruncated) {
  const WireFormat format;
  const Bytes whole = encode(format, make_frame(Foot::Left, InsoleSize::S37_38, 0, 0));
  FrameDecoder decoder(format);
  EXPECT_TRUE(decode(decoder, Bytes(whole.begin(), whole.begin() + 50)).empty());
  decoder.reset();
  EXPECT_EQ(decoder.counters().truncated_frames, 1U);
  EXPECT_EQ(decoder.counters().garbage_bytes, 50U);
  const auto got = decode(decoder, whole);
  EXPECT_EQ(got.size(), 1U);

  decode(decoder, Bytes{0xA5});  // only a sync prefix: garbage, not a frame
  decoder.reset();
  EXPECT_EQ(decoder.counters().truncated_frames, 1U);
  EXPECT_EQ(decoder.counters().garbage_bytes, 51U);
}

TEST(FrameDecoder, CountsSequenceGapsPerFootAcrossTheWrap) {
  const WireFormat format;
  Bytes stream;
  for (std::uint32_t seq : {0xFFFFFFFDU, 0xFFFFFFFEU, 0xFFFFFFFFU, 0U, 3U, 4U}) {
    append(stream, encode(format, make_frame(Foot::Left, InsoleSize::S37_38, seq, 0)));
  }
  for (std::uint32_t seq : {10U, 11U, 15U, 2U, 3U}) {  // 15 -> 2: the device restarted
    append(stream, encode(format, make_frame(Foot::Right, InsoleSize::S37_38, seq, 0)));
  }
  FrameDecoder decoder(format);
  EXPECT_EQ(decode(decoder, stream).size(), 11U);
  const DecoderCounters c = decoder.counters();
  EXPECT_EQ(c.lost_frames[0], 2U);  // 1 and 2
  EXPECT_EQ(c.lost_frames[1], 3U);  // 12, 13, 14
  EXPECT_EQ(c.sequence_restarts, 1U);
}

TEST(FrameDecoder, StampsTheHostMonotonicClock) {
  const WireFormat format;
  const Bytes bytes = encode(format, make_frame(Foot::Left, InsoleSize::S37_38, 0, 0));
  const auto before = std::chrono::duration_cast<std::chrono::nanoseconds>(
                          std::chrono::steady_clock::now().time_since_epoch())
                          .count();
  FrameDecoder decoder(format);
  const auto got = decode(decoder, bytes);
  const auto after = std::chrono::duration_cast<std::chrono::nanoseconds>(
                         std::chrono::steady_clock::now().time_since_epoch())
                         .count();
  ASSERT_EQ(got.size(), 1U);
  EXPECT_GE(got[0].host_time_ns, before);
  EXPECT_LE(got[0].host_time_ns, after);
}

TEST(FrameDecoder, AllocatesNothingPerFrame) {
  const WireFormat format;
  Bytes stream;
  for (std::uint32_t i = 0; i < 1000; ++i) {
    Bytes frame = encode(
        format, make_frame(i % 2 == 0 ? Foot::Left : Foot::Right, InsoleSize::S45_46, i / 2, i));
    if (i % 97 == 5) frame[30] ^= 1;                         // CRC errors
    if (i % 89 == 7) frame.resize(frame.size() - 9);         // truncations
    if (i % 83 == 3) stream.insert(stream.end(), 17, 0x33);  // garbage
    append(stream, frame);
  }
  FrameDecoder decoder(format);
  std::uint64_t frames = 0;
  std::uint64_t checksum = 0;
  auto sink = [&](const SensorFrame& f) {
    ++frames;
    checksum += f.bits[3];
  };
  const std::uint64_t before = test::allocations.load();
  for (std::size_t at = 0; at < stream.size(); at += 61) {
    decoder.feed(std::span(stream).subspan(at, std::min<std::size_t>(61, stream.size() - at)),
                 sink);
  }
  EXPECT_EQ(test::allocations.load() - before, 0U);
  EXPECT_GT(frames, 950U);
  EXPECT_GT(checksum, 0U);
}

TEST(FrameDecoder, CountersAreReadableFromAnotherThread) {
  const WireFormat format;
  Bytes stream;
  for (std::uint32_t i = 0; i < 2000; ++i) {
    append(stream, encode(format, make_frame(Foot::Left, InsoleSize::S35_36, i * 2, 0)));
  }
  FrameDecoder decoder(format);
  std::atomic<bool> done{false};
  std::uint64_t last_seen = 0;
  bool monotonic = true;
  std::atomic<std::uint64_t> reads{0};
  std::thread reader([&] {
    while (!done.load()) {
      const DecoderCounters c = decoder.counters();
      monotonic = monotonic && c.frames >= last_seen;
      last_seen = c.frames;
      reads.fetch_add(1);
    }
  });
  // Reading while the decoder is fed is the point: feed only once the reader reads.
  while (reads.load() == 0) std::this_thread::yield();
  for (std::size_t at = 0; at < stream.size(); at += 500) {
    decoder.feed(std::span(stream).subspan(at, std::min<std::size_t>(500, stream.size() - at)),
                 [](const SensorFrame&) {});
  }
  done = true;
  reader.join();
  EXPECT_GT(reads.load(), 1U);
  EXPECT_TRUE(monotonic);
  EXPECT_EQ(decoder.counters().frames, 2000U);
  EXPECT_EQ(decoder.counters().lost_frames[0], 1999U);
}

}  // namespace
}  // namespace gaitmon::drivers
