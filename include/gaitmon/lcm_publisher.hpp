// The Publisher that the live monitor uses: every report becomes its LCM message type
// (include/gaitmon/lcm/*.lcm, package gaitmon) on the channel that LcmSettings names.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>

#include "gaitmon/config.hpp"
#include "gaitmon/log_throttle.hpp"
#include "gaitmon/publisher.hpp"

namespace lcm {
class LCM;
}

namespace gaitmon {

/// Maps FrameReport -> frame_t, StepEvent -> step_t, FitReport -> fit_t, StatusReport -> status_t,
/// EffectsReport -> effects_t, TissueReport -> tissue_t and RawFrameReport -> raw_t (dropped unless
/// settings.raw_enabled).
/// Fields are copied as given, utime included; feet become 0 = left, 1 = right.
///
/// Thread safety: the publish functions may be called from any number of threads at once; each
/// thread encodes into its own buffer, and a mutex serialises the sends.
///
/// Failures: a message LCM does not send (a full socket buffer, no route) is counted in
/// failed_publishes() and logged (at most once a second), and otherwise ignored, so the publish
/// functions never throw and never block longer than the send itself. LcmPublisher itself allocates
/// nothing per message once a thread has published each type once.
class LcmPublisher final : public Publisher {
 public:
  /// Opens its own connection on settings.url.
  /// @throw LcmError naming the URL when LCM cannot open it.
  explicit LcmPublisher(const LcmSettings& settings);
  /// Publishes on a connection that the caller shares (e.g. memq:// with an in-process
  /// subscriber). @throw std::invalid_argument if lcm is null.
  LcmPublisher(std::shared_ptr<lcm::LCM> lcm, const LcmSettings& settings);
  ~LcmPublisher() override;
  LcmPublisher(const LcmPublisher&) = delete;
  LcmPublisher& operator=(const LcmPublisher&) = delete;

  void publish(const FrameReport& report) override;
  void publish(const StepEvent& event) override;
  void publish(const FitReport& report) override;
  void publish(const StatusReport& report) override;
  void publish(const RawFrameReport& report) override;
  void publish(const EffectsReport& report) override;
  void publish(const TissueReport& report) override;

  /// Messages handed to LCM and accepted, since construction.
  std::uint64_t published() const noexcept { return published_.load(std::memory_order_relaxed); }
  /// Messages that could not be encoded or sent, since construction.
  std::uint64_t failed_publishes() const noexcept {
    return failed_.load(std::memory_order_relaxed);
  }

 private:
  template <typename Report, typename Message>
  void send(const std::string& channel, const Report& report, Message& message) noexcept;

  std::shared_ptr<lcm::LCM> lcm_;
  LcmSettings settings_;
  std::mutex send_mutex_;
  std::atomic<std::uint64_t> published_{0};
  std::atomic<std::uint64_t> failed_{0};
  LogThrottle failure_log_;
};

}  // namespace gaitmon
