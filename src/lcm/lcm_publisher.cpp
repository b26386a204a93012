// LcmPublisher: encodes into per-thread buffers (lcm::LCM::publish would allocate one per
// message) and hands the bytes to LCM's C API under a mutex: not every provider serialises its
// sends (file:// interleaves concurrent writes and corrupts the log).
#include "gaitmon/lcm_publisher.hpp"

#include <spdlog/spdlog.h>

#include <lcm/lcm-cpp.hpp>
#include <mutex>
#include <stdexcept>
#include <utility>
#include <vector>

#include "gaitmon/lcm_connection.hpp"
#include "lcm_messages.hpp"

namespace gaitmon {

LcmPublisher::LcmPublisher(const LcmSettings& settings)
    : LcmPublisher(open_lcm(settings.url), settings) {}

LcmPublisher::LcmPublisher(std::shared_ptr<lcm::LCM> lcm, const LcmSettings& settings)
    : lcm_(std::move(lcm)), settings_(settings) {
  if (!lcm_) throw std::invalid_argument("LcmPublisher: no LCM connection");
}

LcmPublisher::~LcmPublisher() = default;

template <typename Report, typename Message>
void LcmPublisher::send(const std::string& channel, const Report& report,
                        Message& message) noexcept {
  thread_local std::vector<std::uint8_t> buffer;
  const char* failure = nullptr;
  try {
    lcm_messages::to_lcm(report, message);
    const int size = message.getEncodedSize();
    if (buffer.size() < static_cast<std::size_t>(size)) {
      buffer.resize(static_cast<std::size_t>(size));
    }
    if (message.encode(buffer.data(), 0, size) != size) {
      failure = "it could not be encoded";
    } else {
      const std::lock_guard lock(send_mutex_);
      if (lcm_publish(lcm_->getUnderlyingLCM(), channel.c_str(), buffer.data(), size) != 0) {
        failure = "LCM did not send it";
      }
    }
  } catch (const std::bad_alloc&) {
    failure = "out of memory";
  }
  if (failure != nullptr) {
    const std::uint64_t failed = failed_.fetch_add(1, std::memory_order_relaxed) + 1;
    if (auto held = failure_log_.allow()) {
      spdlog::warn("LCM: a message on {} was lost: {}; {} lost so far ({} similar suppressed)",
                   channel, failure, failed, *held);
    }
    return;
  }
  published_.fetch_add(1, std::memory_order_relaxed);
}

// One message object per thread and type, so that its strings and vectors keep their storage.
void LcmPublisher::publish(const FrameReport& report) {
  thread_local frame_t message;
  send(settings_.channels.frame, report, message);
}

void LcmPublisher::publish(const StepEvent& event) {
  thread_local step_t message;
  send(settings_.channels.step, event, message);
}

void LcmPublisher::publish(const FitReport& report) {
  thread_local fit_t message;
  send(settings_.channels.fit, report, message);
}

void LcmPublisher::publish(const StatusReport& report) {
  thread_local status_t message;
  send(settings_.channels.status, report, message);
}

void LcmPublisher::publish(const RawFrameReport& report) {
  if (!settings_.raw_enabled) return;
  thread_local raw_t message;
  send(settings_.channels.raw, report, message);
}

void LcmPublisher::publish(const EffectsReport& report) {
  thread_local effects_t message;
  send(settings_.channels.effects, report, message);
}

void LcmPublisher::publish(const TissueReport& report) {
  thread_local tissue_t message;
  send(settings_.channels.tissue, report, message);
}

}  // namespace gaitmon
