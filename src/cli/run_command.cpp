// `gaitmon run`: the live monitor on a real insole link, publishing over LCM.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <memory>
#include <string>

#include "commands.hpp"
#include "drivers/frame_decoder.hpp"
#include "gaitmon/lcm_publisher.hpp"
#include "gaitmon/monitor.hpp"
#include "live.hpp"

namespace gaitmon::cli {
namespace {

struct RunArgs {
  std::string serial;
  bool usb = false;
  std::string lcm_url;
};

void run_live(const GlobalOptions& global, const RunArgs& args) {
  Config config = load_global_config(global);
  if (!args.serial.empty()) config.serial.device = args.serial;
  if (!args.lcm_url.empty()) config.lcm.url = args.lcm_url;

  // Signals first: every thread started below inherits the blocked mask, those libusb starts
  // inside UsbSource's constructor included.
  std::unique_ptr<drivers::ByteSource> source;
  std::atomic<drivers::ByteSource*> live_source{nullptr};
  // Only the driver: offer() never waits, so the monitor is closed once the driver has
  // returned, and the frames it decodes until then are not refused.
  StopOnSignal on_signal("the driver, then the ring, the fits and a final status", [&](int) {
    if (drivers::ByteSource* s = live_source.load()) s->stop();
  });
  source = make_insole_source(config, args.usb);
  live_source.store(source.get());

  LcmPublisher lcm(open_lcm_url(global, config.lcm.url, !args.lcm_url.empty()), config.lcm);
  StepPrinter printer(lcm);
  drivers::FrameDecoder decoder{drivers::WireFormat(config.wire)};
  LinkStatus link(decoder, *source);
  MonitorOptions options;
  options.sample_rate_hz = config.sample_rate_hz;
  options.publish_raw = config.lcm.raw_enabled;
  options.analysis.area = live_area_source(config.model);
  options.backlog_overflow = BacklogOverflow::DropOldest;
  options.driver_status = [&](StatusReport& status) {
    link.fill(status);
    link.warn_of_overflows();
  };
  Monitor monitor(config, options, printer);
  spdlog::info("run: {} -> LCM {}", insole_source_name(config, args.usb), config.lcm.url);

  // The driver thread is this one: bytes -> decoder -> ring. offer() never waits; a full ring
  // drops the frame and counts it.
  // A signal that came before live_source was set found nothing to stop.
  if (on_signal.received() == 0) {
    source->run(
        [&](std::span<const std::uint8_t> bytes) {
          decoder.feed(bytes, [&](const SensorFrame& frame) { (void)monitor.offer(frame); });
        },
        [&](drivers::LinkState state, std::string_view detail) { link.on_state(state, detail); });
  }
  on_signal.finish();
  // An interrupted run: the effects' running fit stops and the latest estimate is the final one.
  if (on_signal.received() != 0) monitor.close();
  monitor.stop();
  const MonitorCounters c = monitor.counters();
  fmt::print(
      "frames {} processed, {} rejected, {} dropped (ring full), {} refused (monitor closed); "
      "segmentation restarted at {} time gaps; steps {} ({} dropped from the backlog); fits {} "
      "published, {} with failures; {} messages lost (publishing failed)\n{}\n",
      c.frames_processed, c.frames_rejected, c.ring_drops, c.frames_refused, c.segmentation_gaps,
      c.steps_detected, c.step_drops, c.fits_published, c.fits_failed,
      c.publish_failures + lcm.failed_publishes(), link.summary());
}

}  // namespace

void add_run_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* sub = app.add_subcommand(
      "run",
      "The live monitor: reads an insole link, segments steps, fits every step and publishes "
      "over LCM; one line per fitted step and the regions' pooled tissue at the end. Ctrl-C stops "
      "it cleanly");
  CLI::Option* serial =
      sub->add_option("--serial", args->serial,
                      "Serial device (default: [serial] device of the config), e.g. the pty "
                      "`gaitmon fake-insole --pty` prints");
  sub->add_flag("--usb", args->usb, "Read the insole over USB ([usb] of the config)")
      ->excludes(serial);
  sub->add_option("--lcm-url", args->lcm_url, "LCM URL (default: [lcm] url of the config)");
  sub->callback([&global, args] { run_live(global, *args); });
}

}  // namespace gaitmon::cli
