// `gaitmon replay`: a recorded session through the whole live pipeline (the in-process fake
// driver, the real decoder, the monitor, LCM), at real time, x N or as fast as it goes.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>

#include "commands.hpp"
#include "drivers/frame_decoder.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/lcm_publisher.hpp"
#include "gaitmon/monitor.hpp"
#include "live.hpp"
#include "replay/session_byte_source.hpp"

namespace gaitmon::cli {
namespace {

struct ReplayArgs {
  std::filesystem::path session = GAITMON_DEMO_SESSION;
  std::string speed = "1";
  std::string lcm_url;
};

void run_replay(const GlobalOptions& global, const ReplayArgs& args) {
  Config config = load_global_config(global);
  if (!args.lcm_url.empty()) config.lcm.url = args.lcm_url;
  const double speed = parse_speed(args.speed);

  const drivers::WireFormat format(config.wire);
  replay::SessionByteSource source(args.session, format, speed);
  check_session_rate(args.session, source.header().sample_rate_hz, config);
  // Signals first: every thread started below inherits the blocked mask.
  std::atomic<Monitor*> running{nullptr};
  // The driver first, then the monitor, to release the driver from a wait for room in the ring.
  StopOnSignal on_signal("the fake driver, then the ring, the fits and a final status", [&](int) {
    source.stop();
    if (Monitor* m = running.load()) m->close();
  });

  LcmPublisher lcm(open_lcm_url(global, config.lcm.url, !args.lcm_url.empty()), config.lcm);
  StepPrinter printer(lcm);
  drivers::FrameDecoder decoder(format);
  LinkStatus link(decoder, source);
  MonitorOptions options;
  options.sample_rate_hz = source.header().sample_rate_hz;
  options.publish_raw = config.lcm.raw_enabled;
  options.analysis.area = live_area_source(config.model);
  // A replay never skips: a full ring or backlog makes the fake driver wait.
  options.backlog_overflow = BacklogOverflow::Wait;
  options.driver_status = [&](StatusReport& status) { link.fill(status); };
  Monitor monitor(config, options, printer);
  const FinishOnExit watching(on_signal);
  running.store(&monitor);
  spdlog::info("replay: {} at {} -> LCM {}", args.session.string(),
               std::isinf(speed) ? std::string("max speed") : fmt::format("x{}", speed),
               config.lcm.url);

  const auto start = std::chrono::steady_clock::now();
  source.run(
      [&](std::span<const std::uint8_t> bytes) {
        decoder.feed(bytes, [&](const SensorFrame& frame) {
          if (!monitor.offer_wait(frame)) source.stop();
        });
      },
      [&](drivers::LinkState state, std::string_view detail) {
        // The fake driver never drops: its Disconnected is the session's end or a stop.
        if (state == drivers::LinkState::Disconnected) {
          link.on_end(detail);
        } else {
          link.on_state(state, detail);
        }
      });
  // A signal handled just now may still be closing the monitor: it has to return first.
  on_signal.finish();
  monitor.stop();
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const MonitorCounters c = monitor.counters();
  const double session_s =
      static_cast<double>(c.frames_processed) / 2.0 / source.header().sample_rate_hz;
  fmt::print(
      "replayed {} frames (about {:.1f} s of two feet) in {:.2f} s ({:.0f} x real time); steps {}, "
      "fits {} published ({} with failures); rejected {}, ring drops {}, refused {}, step drops "
      "{}; segmentation restarted at {} time gaps; {} messages lost (publishing failed)\n{}\n",
      c.frames_processed, session_s, wall_s, wall_s > 0.0 ? session_s / wall_s : 0.0,
      c.steps_detected, c.fits_published, c.fits_failed, c.frames_rejected, c.ring_drops,
      c.frames_refused, c.step_drops, c.segmentation_gaps,
      c.publish_failures + lcm.failed_publishes(), link.summary());
}

}  // namespace

void add_replay_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<ReplayArgs>();
  CLI::App* sub = app.add_subcommand(
      "replay",
      "Replays a session CSV through the live pipeline (fake driver, wire format, decoder, "
      "monitor, LCM); one line per fitted step and the regions' pooled tissue at the end. No "
      "argument: the bundled demo session");
  sub->add_option("session", args->session, "Session CSV v1 (default: the bundled demo)")
      ->check(session_file_read_twice());
  sub->add_option("--speed", args->speed, "x real time (default 1, at least 0.001), or max");
  sub->add_option("--lcm-url", args->lcm_url, "LCM URL (default: [lcm] url of the config)");
  sub->callback([&global, args] { run_replay(global, *args); });
}

}  // namespace gaitmon::cli
