// Names of the link states, for logs and the status message.
#include "drivers/byte_source.hpp"

namespace gaitmon::drivers {

std::string_view link_state_name(LinkState state) {
  switch (state) {
    case LinkState::Connecting:
      return "connecting";
    case LinkState::Connected:
      return "connected";
    case LinkState::Disconnected:
      return "disconnected";
  }
  return "unknown";
}

}  // namespace gaitmon::drivers
