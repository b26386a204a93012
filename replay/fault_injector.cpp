// Fault drawing with explicit arithmetic on the generator's output (not std distributions, whose
// results differ between standard libraries), so a seed means the same faults everywhere.
#include "replay/fault_injector.hpp"

#include <stdexcept>

namespace gaitmon::replay {

FaultInjector::FaultInjector(const FaultOptions& options, const drivers::WireFormat& format)
    : options_(options),
      sync0_(format.sync()[0]),
      prefix_bytes_(format.sync().size() + drivers::kWireHeaderBytes),
      rng_(options.seed) {
  for (double rate : {options.garbage_rate, options.crc_rate, options.truncate_rate}) {
    if (!(rate >= 0.0 && rate <= 1.0)) {
      throw std::invalid_argument("fault rates must be in [0, 1]");
    }
  }
  if (options.crc_rate + options.truncate_rate > 1.0) {
    throw std::invalid_argument("the CRC and truncation rates must add up to at most 1");
  }
  if (options.garbage_max_bytes == 0) {
    throw std::invalid_argument("garbage bursts need at least 1 byte");
  }
  if (options.crc_rate > 0.0 && format.crc() == CrcKind::None) {
    throw std::invalid_argument("CRC corruption needs a wire format with a CRC");
  }
}

double FaultInjector::uniform() {
  return static_cast<double>(rng_() >> 11) * 0x1.0p-53;
}

std::size_t FaultInjector::below(std::size_t n) {
  return static_cast<std::size_t>(rng_() % n);
}

void FaultInjector::append(std::span<const std::uint8_t> wire, Foot foot, std::uint32_t sequence,
                           std::vector<std::uint8_t>& out) {
  ++counts_.frames;
  if (!last_truncated_ && uniform() < options_.garbage_rate) {
    const std::size_t n = 1 + below(options_.garbage_max_bytes);
    for (std::size_t i = 0; i < n; ++i) {
      auto byte = static_cast<std::uint8_t>(below(255));
      if (byte >= sync0_) ++byte;  // 255 values, skipping sync0
      out.push_back(byte);
    }
    ++counts_.garbage_bursts;
    counts_.garbage_bytes += n;
  }
  const std::size_t at = out.size();
  out.insert(out.end(), wire.begin(), wire.end());
  const double fault = uniform();
  const std::size_t tail = wire.size() - prefix_bytes_;  // sensor bytes and CRC
  last_truncated_ = false;
  if (fault < options_.crc_rate) {
    out[at + prefix_bytes_ + below(tail)] ^= static_cast<std::uint8_t>(1U << below(8));
    ++counts_.crc_corrupted;
  } else if (fault < options_.crc_rate + options_.truncate_rate) {
    const std::size_t drop = 1 + below(tail);
    out.resize(out.size() - drop);
    ++counts_.truncated;
    counts_.dropped_bytes += drop;
    last_truncated_ = true;
  } else {
    return;
  }
  counts_.faulted_sequences[static_cast<std::size_t>(foot)].push_back(sequence);
}

}  // namespace gaitmon::replay
