// Opening an LCM connection, shared by the publisher and the subscriber so that memq:// tests can
// put both on one in-process bus.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>

namespace lcm {
class LCM;
}

namespace gaitmon {

/// LCM refused a URL or a subscription: set-up errors only, never raised while publishing.
class LcmError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Opens `url` (udpm://, memq://, file://, ...). lcm::LCM is internally synchronised, so one
/// connection may be shared by any number of threads.
/// @throw LcmError naming the URL when LCM cannot open it.
std::shared_ptr<lcm::LCM> open_lcm(const std::string& url);

}  // namespace gaitmon
