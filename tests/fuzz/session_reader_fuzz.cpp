// libFuzzer target for the session CSV v1 reader: any input either reads or fails with
// InputError; nothing else may escape, crash or trip a sanitizer.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "gaitmon/error.hpp"
#include "gaitmon/session.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // The stream constructor runs the same parser as the path one without a file per run.
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    gaitmon::SessionReader reader(in, "fuzz-input");
    gaitmon::Frame frame;
    const std::size_t sensors = reader.header().sensors;
    while (reader.next(frame)) {
      if (frame.bits.size() != sensors) std::abort();
    }
  } catch (const gaitmon::InputError& e) {
    if (e.file() != "fuzz-input") std::abort();
  }
  return 0;
}
