// The fake device: a session CSV v1 played back in the wire format, as a ByteSource (the
// in-process fake driver) and as the encoder behind `gaitmon fake-insole`.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include "drivers/byte_source.hpp"
#include "drivers/wire_format.hpp"
#include "gaitmon/sensor_frame.hpp"
#include "gaitmon/session.hpp"
#include "replay/pacer.hpp"

namespace gaitmon::replay {

/// Session frames as a device would send them: each foot's frames numbered from 0 in file
/// order, device time = round(t_s x 10^6) microseconds modulo 2^32 (drivers/PROTOCOL.md).
class SessionEncoder {
 public:
  SessionEncoder(const drivers::WireFormat& format, InsoleSize size);

  /// The SensorFrame for `frame` (host_time_ns 0), advancing its foot's sequence.
  const SensorFrame& next(const Frame& frame);
  /// Appends the wire bytes of the frame last returned by next() to `out`.
  void append_wire(std::vector<std::uint8_t>& out) const;

 private:
  drivers::WireFormat format_;
  SensorFrame frame_;
  std::array<std::uint32_t, 2> next_sequence_{};
};

/// Checks a whole session CSV v1 first, then reads it again as it plays (one frame in memory at a
/// time) and delivers its frames in the wire format at real time x speed, or as fast as possible
/// (kMaxSpeed), never skipping one. States: Connecting, Connected, then Disconnected ("end of
/// session" or "stopped").
///
/// Threading: run() on one thread, once per object; stop() and frames_sent() from any thread.
class SessionByteSource final : public drivers::ByteSource {
 public:
  /// Reads the whole session once: throws InputError for a bad line or a file without frames,
  /// before anything is played, and warns of a header rate the times disagree with
  /// (warn_on_rate_mismatch). speed > 0.
  SessionByteSource(const std::filesystem::path& session, const drivers::WireFormat& format,
                    double speed);
  ~SessionByteSource() override;

  /// Returns at the end of the session or soon after stop(). Throws InputError (on the
  /// calling thread) for a bad line of a file changed since the check; the frames before it
  /// have been delivered.
  void run(const BytesHandler& on_bytes, const StateHandler& on_state) override;
  void stop() override;

  const SessionHeader& header() const;
  /// Frames delivered so far.
  std::uint64_t frames_sent() const { return frames_sent_.load(std::memory_order_relaxed); }

 private:
  std::unique_ptr<SessionReader> reader_;
  drivers::WireFormat format_;
  double speed_;
  std::atomic<bool> stopping_{false};
  std::atomic<std::uint64_t> frames_sent_{0};
};

}  // namespace gaitmon::replay
