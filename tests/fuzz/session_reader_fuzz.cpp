// libFuzzer target for the session CSV v1 reader: any input either reads or fails with
// InputError; nothing else may escape, crash or trip a sanitizer.
#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "gaitmon/error.hpp"
#include "gaitmon/session.hpp"

namespace {

// The reader takes a path: the input goes into one memory-backed file, reopened each time
// through /proc so that every run reads from its start.
const std::string& input_path() {
  static const std::string path = [] {
    const int fd = memfd_create("session_reader_fuzz", 0);
    if (fd < 0) std::abort();
    return "/proc/self/fd/" + std::to_string(fd);
  }();
  return path;
}

int input_fd() {
  static const int fd = std::stoi(input_path().substr(input_path().rfind('/') + 1));
  return fd;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const int fd = input_fd();
  if (ftruncate(fd, 0) != 0) std::abort();
  if (size > 0 && pwrite(fd, data, size, 0) != static_cast<ssize_t>(size)) std::abort();
  try {
    gaitmon::SessionReader reader(input_path());
    gaitmon::Frame frame;
    const std::size_t sensors = reader.header().sensors;
    while (reader.next(frame)) {
      if (frame.bits.size() != sensors) std::abort();
    }
  } catch (const gaitmon::InputError&) {
  }
  return 0;
}
