// The fake insole's pseudo-terminal: raw bytes, unread counting and draining, a write that gives
// up at a stop, the hang-up a reader sees, errors that name the failed call, and the link that
// is never missing.
#include "replay/pseudo_terminal.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "test_support.hpp"

namespace gaitmon::replay {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// Opens the reader's end, as the serial driver does.
int open_reader(const PseudoTerminal& pty) {
  return ::open(pty.path().c_str(), O_RDONLY | O_NOCTTY);
}

// Up to `count` bytes; fewer if none come for 5 s.
std::vector<std::uint8_t> read_exactly(int fd, std::size_t count) {
  std::vector<std::uint8_t> out(count);
  std::size_t at = 0;
  pollfd p{fd, POLLIN, 0};
  while (at < count && ::poll(&p, 1, 5000) == 1) {
    const ssize_t n = ::read(fd, out.data() + at, count - at);
    if (n <= 0) break;
    at += static_cast<std::size_t>(n);
  }
  out.resize(at);
  return out;
}

TEST(PseudoTerminal, PassesEveryByteValueUnchangedAndKeepsThemForALateReader) {
  PseudoTerminal pty;
  EXPECT_EQ(pty.path().rfind("/dev/pts/", 0), 0U) << pty.path();
  std::vector<std::uint8_t> bytes;
  for (int v = 0; v < 256; ++v) bytes.push_back(static_cast<std::uint8_t>(v));
  // Carriage return, newline, ^C, ^D and DEL are the ones a terminal in cooked mode changes.
  ASSERT_TRUE(write_all(pty.fd(), bytes));
  const int reader = open_reader(pty);
  ASSERT_GE(reader, 0) << pty.path();
  EXPECT_EQ(read_exactly(reader, bytes.size()), bytes);
  ::close(reader);
}

TEST(PseudoTerminal, CountsUnreadBytesAndWaitsUntilAReaderDrainsThem) {
  PseudoTerminal pty;
  const std::vector<std::uint8_t> bytes(1000, 0x5a);
  ASSERT_TRUE(write_all(pty.fd(), bytes));
  // The bytes pass a flip buffer before they count, so the count may lag the write briefly.
  const auto until = std::chrono::steady_clock::now() + 2s;
  while (pty.unread() < 1000 && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(5ms);
  EXPECT_EQ(pty.unread(), 1000);
  EXPECT_EQ(pty.wait_drained(100ms), 1000) << "nobody reads, so nothing drains";

  const int reader = open_reader(pty);
  ASSERT_GE(reader, 0);
  std::thread take([&] { EXPECT_EQ(read_exactly(reader, 600).size(), 600U); });
  take.join();
  EXPECT_EQ(pty.wait_drained(100ms), 400);
  std::thread rest([&] {
    std::this_thread::sleep_for(200ms);
    EXPECT_EQ(read_exactly(reader, 400).size(), 400U);
  });
  EXPECT_EQ(pty.wait_drained(10s), 0);
  rest.join();
  ::close(reader);
}

TEST(PseudoTerminal, WaitingForADrainEndsWhenStopIsSet) {
  PseudoTerminal pty;
  ASSERT_TRUE(write_all(pty.fd(), std::vector<std::uint8_t>(10, 1)));
  std::atomic<bool> stop{false};
  std::thread stopper([&] {
    std::this_thread::sleep_for(100ms);
    stop.store(true);
  });
  const auto before = std::chrono::steady_clock::now();
  EXPECT_EQ(pty.wait_drained(30s, &stop), 10);
  EXPECT_LT(std::chrono::steady_clock::now() - before, 10s);
  stopper.join();
}

TEST(PseudoTerminal, WritesMoreThanThePtyHoldsThroughPartialWrites) {
  PseudoTerminal pty;
  std::vector<std::uint8_t> bytes(1 << 20);
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<std::uint8_t>(i * 7);
  const int reader = open_reader(pty);
  ASSERT_GE(reader, 0);
  std::vector<std::uint8_t> got;
  std::thread take([&] { got = read_exactly(reader, bytes.size()); });
  EXPECT_TRUE(write_all(pty.fd(), bytes));
  take.join();
  EXPECT_EQ(got, bytes);
  ::close(reader);
}

extern "C" void interrupt_only(int) {}

// Starts write_all of far more than `fd` holds on a thread, sets the stop flag once it waits,
// calls `nudge` (with the writer's thread) until it returns, and drains `reader` if it never
// does, so that the test can end. Returns whether it returned, having written nothing more.
bool gives_up_on_stop(
    int fd, int reader, const std::function<void(std::thread&)>& nudge = [](std::thread&) {}) {
  std::atomic<bool> stop{false};
  std::atomic<int> result{-1};
  const std::vector<std::uint8_t> bytes(1 << 20, 1);
  std::thread writer([&] { result = write_all(fd, bytes, &stop) ? 1 : 0; });
  std::this_thread::sleep_for(100ms);
  EXPECT_EQ(result.load(), -1) << "nobody reads, so the write waits";
  stop = true;
  const auto give_up = std::chrono::steady_clock::now() + 20s;
  while (result.load() == -1 && std::chrono::steady_clock::now() < give_up) {
    nudge(writer);
    std::this_thread::sleep_for(10ms);
  }
  const bool returned = result.load() != -1;
  if (!returned) read_exactly(reader, bytes.size());
  writer.join();
  return returned && result.load() == 0;
}

// fake-insole takes its signals on a watcher thread (StopOnSignal), so no signal interrupts the
// writer: with nobody reading, the pty's own non-blocking master lets it see the stop request
// (within 100 ms) without one.
TEST(PseudoTerminal, AWriteToAPtyNobodyReadsGivesUpOnStopWithoutASignal) {
  PseudoTerminal pty;
  const int reader = open_reader(pty);
  EXPECT_TRUE(gives_up_on_stop(pty.fd(), reader));
  ::close(reader);
}

// A blocking descriptor (stdout, when fake-insole writes there) is woken by a signal without
// SA_RESTART: the write returns EINTR, and with the stop flag set write_all gives up instead of
// writing on. A signal that arrives once some bytes went through ends that write short instead,
// and the next write blocks again, so the signal is repeated until the writer returns.
TEST(PseudoTerminal, AWriteInterruptedOnceStopIsSetGivesUp) {
  int pipe_fds[2];
  ASSERT_EQ(::pipe(pipe_fds), 0);
  struct sigaction action {};
  action.sa_handler = interrupt_only;
  struct sigaction saved {};
  ASSERT_EQ(sigaction(SIGUSR1, &action, &saved), 0);
  EXPECT_TRUE(gives_up_on_stop(pipe_fds[1], pipe_fds[0], [](std::thread& writer) {
    pthread_kill(writer.native_handle(), SIGUSR1);
  }));
  sigaction(SIGUSR1, &saved, nullptr);
  ::close(pipe_fds[0]);
  ::close(pipe_fds[1]);
}

// A read blocked at that moment fails with EIO instead; which of the two a reader meets depends
// on timing, so the test looks at a reader that was not reading.
TEST(PseudoTerminal, DestroyingItHangsUpTheReader) {
  auto pty = std::make_unique<PseudoTerminal>();
  const int reader = open_reader(*pty);
  ASSERT_GE(reader, 0);
  pty.reset();
  pollfd p{reader, POLLIN, 0};
  ASSERT_EQ(::poll(&p, 1, 1000), 1);
  EXPECT_NE(p.revents & POLLHUP, 0);
  std::uint8_t byte = 0;
  EXPECT_EQ(::read(reader, &byte, 1), 0) << "end of file";
  ::close(reader);
}

TEST(PseudoTerminal, AFailedWriteNamesTheCall) {
  const std::vector<std::uint8_t> bytes(4, 0);
  try {
    write_all(-1, bytes);
    FAIL() << "a write to no descriptor succeeded";
  } catch (const std::system_error& e) {
    EXPECT_EQ(e.code().value(), EBADF);
    EXPECT_EQ(std::string(e.what()).rfind("write", 0), 0U) << e.what();
  }
}

// With one descriptor left, the pty's device end opens and its reader's end cannot. Returns 0
// when the error names the reader's path and the device end was closed again; runs in a child
// process, whose soft descriptor limit it lowers and then restores: UBSan's check of a call on
// the caught exception opens a pipe, and with no descriptor left it reports a bad object.
int open_with_one_descriptor_left() {
  rlimit saved{};
  if (getrlimit(RLIMIT_NOFILE, &saved) != 0) return 2;
  const int probe = ::dup(0);
  ::close(probe);
  const rlimit limit{static_cast<rlim_t>(probe + 1), saved.rlim_max};
  if (setrlimit(RLIMIT_NOFILE, &limit) != 0) return 3;
  try {
    PseudoTerminal pty;
    return 4;
  } catch (const std::system_error& e) {
    if (setrlimit(RLIMIT_NOFILE, &saved) != 0) return 8;
    if (e.code().value() != EMFILE) return 5;
    if (std::string(e.what()).rfind("open /dev/pts/", 0) != 0) return 6;
  }
  return ::dup(0) == probe ? 0 : 7;
}

TEST(PseudoTerminal, AFailedOpenNamesTheCallAndClosesWhatItOpened) {
  EXPECT_EXIT(std::_Exit(open_with_one_descriptor_left()), ::testing::ExitedWithCode(0), "");
}

TEST(PointLink, ReplacesTheLinkAndLeavesNoTemporary) {
  const fs::path dir = test::scratch_dir("point-link");
  const fs::path link = dir / "insole";
  point_link(link, "/dev/pts/998");
  EXPECT_EQ(fs::read_symlink(link), "/dev/pts/998");
  point_link(link, "/dev/pts/999");
  EXPECT_EQ(fs::read_symlink(link), "/dev/pts/999");
  EXPECT_FALSE(fs::exists(fs::symlink_status(link.string() + ".tmp")));
}

// fake-insole refuses a folder as --link up front; one that takes the link's place later (at a
// reopen) fails the rename, which must not leave the new link behind under the temporary name.
TEST(PointLink, AFolderInTheLinksPlaceIsAnErrorThatLeavesNoTemporary) {
  const fs::path dir = test::scratch_dir("point-link-folder");
  const fs::path link = dir / "insole";
  fs::create_directories(link);
  EXPECT_THROW(point_link(link, "/dev/pts/998"), fs::filesystem_error);
  EXPECT_TRUE(fs::is_directory(link));
  EXPECT_FALSE(fs::exists(fs::symlink_status(link.string() + ".tmp")));
}

}  // namespace
}  // namespace gaitmon::replay
