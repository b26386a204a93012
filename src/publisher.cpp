// The clock shared by every published message.
#include "gaitmon/publisher.hpp"

#include <chrono>

namespace gaitmon {

std::int64_t now_utime() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace gaitmon
