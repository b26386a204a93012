// Deterministic link faults for tests of the decoder and drivers: garbage between frames,
// corrupted CRCs and truncated frames, chosen by a seeded generator.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "drivers/wire_format.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon::replay {

/// Per-frame probabilities in [0, 1]; crc_rate + truncate_rate <= 1.
struct FaultOptions {
  std::uint64_t seed = 1;
  double garbage_rate = 0.0;           ///< a burst of garbage before the frame
  std::size_t garbage_max_bytes = 64;  ///< bursts are 1..this many bytes
  double crc_rate = 0.0;               ///< one bit flipped in the sensor bytes or the CRC
  double truncate_rate = 0.0;          ///< the frame's last 1..N+C bytes dropped
};

/// What was injected, so that a test can compare it with the decoder's counters.
struct FaultCounts {
  std::uint64_t frames = 0;  ///< frames passed through, faulty or not
  std::uint64_t garbage_bursts = 0;
  std::uint64_t garbage_bytes = 0;
  std::uint64_t crc_corrupted = 0;
  std::uint64_t truncated = 0;
  std::uint64_t dropped_bytes = 0;
  /// Per foot (0 left, 1 right): the sequence numbers of the frames corrupted or truncated.
  std::array<std::vector<std::uint32_t>, 2> faulted_sequences;
};

/// Garbage never contains the first sync byte, so it cannot fake a frame start, and never
/// follows a truncated frame, so the decoder can tell a truncation (the next frame starts
/// inside the cut one) from a CRC error. Headers are never touched.
class FaultInjector {
 public:
  /// Throws std::invalid_argument for rates outside [0, 1], crc_rate + truncate_rate > 1,
  /// garbage_max_bytes of 0, or CRC corruption on a format without a CRC.
  FaultInjector(const FaultOptions& options, const drivers::WireFormat& format);

  /// Appends one encoded frame (`wire`, of the given foot and sequence) to `out`, with the
  /// faults drawn for it.
  void append(std::span<const std::uint8_t> wire, Foot foot, std::uint32_t sequence,
              std::vector<std::uint8_t>& out);

  const FaultCounts& counts() const { return counts_; }

 private:
  double uniform();
  std::size_t below(std::size_t n);

  FaultOptions options_;
  std::uint8_t sync0_;
  std::size_t prefix_bytes_;  ///< sync + header: never faulted
  std::mt19937_64 rng_;
  bool last_truncated_ = false;
  FaultCounts counts_;
};

}  // namespace gaitmon::replay
