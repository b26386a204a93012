// Turns the byte stream of an insole link into SensorFrames (drivers/PROTOCOL.md), surviving
// garbage, corrupted and truncated frames, and counting every fault.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <type_traits>

#include "drivers/wire_format.hpp"
#include "gaitmon/sensor_frame.hpp"

namespace gaitmon::drivers {

/// A snapshot of the decoder's counters. Every byte fed is either part of a decoded frame,
/// counted in garbage_bytes, or still held for an incomplete frame.
struct DecoderCounters {
  std::uint64_t bytes = 0;             ///< bytes fed
  std::uint64_t frames = 0;            ///< frames decoded and delivered
  std::uint64_t crc_errors = 0;        ///< complete frames whose CRC did not match
  std::uint64_t truncated_frames = 0;  ///< frames cut short: the next frame starts inside them
  std::uint64_t header_errors = 0;     ///< sync patterns followed by an impossible header
  std::uint64_t resyncs = 0;           ///< times the decoder lost alignment and scanned for sync
  std::uint64_t garbage_bytes = 0;     ///< bytes skipped outside decoded frames
  std::array<std::uint64_t, 2> lost_frames{};  ///< per foot (index_of Foot): sequence gaps
  std::uint64_t sequence_restarts = 0;         ///< a sequence went backwards (device restart)

  std::uint64_t lost_frames_total() const { return lost_frames[0] + lost_frames[1]; }
};

/// Decodes one link's byte stream. Not thread-safe except counters(): one thread (the driver
/// thread) feeds, any thread may read the counters. Allocates nothing after construction.
class FrameDecoder {
 public:
  explicit FrameDecoder(const WireFormat& format = WireFormat());
  ~FrameDecoder();
  FrameDecoder(const FrameDecoder&) = delete;
  FrameDecoder& operator=(const FrameDecoder&) = delete;

  /// Decodes `bytes`, which continue the bytes of the previous call, calling
  /// sink(const SensorFrame&) for every complete, valid frame. The frame passed is only valid
  /// during the call. host_time_ns is std::chrono::steady_clock at this call, the same for
  /// every frame of one call. Bytes of a frame that is not complete yet are kept for the next
  /// call.
  template <typename Sink>
  void feed(std::span<const std::uint8_t> bytes, Sink&& sink) {
    using Target = std::remove_reference_t<Sink>;
    feed_impl(bytes, SinkRef{const_cast<void*>(static_cast<const void*>(std::addressof(sink))),
                             [](void* target, const SensorFrame& frame) {
                               (*static_cast<Target*>(target))(frame);
                             }});
  }

  /// The link dropped or the stream ended: a held incomplete frame is counted as truncated
  /// (garbage if it never had a valid header) and discarded. The sequence counters are kept,
  /// so frames the device sent while the link was down count as lost once it is back.
  void reset();

  /// The counters so far; safe from any thread (each value is read atomically, the set is
  /// not one instant).
  DecoderCounters counters() const;

 private:
  struct SinkRef {
    void* target;
    void (*call)(void*, const SensorFrame&);
  };
  enum class Failure : std::uint8_t { None, Crc };

  void feed_impl(std::span<const std::uint8_t> bytes, SinkRef sink);
  std::size_t process(const std::uint8_t* data, std::size_t size, std::uint64_t base, SinkRef sink);
  std::size_t find_sync(const std::uint8_t* data, std::size_t size, std::size_t from) const;
  bool header_valid(const std::uint8_t* header) const;
  void skip(std::size_t count, std::uint64_t end_offset);
  void resolve_failure(std::uint64_t next_frame_offset);
  void deliver(const std::uint8_t* header, SinkRef sink);

  WireFormat format_;
  std::size_t sync_bytes_;
  std::size_t crc_bytes_;
  std::array<std::uint8_t, kMaxFrameBytes> held_{};  ///< an incomplete frame across calls
  std::size_t held_size_ = 0;
  std::size_t need_ = 0;  ///< bytes the held candidate needs before it can be judged
  std::uint64_t fed_ = 0;
  bool in_sync_ = true;
  Failure failure_ = Failure::None;  ///< a rejected frame not yet classified
  std::uint64_t failure_end_ = 0;    ///< stream offset where that frame claimed to end
  std::array<std::uint32_t, 2> next_sequence_{};
  std::array<bool, 2> seen_foot_{};
  std::int64_t call_time_ns_ = 0;
  SensorFrame frame_;

  struct Atomics {
    std::atomic<std::uint64_t> bytes{0}, frames{0}, crc_errors{0}, truncated_frames{0},
        header_errors{0}, resyncs{0}, garbage_bytes{0}, sequence_restarts{0};
    std::array<std::atomic<std::uint64_t>, 2> lost_frames{};
  } counters_;
};

}  // namespace gaitmon::drivers
