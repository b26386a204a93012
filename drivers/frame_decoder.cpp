// The frame decoder's state machine: scan for sync, judge the header, wait for the whole frame,
// check the CRC; on any failure resume one byte after the rejected sync.
#include "drivers/frame_decoder.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>

#include "gaitmon/types.hpp"

namespace gaitmon::drivers {
namespace {

// Only the decoder thread writes, so a load and a store are enough (no read-modify-write).
void bump(std::atomic<std::uint64_t>& counter, std::uint64_t by = 1) {
  counter.store(counter.load(std::memory_order_relaxed) + by, std::memory_order_relaxed);
}

std::uint32_t get_u32_le(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

// The session format's sensor count per insole size, looked up once.
const std::array<std::uint8_t, kInsoleSizeCount> kSizeSensorCounts = [] {
  std::array<std::uint8_t, kInsoleSizeCount> counts{};
  for (InsoleSize size : kInsoleSizes) {
    counts[index_of(size)] = static_cast<std::uint8_t>(session_sensor_count(size));
  }
  return counts;
}();

}  // namespace

FrameDecoder::FrameDecoder(const WireFormat& format)
    : format_(format), sync_bytes_(format.sync().size()), crc_bytes_(format.crc_bytes()) {}

FrameDecoder::~FrameDecoder() = default;

DecoderCounters FrameDecoder::counters() const {
  const auto get = [](const std::atomic<std::uint64_t>& c) {
    return c.load(std::memory_order_relaxed);
  };
  DecoderCounters out;
  out.bytes = get(counters_.bytes);
  out.frames = get(counters_.frames);
  out.crc_errors = get(counters_.crc_errors);
  out.truncated_frames = get(counters_.truncated_frames);
  out.header_errors = get(counters_.header_errors);
  out.resyncs = get(counters_.resyncs);
  out.garbage_bytes = get(counters_.garbage_bytes);
  out.lost_frames = {get(counters_.lost_frames[0]), get(counters_.lost_frames[1])};
  out.sequence_restarts = get(counters_.sequence_restarts);
  return out;
}

void FrameDecoder::reset() {
  if (held_size_ >= sync_bytes_ + kWireHeaderBytes && header_valid(held_.data() + sync_bytes_)) {
    resolve_failure(fed_ - held_size_);
    bump(counters_.truncated_frames);
    bump(counters_.garbage_bytes, held_size_);
    if (in_sync_) bump(counters_.resyncs);
    in_sync_ = false;
  } else if (held_size_ > 0) {
    skip(held_size_, fed_);
  }
  resolve_failure(fed_);
  held_size_ = 0;
  need_ = 0;
}

void FrameDecoder::feed_impl(std::span<const std::uint8_t> bytes, SinkRef sink) {
  bump(counters_.bytes, bytes.size());
  call_time_ns_ = 0;
  const std::uint64_t start = fed_;
  fed_ += bytes.size();
  std::size_t used = 0;
  // Complete the held candidate with just the bytes it needs, so that the rest of the input is
  // decoded in place without copying.
  while (held_size_ > 0 && used < bytes.size()) {
    const std::size_t take = std::min(need_ - held_size_, bytes.size() - used);
    std::memcpy(held_.data() + held_size_, bytes.data() + used, take);
    held_size_ += take;
    used += take;
    if (held_size_ < need_) return;
    const std::uint64_t held_offset = start + used - held_size_;
    const std::size_t consumed = process(held_.data(), held_size_, held_offset, sink);
    std::memmove(held_.data(), held_.data() + consumed, held_size_ - consumed);
    held_size_ -= consumed;
  }
  if (used == bytes.size()) return;
  const std::size_t consumed =
      process(bytes.data() + used, bytes.size() - used, start + used, sink);
  held_size_ = bytes.size() - used - consumed;
  std::memcpy(held_.data(), bytes.data() + used + consumed, held_size_);
}

std::size_t FrameDecoder::find_sync(const std::uint8_t* data, std::size_t size,
                                    std::size_t from) const {
  const std::uint8_t* sync = format_.sync().data();
  while (from < size) {
    const void* hit = std::memchr(data + from, sync[0], size - from);
    if (hit == nullptr) return size;
    const std::size_t at = static_cast<std::size_t>(static_cast<const std::uint8_t*>(hit) - data);
    const std::size_t available = std::min(sync_bytes_, size - at);
    if (std::memcmp(data + at, sync, available) == 0) return at;  // whole, or a prefix at the end
    from = at + 1;
  }
  return size;
}

bool FrameDecoder::header_valid(const std::uint8_t* header) const {
  const std::uint8_t version = header[0];
  const std::uint8_t foot = header[1];
  const std::uint8_t size = header[2];
  const std::uint8_t count = header[3];
  if (version != kWireVersion || foot > 1 || size >= kInsoleSizeCount) return false;
  if (format_.require_size_sensor_count()) return count == kSizeSensorCounts[size];
  return count >= 1 && count <= SensorFrame::kMaxSensors;
}

void FrameDecoder::skip(std::size_t count, std::uint64_t end_offset) {
  if (count == 0) return;
  bump(counters_.garbage_bytes, count);
  if (in_sync_) bump(counters_.resyncs);
  in_sync_ = false;
  if (failure_ != Failure::None && end_offset >= failure_end_) resolve_failure(end_offset);
}

// A rejected frame is a truncation when a valid frame header starts inside the span it claimed
// (the bytes it lacked were taken from its successor); otherwise its CRC was wrong.
void FrameDecoder::resolve_failure(std::uint64_t next_frame_offset) {
  if (failure_ == Failure::None) return;
  bump(next_frame_offset < failure_end_ ? counters_.truncated_frames : counters_.crc_errors);
  failure_ = Failure::None;
}

std::size_t FrameDecoder::process(const std::uint8_t* data, std::size_t size, std::uint64_t base,
                                  SinkRef sink) {
  const std::size_t header_end = sync_bytes_ + kWireHeaderBytes;
  std::size_t pos = 0;
  for (;;) {
    const std::size_t at = find_sync(data, size, pos);
    skip(at - pos, base + at);
    pos = at;
    if (size - pos < header_end) {
      need_ = header_end;
      return pos;
    }
    const std::uint8_t* header = data + pos + sync_bytes_;
    if (!header_valid(header)) {
      bump(counters_.header_errors);
      skip(1, base + pos + 1);
      ++pos;
      continue;
    }
    resolve_failure(base + pos);
    const std::size_t frame_size = format_.frame_bytes(header[3]);
    if (size - pos < frame_size) {
      need_ = frame_size;
      return pos;
    }
    const std::size_t checked = kWireHeaderBytes + header[3];
    const std::uint8_t* crc_field = header + checked;
    std::uint32_t sent = 0;
    for (std::size_t i = 0; i < crc_bytes_; ++i) {
      const std::size_t shift = format_.crc_big_endian() ? crc_bytes_ - 1 - i : i;
      sent |= static_cast<std::uint32_t>(crc_field[i]) << (8 * shift);
    }
    if (sent != format_.checksum({header, checked})) {
      failure_ = Failure::Crc;
      failure_end_ = base + pos + frame_size;
      skip(1, base + pos + 1);
      ++pos;
      continue;
    }
    deliver(header, sink);
    in_sync_ = true;
    pos += frame_size;
  }
}

void FrameDecoder::deliver(const std::uint8_t* header, SinkRef sink) {
  const std::uint8_t foot = header[1];
  const std::uint8_t count = header[3];
  const std::uint32_t sequence = get_u32_le(header + 4);
  if (seen_foot_[foot]) {
    // Unsigned difference: a counter that wraps from 2^32-1 to 0 is no gap.
    const std::uint32_t gap = sequence - next_sequence_[foot];
    if (gap < 0x80000000U) {
      bump(counters_.lost_frames[foot], gap);
    } else {
      bump(counters_.sequence_restarts);
    }
  }
  seen_foot_[foot] = true;
  next_sequence_[foot] = sequence + 1;

  if (call_time_ns_ == 0) {
    call_time_ns_ = std::chrono::duration_cast<std::chrono::nanoseconds>(
                        std::chrono::steady_clock::now().time_since_epoch())
                        .count();
  }
  frame_.foot = static_cast<Foot>(foot);
  frame_.size = kInsoleSizes[header[2]];
  frame_.sensor_count = count;
  frame_.sequence = sequence;
  frame_.device_time_us = get_u32_le(header + 8);
  frame_.host_time_ns = call_time_ns_;
  std::memcpy(frame_.bits.data(), header + kWireHeaderBytes, count);
  std::fill(frame_.bits.begin() + count, frame_.bits.end(), std::uint8_t{0});
  bump(counters_.frames);
  sink.call(sink.target, frame_);
}

}  // namespace gaitmon::drivers
