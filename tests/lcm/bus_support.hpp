// Helpers for tests that run LCM over a real bus with clients in other processes: a private
// network namespace for udpm, child processes whose output is read line by line, and a reader
// of lcm-logger files. Header-only, so that any test (the end-to-end monitor test too) can
// include "lcm/bus_support.hpp".
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "test_support.hpp"

extern char** environ;

namespace gaitmon::test {

/// The udpm bus a test should use, and how it was made (tests print it).
struct Bus {
  std::string url;
  std::string description;
  bool private_namespace = false;
};

/// Moves this process into a network namespace of its own, with lo up and multicast routed to
/// it, so that nothing it publishes leaves it and parallel tests do not hear each other; child
/// processes started afterwards share it. Needs root or CAP_SYS_ADMIN. Where that is refused,
/// the process stays where it was and gets udpm with ttl=0 (this host only) on a port derived
/// from its pid. Call it first, from the test's main thread: the namespace belongs to the
/// calling thread and to threads and processes it starts later. Idempotent.
inline const Bus& private_bus() {
  static const Bus bus = [] {
    std::string why;
    const int original = ::open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
    if (::unshare(CLONE_NEWNET) == 0) {
      std::string output;
      if (run_command("ip link set lo up && ip route add 224.0.0.0/4 dev lo", &output) == 0) {
        if (original >= 0) ::close(original);
        return Bus{"udpm://239.255.76.67:7667?ttl=0",
                   "udpm in a private network namespace (unshare(CLONE_NEWNET), lo up, "
                   "224.0.0.0/4 routed to lo)",
                   true};
      }
      why = "ip failed in the new namespace: " + output;
      if (original < 0 || ::setns(original, CLONE_NEWNET) != 0) {
        throw std::runtime_error("cannot return to the original network namespace");
      }
    } else {
      why = std::string("unshare(CLONE_NEWNET): ") + std::strerror(errno);
    }
    if (original >= 0) ::close(original);
    const int port = 20000 + static_cast<int>(::getpid() % 20000);
    return Bus{"udpm://239.255.76.67:" + std::to_string(port) + "?ttl=0",
               "udpm with ttl=0 on this host's loopback, port " + std::to_string(port) +
                   " (no private network namespace: " + why + ")",
               false};
  }();
  return bus;
}

/// A child process whose stdout and stderr are read line by line. The destructor kills it if
/// it still runs.
class ChildProcess {
 public:
  enum Stream { Stdout = 0, Stderr = 1 };
  using Clock = std::chrono::steady_clock;

  explicit ChildProcess(const std::vector<std::string>& argv) {
    int out[2];
    int err[2];
    if (::pipe2(out, O_CLOEXEC) != 0 || ::pipe2(err, O_CLOEXEC) != 0) {
      throw std::runtime_error("pipe2 failed");
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, out[1], 1);
    posix_spawn_file_actions_adddup2(&actions, err[1], 2);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    const int rc = posix_spawnp(&pid_, args[0], &actions, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    ::close(out[1]);
    ::close(err[1]);
    fds_[Stdout] = out[0];
    fds_[Stderr] = err[0];
    if (rc != 0) {
      pid_ = -1;
      throw std::runtime_error("cannot start " + argv[0] + ": " + std::strerror(rc));
    }
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;
  ~ChildProcess() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    for (int fd : fds_) {
      if (fd >= 0) ::close(fd);
    }
  }

  /// The next line of `stream` (without its newline), or nullopt at the deadline or at the end
  /// of the stream. Reading one stream also buffers what arrived on the other.
  std::optional<std::string> read_line(Stream stream, Clock::time_point deadline) {
    for (;;) {
      const auto newline = buffers_[stream].find('\n');
      if (newline != std::string::npos) {
        std::string line = buffers_[stream].substr(0, newline);
        buffers_[stream].erase(0, newline + 1);
        return line;
      }
      if (fds_[stream] < 0) return std::nullopt;
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (left <= 0) return std::nullopt;
      pollfd polls[2] = {{fds_[0], POLLIN, 0}, {fds_[1], POLLIN, 0}};
      if (::poll(polls, 2, static_cast<int>(left)) < 0 && errno != EINTR) {
        throw std::runtime_error("poll failed");
      }
      for (int s = 0; s < 2; ++s) {
        if (fds_[s] >= 0 && (polls[s].revents & (POLLIN | POLLHUP | POLLERR)) != 0) fill(s);
      }
    }
  }

  /// Lines of `stream` up to and including the first one that contains `text`; empty if none
  /// came before the deadline.
  std::vector<std::string> read_until(Stream stream, const std::string& text,
                                      Clock::time_point deadline) {
    std::vector<std::string> lines;
    while (auto line = read_line(stream, deadline)) {
      lines.push_back(*line);
      if (line->find(text) != std::string::npos) return lines;
    }
    return {};
  }

  /// Everything left on `stream` until it closes or the deadline passes.
  std::vector<std::string> read_rest(Stream stream, Clock::time_point deadline) {
    std::vector<std::string> lines;
    while (auto line = read_line(stream, deadline)) lines.push_back(*line);
    if (!buffers_[stream].empty()) lines.push_back(std::exchange(buffers_[stream], {}));
    return lines;
  }

  /// What is left on stderr as one text, for a failure message (a sanitizer's report, say).
  std::string stderr_text(Clock::time_point deadline) {
    std::string text;
    for (const std::string& line : read_rest(Stderr, deadline)) text += line + '\n';
    return text;
  }

  void signal(int signo) {
    if (pid_ > 0) ::kill(pid_, signo);
  }

  /// The exit status (128 + signal if killed), or nullopt if it still runs at the deadline.
  std::optional<int> wait(Clock::time_point deadline) {
    while (pid_ > 0) {
      int status = 0;
      const pid_t done = ::waitpid(pid_, &status, WNOHANG);
      if (done == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      if (Clock::now() >= deadline) return std::nullopt;
      ::usleep(10000);
    }
    return std::nullopt;
  }

 private:
  void fill(int stream) {
    char chunk[4096];
    const ssize_t n = ::read(fds_[stream], chunk, sizeof chunk);
    if (n > 0) {
      buffers_[stream].append(chunk, static_cast<std::size_t>(n));
    } else if (n == 0 || errno != EINTR) {
      ::close(fds_[stream]);
      fds_[stream] = -1;
    }
  }

  pid_t pid_ = -1;
  int fds_[2] = {-1, -1};
  std::string buffers_[2];
};

/// One event of an LCM log file (lcm-logger, or the file:// provider).
struct LogEvent {
  std::int64_t number = 0;
  std::int64_t utime = 0;
  std::string channel;
  std::vector<std::uint8_t> data;
};

/// Reads an LCM log: per event a 28-byte big-endian header (sync 0xEDA1DA01, int64 event
/// number, int64 utime, int32 channel length, int32 data length), then the channel and the
/// data. A truncated last event (a logger still writing) is ignored; a bad sync word throws.
inline std::vector<LogEvent> read_lcm_log(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto be = [&bytes](std::size_t at, int size) {
    std::uint64_t value = 0;
    for (int i = 0; i < size; ++i) {
      value = (value << 8) | static_cast<std::uint8_t>(bytes[at + static_cast<std::size_t>(i)]);
    }
    return value;
  };
  std::vector<LogEvent> events;
  std::size_t at = 0;
  while (at + 28 <= bytes.size()) {
    if (be(at, 4) != 0xEDA1DA01U) {
      throw std::runtime_error(path.string() + ": no sync word at byte " + std::to_string(at));
    }
    LogEvent event;
    event.number = static_cast<std::int64_t>(be(at + 4, 8));
    event.utime = static_cast<std::int64_t>(be(at + 12, 8));
    const std::size_t channel_size = be(at + 20, 4);
    const std::size_t data_size = be(at + 24, 4);
    if (at + 28 + channel_size + data_size > bytes.size()) break;
    event.channel = bytes.substr(at + 28, channel_size);
    const auto* data = reinterpret_cast<const std::uint8_t*>(bytes.data() + at + 28 + channel_size);
    event.data.assign(data, data + data_size);
    events.push_back(std::move(event));
    at += 28 + channel_size + data_size;
  }
  return events;
}

}  // namespace gaitmon::test
