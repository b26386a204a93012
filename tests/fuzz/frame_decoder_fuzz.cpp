// libFuzzer target for the frame decoder. The first bytes choose the wire layout and how the
// stream is split; the decoder must never crash, must account for every byte, and must give
// the same frames and counters however the stream is split.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "drivers/frame_decoder.hpp"

namespace {

using gaitmon::SensorFrame;
using gaitmon::drivers::DecoderCounters;
using gaitmon::drivers::FrameDecoder;
using gaitmon::drivers::WireFormat;

void check(bool ok) {
  if (!ok) std::abort();
}

struct Outcome {
  std::uint64_t frames = 0;
  std::uint64_t frame_bytes = 0;
  std::uint64_t digest = 0;
};

// Counters of one decoder fed `stream` in the given piece sizes (cycled; empty = at once).
DecoderCounters decode(const WireFormat& format, std::span<const std::uint8_t> stream,
                       std::span<const std::uint8_t> pieces, Outcome& out) {
  FrameDecoder decoder(format);
  auto sink = [&](const SensorFrame& f) {
    check(f.sensor_count >= 1 && f.sensor_count <= SensorFrame::kMaxSensors);
    ++out.frames;
    out.frame_bytes += format.frame_bytes(f.sensor_count);
    out.digest = out.digest * 1000003U + f.sequence + f.device_time_us + f.bits[0] +
                 f.bits[f.sensor_count - 1] + static_cast<std::uint64_t>(f.foot);
  };
  std::size_t at = 0;
  for (std::size_t i = 0; at < stream.size(); ++i) {
    const std::size_t piece = pieces.empty() ? stream.size() : 1 + pieces[i % pieces.size()];
    const std::size_t n = piece < stream.size() - at ? piece : stream.size() - at;
    decoder.feed(stream.subspan(at, n), sink);
    at += n;
  }
  decoder.reset();
  return decoder.counters();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 4) return 0;
  const std::uint8_t layout = data[0];
  const std::size_t piece_count = data[1] % 8;
  if (size < 2 + piece_count) return 0;
  gaitmon::WireSettings settings;
  // Bit 0-1: sync length 1..4 (A5 5A C3 3C prefixes); bits 2-3: CRC kind; 4: byte order;
  // 5: sensor count fixed by size or not. Most inputs use the default layout.
  if ((layout & 0x80) != 0) {
    static constexpr std::uint8_t kSync[] = {0xA5, 0x5A, 0xC3, 0x3C};
    settings.sync.assign(kSync, kSync + 1 + (layout & 3));
    const int crc = (layout >> 2) & 3;
    settings.crc = crc == 1   ? gaitmon::CrcKind::Crc32
                   : crc == 2 ? gaitmon::CrcKind::None
                              : gaitmon::CrcKind::Crc16CcittFalse;
    settings.crc_big_endian = (layout & 0x10) != 0;
    settings.require_size_sensor_count = (layout & 0x20) == 0;
  }
  const WireFormat format(settings);
  const std::span<const std::uint8_t> pieces(data + 2, piece_count);
  const std::span<const std::uint8_t> stream(data + 2 + piece_count, size - 2 - piece_count);

  Outcome whole;
  Outcome split;
  const DecoderCounters a = decode(format, stream, {}, whole);
  const DecoderCounters b = decode(format, stream, pieces, split);
  // Every byte is in a decoded frame or counted as garbage once the held frame is reset.
  check(a.bytes == stream.size());
  check(a.bytes == whole.frame_bytes + a.garbage_bytes);
  check(a.frames == whole.frames);
  // Splitting the stream changes nothing.
  check(whole.frames == split.frames && whole.digest == split.digest);
  check(a.garbage_bytes == b.garbage_bytes && a.crc_errors == b.crc_errors &&
        a.truncated_frames == b.truncated_frames && a.header_errors == b.header_errors &&
        a.resyncs == b.resyncs && a.lost_frames == b.lost_frames &&
        a.sequence_restarts == b.sequence_restarts);
  return 0;
}
