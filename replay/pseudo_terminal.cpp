// The pseudo-terminal of the fake insole, on the POSIX pty calls.
#include "replay/pseudo_terminal.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdlib>
#include <system_error>
#include <thread>

namespace gaitmon::replay {
namespace {

[[noreturn]] void fail_errno(const std::string& what) {
  throw std::system_error(errno, std::generic_category(), what);
}

}  // namespace

PseudoTerminal::PseudoTerminal() {
  // Non-blocking, so that a writer with no reader on the other side still sees a stop request
  // (write_all waits for room in short polls).
  master_ = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (master_ < 0) fail_errno("posix_openpt");
  try {
    if (grantpt(master_) != 0) fail_errno("grantpt");
    if (unlockpt(master_) != 0) fail_errno("unlockpt");
    std::array<char, 128> name{};
    if (ptsname_r(master_, name.data(), name.size()) != 0) fail_errno("ptsname_r");
    path_ = name.data();
    slave_ = ::open(path_.c_str(), O_RDWR | O_NOCTTY);
    if (slave_ < 0) fail_errno("open " + path_);
    termios tio{};
    if (tcgetattr(slave_, &tio) != 0) fail_errno("tcgetattr " + path_);
    cfmakeraw(&tio);
    if (tcsetattr(slave_, TCSANOW, &tio) != 0) fail_errno("tcsetattr " + path_);
  } catch (...) {
    if (slave_ >= 0) ::close(slave_);
    ::close(master_);
    throw;
  }
}

PseudoTerminal::~PseudoTerminal() {
  ::close(master_);
  ::close(slave_);
}

int PseudoTerminal::unread() const {
  int n = 0;
  return ioctl(slave_, FIONREAD, &n) == 0 ? n : 0;
}

int PseudoTerminal::wait_drained(std::chrono::milliseconds limit,
                                 const std::atomic<bool>* stop) const {
  using namespace std::chrono_literals;
  const auto give_up = std::chrono::steady_clock::now() + limit;
  int empty_checks = 0;
  while (empty_checks < 3 && std::chrono::steady_clock::now() < give_up &&
         (stop == nullptr || !stop->load())) {
    empty_checks = unread() == 0 ? empty_checks + 1 : 0;
    std::this_thread::sleep_for(20ms);
  }
  return unread();
}

bool write_all(int fd, std::span<const std::uint8_t> bytes, const std::atomic<bool>* stop) {
  while (!bytes.empty()) {
    const ssize_t n = ::write(fd, bytes.data(), bytes.size());
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) {
        pollfd room{fd, POLLOUT, 0};
        if (::poll(&room, 1, 100) < 0 && errno != EINTR) fail_errno("poll");
      } else if (errno != EINTR) {
        fail_errno("write");
      }
      if (stop != nullptr && stop->load()) return false;
      continue;
    }
    bytes = bytes.subspan(static_cast<std::size_t>(n));
  }
  return true;
}

void point_link(const std::filesystem::path& link, const std::string& target) {
  const std::filesystem::path tmp = link.string() + ".tmp";
  std::filesystem::remove(tmp);
  std::filesystem::create_symlink(target, tmp);
  try {
    std::filesystem::rename(tmp, link);
  } catch (...) {
    // A folder that took the link's place since fake-insole checked it, for one.
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw;
  }
}

}  // namespace gaitmon::replay
