// open_lcm: one place that turns LCM's silent failures (a null lcm_t, a missing socket) into an
// exception.
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
  // A tcpq:// URL whose server does not answer gives a "good" LCM without a socket: waiting on
  // it aborts (select on fd -1) and publishing to it goes nowhere.
  if (connection->getFileno() < 0) {
    throw LcmError("LCM has no connection for \"" + url +
                   "\" (for tcpq://, is the LCM TCP server running at that address?)");
  }
  return connection;
}

}  // namespace gaitmon
