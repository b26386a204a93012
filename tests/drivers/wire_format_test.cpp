// The wire format's contract against drivers/PROTOCOL.md: checksum check values, the written
// test vector and header layout (expected bytes taken from the spec, not from the encoder),
// every [wire] layout, and the refusals that must name their reason.
#include "drivers/wire_format.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <array>
#include <random>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace gaitmon::drivers {
namespace {

using Bytes = std::vector<std::uint8_t>;
using ::testing::HasSubstr;

Bytes ascii(std::string_view text) {
  return Bytes(text.begin(), text.end());
}

Bytes encode(const WireFormat& format, const SensorFrame& frame) {
  Bytes out(format.frame_bytes(frame.sensor_count));
  EXPECT_EQ(encode_frame(format, frame, out), out.size());
  return out;
}

// The frame of PROTOCOL.md's test vector: left, 35-36, sequence 1, 10000 us, reading i = i.
SensorFrame protocol_vector_frame() {
  SensorFrame frame;
  frame.foot = Foot::Left;
  frame.size = InsoleSize::S35_36;
  frame.sensor_count = 93;
  frame.sequence = 1;
  frame.device_time_us = 10000;
  for (std::size_t i = 0; i < 93; ++i) frame.bits[i] = static_cast<std::uint8_t>(i);
  return frame;
}

WireSettings settings_with(CrcKind crc, bool big_endian) {
  WireSettings settings;
  settings.crc = crc;
  settings.crc_big_endian = big_endian;
  return settings;
}

// The what() of the std::invalid_argument `call` throws; fails the test if it throws nothing.
template <typename Call>
std::string invalid_argument_message(Call call) {
  try {
    call();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  ADD_FAILURE() << "no std::invalid_argument";
  return {};
}

TEST(WireFormat, ChecksumTestVectors) {
  EXPECT_EQ(crc16_ccitt_false(ascii("123456789")), 0x29B1);
  EXPECT_EQ(crc32_iso_hdlc(ascii("123456789")), 0xCBF43926U);
  EXPECT_EQ(crc16_ccitt_false({}), 0xFFFF);
}

// Bit-at-a-time references, independent of the table-driven code under test.
std::uint16_t crc16_bitwise(std::span<const std::uint8_t> data) {
  std::uint32_t crc = 0xFFFF;
  for (std::uint8_t byte : data) {
    crc ^= static_cast<std::uint32_t>(byte) << 8;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 0x8000U) != 0 ? (crc << 1) ^ 0x1021U : crc << 1;
    crc &= 0xFFFFU;
  }
  return static_cast<std::uint16_t>(crc);
}

std::uint32_t crc32_bitwise(std::span<const std::uint8_t> data) {
  std::uint32_t crc = 0xFFFFFFFFU;
  for (std::uint8_t byte : data) {
    crc ^= byte;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 1U) != 0 ? (crc >> 1) ^ 0xEDB88320U : crc >> 1;
  }
  return ~crc;
}

TEST(WireFormat, ChecksumsEqualABitwiseReferenceForEveryLength) {
  std::mt19937 rng(3);
  for (std::size_t length = 0; length < 200; ++length) {
    Bytes data(length);
    for (auto& b : data) b = static_cast<std::uint8_t>(rng());
    EXPECT_EQ(crc16_ccitt_false(data), crc16_bitwise(data)) << length;
    EXPECT_EQ(crc32_iso_hdlc(data), crc32_bitwise(data)) << length;
  }
}

// The test vector of drivers/PROTOCOL.md, worked out independently (bitwise CRC in Python).
TEST(WireFormat, EncodesTheProtocolTestVector) {
  const SensorFrame frame = protocol_vector_frame();
  const Bytes bytes = encode(WireFormat(), frame);
  ASSERT_EQ(bytes.size(), 109U);
  const Bytes head{0xA5, 0x5A, 0x01, 0x00, 0x00, 0x5D, 0x01,
                   0x00, 0x00, 0x00, 0x10, 0x27, 0x00, 0x00};
  EXPECT_EQ(Bytes(bytes.begin(), bytes.begin() + 14), head);
  for (std::size_t i = 0; i < 93; ++i) EXPECT_EQ(bytes[14 + i], i);
  EXPECT_EQ(bytes[107], 0x01);
  EXPECT_EQ(bytes[108], 0xD5);

  const Bytes crc32 = encode(WireFormat(settings_with(CrcKind::Crc32, true)), frame);
  ASSERT_EQ(crc32.size(), 111U);
  EXPECT_EQ(Bytes(crc32.end() - 4, crc32.end()), (Bytes{0xD9, 0x88, 0xA9, 0x55}));
}

// The byte orders PROTOCOL.md gives for the test vector's CRC fields that the vector test above
// leaves out, and the CRC kind `none`, whose frame ends with the readings.
TEST(WireFormat, WritesTheCrcFieldInEachKindAndByteOrder) {
  const SensorFrame frame = protocol_vector_frame();
  const Bytes crc16_be = encode(WireFormat(settings_with(CrcKind::Crc16CcittFalse, true)), frame);
  ASSERT_EQ(crc16_be.size(), 109U);
  EXPECT_EQ(Bytes(crc16_be.end() - 2, crc16_be.end()), (Bytes{0xD5, 0x01}));

  const Bytes crc32_le = encode(WireFormat(settings_with(CrcKind::Crc32, false)), frame);
  ASSERT_EQ(crc32_le.size(), 111U);
  EXPECT_EQ(Bytes(crc32_le.end() - 4, crc32_le.end()), (Bytes{0x55, 0xA9, 0x88, 0xD9}));

  const Bytes none = encode(WireFormat(settings_with(CrcKind::None, false)), frame);
  ASSERT_EQ(none.size(), 107U);
  EXPECT_EQ(none.back(), 92);  // the last reading
}

TEST(WireFormat, ChecksumDispatchesOnTheCrcKind) {
  const Bytes check = ascii("123456789");
  EXPECT_EQ(WireFormat().checksum(check), 0x29B1U);
  EXPECT_EQ(WireFormat(settings_with(CrcKind::Crc32, false)).checksum(check), 0xCBF43926U);
  EXPECT_EQ(WireFormat(settings_with(CrcKind::None, false)).checksum(check), 0U);
  EXPECT_EQ(WireFormat().crc_bytes(), 2U);
  EXPECT_EQ(WireFormat(settings_with(CrcKind::Crc32, false)).crc_bytes(), 4U);
  EXPECT_EQ(WireFormat(settings_with(CrcKind::None, false)).crc_bytes(), 0U);
}

// The default constructor spells the defaults out separately from WireSettings{}; they must
// not drift apart.
TEST(WireFormat, DefaultEqualsTheDefaultSettings) {
  const WireFormat defaults;
  const WireFormat from_settings{WireSettings{}};
  const Bytes a5_5a{0xA5, 0x5A};
  EXPECT_EQ(Bytes(defaults.sync().begin(), defaults.sync().end()), a5_5a);
  EXPECT_EQ(Bytes(from_settings.sync().begin(), from_settings.sync().end()), a5_5a);
  EXPECT_EQ(defaults.crc(), CrcKind::Crc16CcittFalse);
  EXPECT_EQ(from_settings.crc(), CrcKind::Crc16CcittFalse);
  EXPECT_FALSE(defaults.crc_big_endian());
  EXPECT_FALSE(from_settings.crc_big_endian());
  EXPECT_TRUE(defaults.require_size_sensor_count());
  EXPECT_TRUE(from_settings.require_size_sensor_count());
}

// PROTOCOL.md: S + 12 + N + C bytes, 123 for size 37-38 with the defaults.
TEST(WireFormat, FrameLengthFollowsTheSpec) {
  EXPECT_EQ(WireFormat().frame_bytes(107), 123U);
  WireSettings longest = settings_with(CrcKind::Crc32, false);
  longest.sync = {1, 2, 3, 4};
  EXPECT_EQ(WireFormat(longest).frame_bytes(162), 4U + 12U + 162U + 4U);
  EXPECT_EQ(kMaxFrameBytes, 182U);
  WireSettings shortest = settings_with(CrcKind::None, false);
  shortest.sync = {0x7E};
  EXPECT_EQ(WireFormat(shortest).frame_bytes(1), 14U);
}

// The CRC covers the header and readings but not the sync, so the test vector's CRC is the same
// behind a sync of any length.
TEST(WireFormat, SyncOfOneToFourBytesLeadsTheFrameOutsideTheCrc) {
  const SensorFrame frame = protocol_vector_frame();
  for (const Bytes& sync : {Bytes{0x7E}, Bytes{0xDE, 0xAD, 0xBE}, Bytes{0xFF, 0x00, 0xFF, 0x00}}) {
    WireSettings settings;
    settings.sync = sync;
    const Bytes bytes = encode(WireFormat(settings), frame);
    ASSERT_EQ(bytes.size(), sync.size() + 12 + 93 + 2);
    EXPECT_EQ(Bytes(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(sync.size())), sync);
    EXPECT_EQ(bytes[sync.size()], 0x01) << "the version follows the sync";
    EXPECT_EQ(Bytes(bytes.end() - 2, bytes.end()), (Bytes{0x01, 0xD5}));
  }
}

// Every header field at its offset, little-endian, at the far end of each range: right foot,
// the largest size, and sequence and device time at the values that wrap next.
TEST(WireFormat, HeaderFieldsAtTheirLimits) {
  SensorFrame frame;
  frame.foot = Foot::Right;
  frame.size = InsoleSize::S45_46;
  frame.sensor_count = 161;
  frame.sequence = 0xFFFFFFFFU;
  frame.device_time_us = 0x12345678U;
  frame.bits.fill(0xFF);
  const Bytes bytes = encode(WireFormat(), frame);
  ASSERT_EQ(bytes.size(), 2U + 12U + 161U + 2U);
  const Bytes head{0xA5, 0x5A, 0x01, 0x01, 0x05, 0xA1, 0xFF,
                   0xFF, 0xFF, 0xFF, 0x78, 0x56, 0x34, 0x12};
  EXPECT_EQ(Bytes(bytes.begin(), bytes.begin() + 14), head);
  for (std::size_t i = 0; i < 161; ++i) EXPECT_EQ(bytes[14 + i], 0xFF) << i;
}

// Each size's code and count as PROTOCOL.md lists them.
TEST(WireFormat, WritesEachInsoleSizeCodeAndCount) {
  const std::array<std::pair<InsoleSize, std::uint8_t>, 6> sizes{{{InsoleSize::S35_36, 93},
                                                                  {InsoleSize::S37_38, 107},
                                                                  {InsoleSize::S39_40, 116},
                                                                  {InsoleSize::S41_42, 129},
                                                                  {InsoleSize::S43_44, 151},
                                                                  {InsoleSize::S45_46, 161}}};
  for (std::size_t code = 0; code < sizes.size(); ++code) {
    SensorFrame frame;
    frame.size = sizes[code].first;
    frame.sensor_count = sizes[code].second;
    const Bytes bytes = encode(WireFormat(), frame);
    EXPECT_EQ(bytes[4], code);
    EXPECT_EQ(bytes[5], sizes[code].second);
  }
}

// With require_size_sensor_count = false any count from 1 to 162 is written as given.
TEST(WireFormat, LooseCountAcceptsOneTo162) {
  WireSettings settings;
  settings.require_size_sensor_count = false;
  const WireFormat loose(settings);
  SensorFrame frame;
  frame.size = InsoleSize::S37_38;
  for (std::uint16_t count : {std::uint16_t{1}, std::uint16_t{162}}) {
    frame.sensor_count = count;
    const Bytes bytes = encode(loose, frame);
    EXPECT_EQ(bytes.size(), 2U + 12U + count + 2U);
    EXPECT_EQ(bytes[5], count & 0xFF);
  }
  Bytes out(kMaxFrameBytes);
  frame.sensor_count = 163;
  EXPECT_THAT(invalid_argument_message([&] { encode_frame(loose, frame, out); }),
              HasSubstr("1 to 162, got 163"));
}

TEST(WireFormat, WritesNothingPastTheFrame) {
  Bytes out(200, 0xEE);
  EXPECT_EQ(encode_frame(WireFormat(), protocol_vector_frame(), out), 109U);
  for (std::size_t i = 109; i < out.size(); ++i) EXPECT_EQ(out[i], 0xEE) << i;
}

TEST(WireFormat, RefusesBadInput) {
  WireSettings settings;
  settings.sync = {};
  EXPECT_THROW(WireFormat{settings}, std::invalid_argument);
  settings.sync = {1, 2, 3, 4, 5};
  EXPECT_THROW(WireFormat{settings}, std::invalid_argument);

  SensorFrame frame;
  frame.size = InsoleSize::S37_38;
  frame.sensor_count = 107;
  Bytes small(50);
  EXPECT_THROW(encode_frame(WireFormat(), frame, small), std::invalid_argument);
  Bytes big(kMaxFrameBytes);
  frame.sensor_count = 106;
  EXPECT_THROW(encode_frame(WireFormat(), frame, big), std::invalid_argument);
  frame.sensor_count = 0;
  EXPECT_THROW(encode_frame(WireFormat(), frame, big), std::invalid_argument);
}

TEST(WireFormat, RefusalsNameTheReason) {
  WireSettings settings;
  settings.sync = {};
  EXPECT_THAT(invalid_argument_message([&] { WireFormat{settings}; }),
              HasSubstr("1 to 4 bytes, got 0"));
  settings.sync = {1, 2, 3, 4, 5};
  EXPECT_THAT(invalid_argument_message([&] { WireFormat{settings}; }),
              HasSubstr("1 to 4 bytes, got 5"));

  SensorFrame frame;
  frame.size = InsoleSize::S37_38;
  frame.sensor_count = 107;
  Bytes small(122);
  EXPECT_THAT(invalid_argument_message([&] { encode_frame(WireFormat(), frame, small); }),
              HasSubstr("holds 122 bytes, the frame needs 123"));
  Bytes big(kMaxFrameBytes);
  frame.sensor_count = 106;
  EXPECT_THAT(invalid_argument_message([&] { encode_frame(WireFormat(), frame, big); }),
              HasSubstr("sensor_count 106 does not match insole size 37-38"));
  frame.sensor_count = 0;
  EXPECT_THAT(invalid_argument_message([&] { encode_frame(WireFormat(), frame, big); }),
              HasSubstr("1 to 162, got 0"));
}

}  // namespace
}  // namespace gaitmon::drivers
