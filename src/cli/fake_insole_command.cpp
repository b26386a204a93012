// `gaitmon fake-insole`: a fake insole device. Streams a session CSV v1 in the project's wire
// format through a pseudo-terminal (or stdout), paced like the recording, with optional
// deterministic link faults for tests.
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "drivers/wire_format.hpp"
#include "gaitmon/json.hpp"
#include "live.hpp"
#include "output_file.hpp"
#include "replay/fault_injector.hpp"
#include "replay/pacer.hpp"
#include "replay/pseudo_terminal.hpp"
#include "replay/session_byte_source.hpp"

namespace gaitmon::cli {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

std::atomic<bool> g_stop{false};

extern "C" void on_stop_signal(int) {
  g_stop.store(true);
}

struct FakeInsoleArgs {
  fs::path session;
  std::string speed = "1";
  bool pty = false;
  fs::path link;
  replay::FaultOptions faults;
  double reopen_after_s = 0.0;
  int reopen_gap_ms = 200;
  bool hold = false;
  fs::path summary;
};

void announce(const std::string& path) {
  std::fputs((path + "\n").c_str(), stdout);
  std::fflush(stdout);
}

void run_fake_insole(const GlobalOptions& global, const FakeInsoleArgs& args) {
  const Config config = load_global_config(global);
  const double speed = parse_speed(args.speed);
  if (args.reopen_after_s > 0.0 && (!args.pty || args.link.empty())) {
    throw CLI::ValidationError("--reopen-after",
                               "needs --pty and --link (the new pty's path differs)");
  }
  if ((!args.link.empty() || args.hold) && !args.pty) {
    throw CLI::ValidationError("--link and --hold", "need --pty");
  }
  const drivers::WireFormat format(config.wire);
  check_whole_session(args.session);
  SessionReader reader(args.session);
  replay::SessionEncoder encoder(format, reader.header().insole_size);
  replay::FaultInjector injector(args.faults, format);

  struct sigaction action {};
  action.sa_handler = on_stop_signal;  // no SA_RESTART: a blocked write returns EINTR
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  std::signal(SIGPIPE, SIG_IGN);

  std::unique_ptr<replay::PseudoTerminal> pty;
  std::vector<std::string> paths;
  const auto open_pty = [&] {
    pty = std::make_unique<replay::PseudoTerminal>();
    paths.push_back(pty->path());
    if (!args.link.empty()) replay::point_link(args.link, pty->path());
    announce(pty->path());
  };
  if (args.pty) open_pty();

  replay::Pacer pacer(speed, g_stop);
  const auto start = std::chrono::steady_clock::now();
  bool reopen_pending = args.reopen_after_s > 0.0;
  int reopens = 0;
  std::vector<std::uint8_t> batch;
  std::vector<std::uint8_t> wire;
  const auto flush = [&] {
    const bool ok = replay::write_all(pty ? pty->fd() : STDOUT_FILENO, batch, &g_stop);
    batch.clear();
    return ok;
  };
  Frame frame;
  bool stopped = false;
  while (!stopped && reader.next(frame)) {
    if (!pacer.due(frame.t_s) && (!flush() || !pacer.wait(frame.t_s))) break;
    if (reopen_pending && std::chrono::steady_clock::now() - start >=
                              std::chrono::duration<double>(args.reopen_after_s)) {
      reopen_pending = false;
      if (!flush()) break;
      // Unplugged, as udev drops a /dev/serial/by-id link: a link left on the old pty could lead
      // a reader into whichever process gets that pty number next.
      fs::remove(args.link);
      pty.reset();  // the device disappears: the reader is hung up
      std::this_thread::sleep_for(std::chrono::milliseconds(args.reopen_gap_ms));
      open_pty();
      ++reopens;
    }
    const SensorFrame& sent = encoder.next(frame);
    wire.clear();
    encoder.append_wire(wire);
    injector.append(wire, sent.foot, sent.sequence, batch);
    if (batch.size() >= 64 * 1024 || !std::isinf(speed)) stopped = !flush();
  }
  if (!stopped) flush();  // the rest: after the last frame a reader that left changes nothing
  const int unread = pty ? pty->wait_drained(10s, &g_stop) : 0;
  while (args.hold && !g_stop.load()) std::this_thread::sleep_for(50ms);
  pty.reset();

  const replay::FaultCounts& counts = injector.counts();
  nlohmann::json summary{
      {"frames", counts.frames},
      {"garbage_bursts", counts.garbage_bursts},
      {"garbage_bytes", counts.garbage_bytes},
      {"crc_corrupted", counts.crc_corrupted},
      {"truncated", counts.truncated},
      {"dropped_bytes", counts.dropped_bytes},
      {"reopens", reopens},
      {"unread_bytes_at_exit", unread},
      {"stopped_early", g_stop.load()},
      {"paths", paths},
      {"faulted_sequences",
       {{"L", counts.faulted_sequences[0]}, {"R", counts.faulted_sequences[1]}}}};
  if (!args.summary.empty()) {
    std::ofstream out(args.summary);
    out << json_file_text(summary);
    if (!out) throw std::runtime_error("cannot write " + args.summary.string());
  }
  fmt::print(stderr,
             "fake-insole: {} frames sent; injected {} garbage bursts ({} bytes), {} CRC "
             "corruptions, {} truncations ({} bytes dropped), {} reopens; {} bytes unread\n",
             counts.frames, counts.garbage_bursts, counts.garbage_bytes, counts.crc_corrupted,
             counts.truncated, counts.dropped_bytes, reopens, unread);
}

}  // namespace

void add_fake_insole_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<FakeInsoleArgs>();
  CLI::App* sub = app.add_subcommand(
      "fake-insole",
      "A fake insole: streams a session CSV v1 in the project's wire format (drivers/PROTOCOL.md) "
      "through a pseudo-terminal (--pty; its path is the first line on stdout) or to stdout");
  sub->add_option("session", args->session, "Session CSV v1 to play")
      ->required()
      ->check(session_file_read_twice());
  sub->add_option("--speed", args->speed, "Playback speed: x real time (at least 0.001), or max")
      ->capture_default_str();
  sub->add_flag("--pty", args->pty, "Create a pseudo-terminal and print its path");
  sub->add_option("--link", args->link,
                  "Keep a symlink at this path pointing to the current pty (a reopened pty gets "
                  "a new path; the link is gone while there is no pty, as a by-id link unplugged)");
  sub->add_flag("--hold", args->hold,
                "Keep the pty open after the session until SIGINT or SIGTERM");
  sub->add_option("--seed", args->faults.seed, "Seed of the fault injection")
      ->check(whole_number_in(0, std::numeric_limits<std::uint64_t>::max()))
      ->capture_default_str();
  sub->add_option("--garbage-rate", args->faults.garbage_rate,
                  "Probability of a garbage burst before a frame (bytes never equal the first "
                  "sync byte)")
      ->check(number_in(0.0, 1.0))
      ->capture_default_str();
  sub->add_option("--garbage-max-bytes", args->faults.garbage_max_bytes,
                  "Longest garbage burst, bytes")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  sub->add_option("--crc-rate", args->faults.crc_rate,
                  "Probability that a frame has one bit flipped after its header")
      ->check(number_in(0.0, 1.0))
      ->capture_default_str();
  sub->add_option("--truncate-rate", args->faults.truncate_rate,
                  "Probability that a frame loses 1 to N+C bytes from its end (N its sensors, C "
                  "the CRC's bytes)")
      ->check(number_in(0.0, 1.0))
      ->capture_default_str();
  sub->add_option("--reopen-after", args->reopen_after_s,
                  "Close the pty this many seconds after the start and open a new one (needs "
                  "--pty and --link); bytes not yet read are lost, as with a real unplug")
      ->check(number_in(0.0, 86400.0));
  sub->add_option("--reopen-gap-ms", args->reopen_gap_ms, "Time without a pty when reopening, ms")
      ->check(CLI::Range(0, 60000))
      ->capture_default_str();
  sub->add_option("--summary", args->summary,
                  "Write what was sent and injected as JSON (a fault summary also goes to "
                  "stderr)");
  sub->callback([&global, args, sub] {
    // Checked before the playback, which can take as long as the session. An empty path given
    // would otherwise read as the option left out.
    if (sub->count("--link") > 0 && args->link.empty()) {
      throw CLI::ValidationError("--link", "the path is empty");
    }
    if (!args->link.empty()) {
      const auto status = std::filesystem::symlink_status(args->link);
      if (std::filesystem::exists(status) && !std::filesystem::is_symlink(status)) {
        throw CLI::ValidationError("--link", args->link.string() +
                                                 " exists and is not a symlink, which the link "
                                                 "would replace");
      }
    }
    if (sub->count("--summary") > 0) {
      check_output_path(args->summary, "--summary");
      const fs::path folder = fs::absolute(args->summary).parent_path();
      if (!fs::is_directory(folder)) {
        throw CLI::ValidationError("--summary",
                                   "the folder " + folder.string() + " does not exist");
      }
    }
    run_fake_insole(global, *args);
  });
}

}  // namespace gaitmon::cli
