// Session playback in the wire format. At full speed frames are batched into 64 KiB deliveries
// so the consumer is not called once per 123 bytes; when paced, each frame goes out when due.
#include "replay/session_byte_source.hpp"

#include <cmath>
#include <stdexcept>

namespace gaitmon::replay {

SessionEncoder::SessionEncoder(const drivers::WireFormat& format, InsoleSize size)
    : format_(format) {
  frame_.size = size;
  frame_.sensor_count = static_cast<std::uint16_t>(session_sensor_count(size));
}

const SensorFrame& SessionEncoder::next(const Frame& frame) {
  if (frame.bits.size() != frame_.sensor_count) {
    throw std::invalid_argument("SessionEncoder: a frame with the wrong sensor count");
  }
  const auto foot = static_cast<std::size_t>(frame.foot);
  frame_.foot = frame.foot;
  frame_.sequence = next_sequence_[foot]++;
  frame_.device_time_us =
      static_cast<std::uint32_t>(static_cast<std::uint64_t>(std::llround(frame.t_s * 1e6)));
  std::copy(frame.bits.begin(), frame.bits.end(), frame_.bits.begin());
  return frame_;
}

void SessionEncoder::append_wire(std::vector<std::uint8_t>& out) const {
  const std::size_t at = out.size();
  out.resize(at + format_.frame_bytes(frame_.sensor_count));
  drivers::encode_frame(format_, frame_, std::span(out).subspan(at));
}

SessionByteSource::SessionByteSource(const std::filesystem::path& session,
                                     const drivers::WireFormat& format, double speed)
    : format_(format), speed_(speed) {
  if (!(speed > 0.0)) throw std::invalid_argument("SessionByteSource: speed must be > 0");
  check_whole_session(session);
  reader_ = std::make_unique<SessionReader>(session);
}

SessionByteSource::~SessionByteSource() = default;

const SessionHeader& SessionByteSource::header() const {
  return reader_->header();
}

void SessionByteSource::run(const BytesHandler& on_bytes, const StateHandler& on_state) {
  if (stopping_.load()) return;
  const std::string name = reader_->path().string();
  on_state(drivers::LinkState::Connecting, name);
  on_state(drivers::LinkState::Connected, name);
  constexpr std::size_t kBatchBytes = 64 * 1024;
  SessionEncoder encoder(format_, reader_->header().insole_size);
  Pacer pacer(speed_, stopping_);
  std::vector<std::uint8_t> batch;
  batch.reserve(kBatchBytes + drivers::kMaxFrameBytes);
  std::uint64_t batched = 0;
  const auto flush = [&] {
    if (batch.empty()) return;
    on_bytes(batch);
    frames_sent_.fetch_add(batched, std::memory_order_relaxed);
    batch.clear();
    batched = 0;
  };
  Frame frame;
  bool stopped = false;
  while (reader_->next(frame)) {
    if (!pacer.due(frame.t_s)) {
      flush();
      if (!pacer.wait(frame.t_s)) {
        stopped = true;
        break;
      }
    }
    if (stopping_.load()) {
      stopped = true;
      break;
    }
    encoder.next(frame);
    encoder.append_wire(batch);
    ++batched;
    if (batch.size() >= kBatchBytes || !std::isinf(speed_)) flush();
  }
  flush();
  on_state(drivers::LinkState::Disconnected, stopped ? "stopped" : "end of session");
}

void SessionByteSource::stop() {
  stopping_.store(true);
}

}  // namespace gaitmon::replay
