// The progress bar on a real pseudo-terminal put in place of stderr, and its silence when stderr
// is not a terminal, so that logs and CI output stay free of it.
#include "src/cli/progress.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <cstdio>
#include <stdexcept>
#include <string>

namespace gaitmon::cli {
namespace {

// Points stderr at `fd` for the object's lifetime.
class StderrTo {
 public:
  explicit StderrTo(int fd) : saved_(::dup(STDERR_FILENO)) {
    if (saved_ < 0 || ::dup2(fd, STDERR_FILENO) < 0) throw std::runtime_error("dup2 stderr");
  }
  ~StderrTo() {
    std::fflush(stderr);
    ::dup2(saved_, STDERR_FILENO);
    ::close(saved_);
  }
  StderrTo(const StderrTo&) = delete;
  StderrTo& operator=(const StderrTo&) = delete;

 private:
  int saved_;
};

// Everything readable from `fd` until it stays quiet for 200 ms.
std::string drain(int fd) {
  std::string out;
  pollfd p{fd, POLLIN, 0};
  char buffer[512];
  while (::poll(&p, 1, 200) == 1 && (p.revents & POLLIN) != 0) {
    const ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n <= 0) break;
    out.append(buffer, static_cast<std::size_t>(n));
  }
  return out;
}

TEST(ProgressBar, DrawsOnATerminalOnlyWhenThePercentMoves) {
  int master = -1;
  int slave = -1;
  ASSERT_EQ(openpty(&master, &slave, nullptr, nullptr, nullptr), 0);
  termios tio{};
  ASSERT_EQ(tcgetattr(slave, &tio), 0);
  cfmakeraw(&tio);  // no "\n" -> "\r\n", so the bytes compare as written
  ASSERT_EQ(tcsetattr(slave, TCSANOW, &tio), 0);
  {
    StderrTo redirect(slave);
    ProgressBar bar("fit");
    bar.update(0.5);
    bar.update(0.504);
    bar.update(-1.0);
    bar.update(7.0);
  }
  const std::string hashes(40, '#');
  EXPECT_EQ(drain(master), "\rfit [" + hashes.substr(0, 20) + std::string(20, ' ') + "]  50%" +
                               "\rfit [" + std::string(40, ' ') + "]   0%" + "\rfit [" + hashes +
                               "] 100%\n");
  ::close(slave);
  ::close(master);
}

TEST(ProgressBar, IsSilentWhenStderrIsNotATerminal) {
  int pipe_fds[2];
  ASSERT_EQ(::pipe2(pipe_fds, O_NONBLOCK), 0);
  {
    StderrTo redirect(pipe_fds[1]);
    ProgressBar bar("fit");
    bar.update(0.5);
    bar.update(1.0);
  }
  ::close(pipe_fds[1]);
  EXPECT_EQ(drain(pipe_fds[0]), "");
  ::close(pipe_fds[0]);
}

}  // namespace
}  // namespace gaitmon::cli
