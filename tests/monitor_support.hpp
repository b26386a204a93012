// Helpers for tests and benchmarks of the live monitor: a Publisher that records in memory and
// the frames of a session file as a driver would deliver them. Free of any test framework.
#pragma once

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <vector>

#include "gaitmon/publisher.hpp"
#include "gaitmon/sensor_frame.hpp"
#include "gaitmon/session.hpp"

namespace gaitmon::test {

/// Keeps every message. Thread-safe, as Publisher requires.
class RecordingPublisher : public Publisher {
 public:
  enum class Kind { Frame, Step, Fit, Status, Raw, Effects, Tissue };

  void publish(const FrameReport& r) override { add(frames_, r, Kind::Frame); }
  void publish(const StepEvent& r) override { add(events_, r, Kind::Step); }
  void publish(const FitReport& r) override { add(fits_, r, Kind::Fit); }
  void publish(const StatusReport& r) override { add(statuses_, r, Kind::Status); }
  void publish(const RawFrameReport& r) override { add(raws_, r, Kind::Raw); }
  void publish(const EffectsReport& r) override { add(effects_, r, Kind::Effects); }
  void publish(const TissueReport& r) override { add(tissues_, r, Kind::Tissue); }

  std::vector<FrameReport> frames() const { return copy(frames_); }
  std::vector<StepEvent> events() const { return copy(events_); }
  std::vector<FitReport> fits() const { return copy(fits_); }
  std::vector<StatusReport> statuses() const { return copy(statuses_); }
  std::vector<RawFrameReport> raws() const { return copy(raws_); }
  std::vector<EffectsReport> effects() const { return copy(effects_); }
  std::vector<TissueReport> tissues() const { return copy(tissues_); }
  /// The kinds in publication order.
  std::vector<Kind> order() const { return copy(order_); }

 private:
  template <typename T>
  void add(std::vector<T>& into, const T& r, Kind kind) {
    const std::lock_guard lock(mutex_);
    into.push_back(r);
    order_.push_back(kind);
  }
  template <typename T>
  std::vector<T> copy(const std::vector<T>& from) const {
    const std::lock_guard lock(mutex_);
    return from;
  }

  mutable std::mutex mutex_;
  std::vector<FrameReport> frames_;
  std::vector<StepEvent> events_;
  std::vector<FitReport> fits_;
  std::vector<StatusReport> statuses_;
  std::vector<RawFrameReport> raws_;
  std::vector<EffectsReport> effects_;
  std::vector<TissueReport> tissues_;
  std::vector<Kind> order_;
};

/// A session frame as the drivers deliver it: device_time_us = round(t_s x 1e6), a per-foot
/// sequence counter, the host clock unset.
inline SensorFrame sensor_frame(const Frame& frame, InsoleSize size, std::uint32_t sequence) {
  SensorFrame out;
  out.foot = frame.foot;
  out.size = size;
  out.sensor_count = static_cast<std::uint16_t>(frame.bits.size());
  out.sequence = sequence;
  out.device_time_us = static_cast<std::uint32_t>(std::llround(frame.t_s * 1e6));
  for (std::size_t i = 0; i < frame.bits.size(); ++i) out.bits[i] = frame.bits[i];
  return out;
}

/// Every frame of a session file in file order.
inline std::vector<SensorFrame> session_frames(const std::filesystem::path& path,
                                               SessionHeader* header = nullptr) {
  SessionReader reader(path);
  if (header != nullptr) *header = reader.header();
  std::vector<SensorFrame> out;
  std::uint32_t sequence[2] = {0, 0};
  Frame frame;
  while (reader.next(frame)) {
    out.push_back(sensor_frame(frame, reader.header().insole_size,
                               sequence[static_cast<std::size_t>(frame.foot)]++));
  }
  return out;
}

/// Every frame of a session file as the file has it.
inline std::vector<Frame> file_frames(const std::filesystem::path& path,
                                      SessionHeader* header = nullptr) {
  SessionReader reader(path);
  if (header != nullptr) *header = reader.header();
  std::vector<Frame> frames;
  Frame frame;
  while (reader.next(frame)) frames.push_back(frame);
  return frames;
}

/// Writes the frames of `from` with t_s < until_s to `to`; returns `to`.
inline std::filesystem::path cut_session(const std::filesystem::path& from,
                                         const std::filesystem::path& to, double until_s) {
  SessionReader reader(from);
  SessionWriter writer(to, reader.header());
  Frame frame;
  while (reader.next(frame) && frame.t_s < until_s) writer.write(frame);
  writer.close();
  return to;
}

}  // namespace gaitmon::test
