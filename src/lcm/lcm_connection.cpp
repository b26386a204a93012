// open_lcm: one place that turns LCM's silent failure (a null lcm_t) into an exception.
#include "gaitmon/lcm_connection.hpp"

#include <lcm/lcm-cpp.hpp>

namespace gaitmon {

std::shared_ptr<lcm::LCM> open_lcm(const std::string& url) {
  auto connection = std::make_shared<lcm::LCM>(url);
  if (!connection->good()) {
    throw LcmError("LCM cannot open \"" + url +
                   "\" (expected e.g. udpm://239.255.76.67:7667?ttl=0 or memq://; LCM's own "
                   "message, if any, is above)");
  }
  return connection;
}

}  // namespace gaitmon
