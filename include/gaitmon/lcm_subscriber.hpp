// Receives the gaitmon LCM channels and decodes each message back into its Publisher struct: the
// other end of LcmPublisher, for `gaitmon spy`, tests and C++ clients.
#pragma once

#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/log_throttle.hpp"
#include "gaitmon/publisher.hpp"

namespace lcm {
class LCM;
class Subscription;
}  // namespace lcm

namespace gaitmon {

/// One decoded message; the alternative tells its type.
using LcmMessage = std::variant<FrameReport, StepEvent, FitReport, StatusReport, RawFrameReport,
                                EffectsReport, TissueReport>;

/// Thread safety: construct it, then call handle() from one thread at a time; the handler runs
/// on that thread, inside handle().
class LcmSubscriber {
 public:
  using Handler = std::function<void(const std::string& channel, const LcmMessage& message)>;

  /// Subscribes on its own connection to settings.url. `channels` are names among
  /// settings.channels (each decoded as that channel's type); empty means all seven.
  /// @throw LcmError for a URL LCM cannot open or a channel settings does not name.
  LcmSubscriber(const LcmSettings& settings, const std::vector<std::string>& channels,
                Handler handler);
  /// The same on a connection the caller shares (e.g. memq:// with an LcmPublisher).
  LcmSubscriber(std::shared_ptr<lcm::LCM> lcm, const LcmSettings& settings,
                const std::vector<std::string>& channels, Handler handler);
  ~LcmSubscriber();
  LcmSubscriber(const LcmSubscriber&) = delete;
  LcmSubscriber& operator=(const LcmSubscriber&) = delete;

  /// Waits up to timeout_ms for a message and dispatches it to the handler. Returns whether one
  /// arrived. An exception from the handler is held until LCM's C code is off the stack, then
  /// rethrown here.
  /// @throw LcmError if LCM reports an error while waiting.
  bool handle(int timeout_ms);

  /// Messages on a subscribed channel that were not the expected type, were malformed or held
  /// impossible values (a foot other than 0 or 1, ...); they are skipped and logged (at most
  /// once a second).
  std::uint64_t decode_errors() const noexcept { return decode_errors_; }

 private:
  struct Route;
  void dispatch(const Route& route, const void* data, std::uint32_t size);

  std::shared_ptr<lcm::LCM> lcm_;
  Handler handler_;
  std::vector<std::unique_ptr<Route>> routes_;
  std::uint64_t decode_errors_ = 0;
  LogThrottle decode_log_;
  std::exception_ptr pending_;
};

}  // namespace gaitmon
