// LcmSubscriber: raw subscriptions decoded here (not by lcm-cpp's typed handlers, which print
// decoding errors to stderr and hide them from the caller).
#include "gaitmon/lcm_subscriber.hpp"

#include <spdlog/spdlog.h>

#include <cctype>
#include <lcm/lcm-cpp.hpp>
#include <stdexcept>
#include <utility>

#include "gaitmon/lcm_connection.hpp"
#include "lcm_messages.hpp"

namespace gaitmon {

enum class MessageKind { Frame, Step, Fit, Status, Raw, Effects, Tissue };

struct LcmSubscriber::Route {
  LcmSubscriber* owner = nullptr;
  std::string channel;
  MessageKind kind = MessageKind::Frame;
  lcm::Subscription* subscription = nullptr;
};

namespace {

template <typename Message>
bool decode_into(const void* data, std::uint32_t size, LcmMessage& out) {
  Message message;
  if (message.decode(data, 0, static_cast<int>(size)) != static_cast<int>(size)) return false;
  auto report = lcm_messages::from_lcm(message);
  if (!report) return false;
  out = std::move(*report);
  return true;
}

bool decode(MessageKind kind, const void* data, std::uint32_t size, LcmMessage& out) {
  switch (kind) {
    case MessageKind::Frame:
      return decode_into<frame_t>(data, size, out);
    case MessageKind::Step:
      return decode_into<step_t>(data, size, out);
    case MessageKind::Fit:
      return decode_into<fit_t>(data, size, out);
    case MessageKind::Status:
      return decode_into<status_t>(data, size, out);
    case MessageKind::Raw:
      return decode_into<raw_t>(data, size, out);
    case MessageKind::Effects:
      return decode_into<effects_t>(data, size, out);
    case MessageKind::Tissue:
      return decode_into<tissue_t>(data, size, out);
  }
  return false;
}

// LCM takes channel names as regular expressions (anchored at both ends); gaitmon's are plain
// names, so a "." in one must not match any character.
std::string literal_pattern(const std::string& channel) {
  std::string pattern;
  for (char c : channel) {
    if (std::isalnum(static_cast<unsigned char>(c)) == 0 && c != '_') pattern += '\\';
    pattern += c;
  }
  return pattern;
}

}  // namespace

LcmSubscriber::LcmSubscriber(const LcmSettings& settings, const std::vector<std::string>& channels,
                             Handler handler)
    : LcmSubscriber(open_lcm(settings.url), settings, channels, std::move(handler)) {}

LcmSubscriber::LcmSubscriber(std::shared_ptr<lcm::LCM> lcm, const LcmSettings& settings,
                             const std::vector<std::string>& channels, Handler handler)
    : lcm_(std::move(lcm)), handler_(std::move(handler)) {
  if (!lcm_) throw std::invalid_argument("LcmSubscriber: no LCM connection");
  const std::pair<const std::string*, MessageKind> known[] = {
      {&settings.channels.frame, MessageKind::Frame},
      {&settings.channels.step, MessageKind::Step},
      {&settings.channels.fit, MessageKind::Fit},
      {&settings.channels.status, MessageKind::Status},
      {&settings.channels.raw, MessageKind::Raw},
      {&settings.channels.effects, MessageKind::Effects},
      {&settings.channels.tissue, MessageKind::Tissue}};
  std::vector<std::string> wanted = channels;
  if (wanted.empty()) {
    for (const auto& [name, kind] : known) wanted.push_back(*name);
  }
  for (const std::string& channel : wanted) {
    auto route = std::make_unique<Route>();
    route->owner = this;
    route->channel = channel;
    bool found = false;
    for (const auto& [name, kind] : known) {
      if (*name == channel) {
        route->kind = kind;
        found = true;
      }
    }
    if (!found) {
      throw LcmError("\"" + channel + "\" is not a gaitmon channel; the config names " +
                     settings.channels.frame + ", " + settings.channels.step + ", " +
                     settings.channels.fit + ", " + settings.channels.status + ", " +
                     settings.channels.raw + ", " + settings.channels.effects + " and " +
                     settings.channels.tissue);
    }
    route->subscription = lcm_->subscribeFunction(
        literal_pattern(channel),
        +[](const lcm::ReceiveBuffer* buffer, const std::string&, Route* target) {
          target->owner->dispatch(*target, buffer->data, buffer->data_size);
        },
        route.get());
    if (route->subscription == nullptr) throw LcmError("LCM cannot subscribe to " + channel);
    routes_.push_back(std::move(route));
  }
}

LcmSubscriber::~LcmSubscriber() {
  for (const auto& route : routes_) lcm_->unsubscribe(route->subscription);
}

void LcmSubscriber::dispatch(const Route& route, const void* data, std::uint32_t size) {
  if (pending_) return;
  LcmMessage message;
  bool ok = false;
  std::string thrown;
  // The generated decoders throw for some malformed messages (a negative array length makes
  // resize throw); an exception must not cross LCM's C callback.
  try {
    ok = decode(route.kind, data, size, message);
  } catch (const std::exception& e) {
    thrown = e.what();
  }
  if (!ok) {
    ++decode_errors_;
    if (auto held = decode_log_.allow()) {
      spdlog::warn("LCM: a malformed message on {} skipped: {}; {} so far ({} similar suppressed)",
                   route.channel,
                   thrown.empty() ? "another type, cut short or an impossible value" : thrown,
                   decode_errors_, *held);
    }
    return;
  }
  try {
    handler_(route.channel, message);
  } catch (...) {
    pending_ = std::current_exception();
  }
}

bool LcmSubscriber::handle(int timeout_ms) {
  const int result = lcm_->handleTimeout(timeout_ms);
  if (pending_) std::rethrow_exception(std::exchange(pending_, nullptr));
  if (result < 0) throw LcmError("LCM failed while waiting for messages");
  return result > 0;
}

}  // namespace gaitmon
