// `gaitmon spy`: prints every gaitmon LCM message it receives as one JSON line, for people
// watching a live run and for scripts and tests that check what was published.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "commands.hpp"
#include "gaitmon/contact_ellipse.hpp"
#include "gaitmon/lcm_subscriber.hpp"
#include "live.hpp"

namespace gaitmon::cli {
namespace {

using nlohmann::json;

struct SpyArgs {
  std::vector<std::string> channels;
  std::string lcm_url;
  std::uint64_t count = 0;
  double timeout_s = 0.0;
};

json to_json(const FrameReport& r) {
  json regions = json::array();
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const RegionFrameReport& g = r.regions[i];
    regions.push_back(
        {{"region", region_name(kRegions[i])},
         {"force_n", g.force_n},
         {"active_area_mm2", g.active_area_mm2},
         {"ellipse_case", ellipse_case_name(static_cast<EllipseCase>(g.ellipse_case))},
         {"centre_x_mm", g.centre_x_mm},
         {"centre_y_mm", g.centre_y_mm},
         {"ra_mm", g.ra_mm},
         {"rb_mm", g.rb_mm},
         {"angle_rad", g.angle_rad},
         {"ellipse_area_mm2", g.ellipse_area_mm2}});
  }
  return {{"type", "frame_t"}, {"utime", r.utime}, {"foot", foot_name(r.foot)},
          {"frame", r.frame},  {"t_s", r.t_s},     {"regions", std::move(regions)}};
}

json to_json(const StepEvent& e) {
  return {{"type", "step_t"},
          {"utime", e.utime},
          {"foot", foot_name(e.foot)},
          {"step", e.step},
          {"kind", e.kind == StepEvent::Kind::HeelStrike ? "heel_strike" : "toe_off"},
          {"complete", e.complete},
          {"frame", e.frame},
          {"t_s", e.t_s}};
}

// A region's name, status, four tissue parameters and their standard errors, in its fit and in
// its pool.
template <typename RegionReport>
json region_json(const RegionReport& g) {
  return {{"region", region_name(g.region)},
          {"status", g.status},
          {"kbar_n_per_mm3", g.kbar_n_per_mm3},
          {"n", g.n},
          {"cbar_ns_per_mm3", g.cbar_ns_per_mm3},
          {"m", g.m},
          {"se_kbar", g.se_kbar},
          {"se_n", g.se_n},
          {"se_cbar", g.se_cbar},
          {"se_m", g.se_m}};
}

json to_json(const FitReport& r) {
  json regions = json::array();
  for (const RegionFitReport& g : r.regions) {
    json region = region_json(g);
    region.update({{"se_kbar_total", g.se_kbar_total},
                   {"se_n_total", g.se_n_total},
                   {"se_cbar_total", g.se_cbar_total},
                   {"se_m_total", g.se_m_total},
                   {"A_mm", g.A_mm},
                   {"B_mm", g.B_mm},
                   {"C_mm", g.C_mm},
                   {"d0_mm", g.d0_mm},
                   {"nrmse_pct", g.nrmse_pct},
                   {"m_steps", g.m_steps}});
    regions.push_back(std::move(region));
  }
  return {{"type", "fit_t"},
          {"utime", r.utime},
          {"foot", foot_name(r.foot)},
          {"step", r.step},
          {"t_heel_strike_s", r.t_heel_strike_s},
          {"t_toe_off_s", r.t_toe_off_s},
          {"nrmse_total_pct", r.nrmse_total_pct},
          {"latency_ms", r.latency_ms},
          {"effects_inside", r.effects_inside},
          {"effects_utime", r.effects_utime},
          {"regions", std::move(regions)}};
}

json to_json(const StatusReport& s) {
  return {{"type", "status_t"},
          {"utime", s.utime},
          {"connection", s.connection},
          {"bytes_received", s.bytes_received},
          {"frames_decoded", s.frames_decoded},
          {"crc_errors", s.crc_errors},
          {"resyncs", s.resyncs},
          {"frames_truncated", s.frames_truncated},
          {"header_errors", s.header_errors},
          {"frames_lost_sequence", s.frames_lost_sequence},
          {"sequence_restarts", s.sequence_restarts},
          {"reconnects", s.reconnects},
          {"transfers_overflowed", s.transfers_overflowed},
          {"ring_depth", s.ring_depth},
          {"ring_drops", s.ring_drops},
          {"frames_processed", s.frames_processed},
          {"frames_rejected", s.frames_rejected},
          {"segmentation_gaps", s.segmentation_gaps},
          {"steps_detected", s.steps_detected},
          {"step_backlog", s.step_backlog},
          {"step_drops", s.step_drops},
          {"fits_published", s.fits_published},
          {"fits_failed", s.fits_failed},
          {"fit_latency_p50_ms", s.fit_latency_p50_ms},
          {"fit_latency_p99_ms", s.fit_latency_p99_ms}};
}

json to_json(const RawFrameReport& r) {
  return {{"type", "raw_t"},
          {"utime", r.utime},
          {"foot", foot_name(r.foot)},
          {"sequence", r.sequence},
          {"device_time_us", r.device_time_us},
          {"bits", r.bits}};
}

json to_json(const EffectsReport& r) {
  json params = json::array();
  for (const EffectParamReport& p : r.params) {
    params.push_back({{"effect", p.effect}, {"name", p.name}, {"value", p.value}, {"se", p.se}});
  }
  return {{"type", "effects_t"},
          {"utime", r.utime},
          {"final_estimate", r.final_estimate},
          {"steps", r.steps},
          {"t_first_heel_strike_s", r.t_first_heel_strike_s},
          {"t_last_toe_off_s", r.t_last_toe_off_s},
          {"baseline_nrmse_pct", r.baseline_nrmse_pct},
          {"extended_nrmse_pct", r.extended_nrmse_pct},
          {"baseline_heldout_nrmse_pct", r.baseline_heldout_nrmse_pct},
          {"extended_heldout_nrmse_pct", r.extended_heldout_nrmse_pct},
          {"params", std::move(params)}};
}

json to_json(const TissueReport& r) {
  json regions = json::array();
  for (const RegionTissueReport& g : r.regions) {
    json region = region_json(g);
    region["steps"] = g.steps;
    regions.push_back(std::move(region));
  }
  return {{"type", "tissue_t"},
          {"utime", r.utime},
          {"final_estimate", r.final_estimate},
          {"foot", foot_name(r.foot)},
          {"step", r.step},
          {"t_first_heel_strike_s", r.t_first_heel_strike_s},
          {"t_last_toe_off_s", r.t_last_toe_off_s},
          {"regions", std::move(regions)}};
}

// Channel arguments may be the configured names or the message kinds; anything else is a usage
// error, as a typo on the command line is.
std::vector<std::string> resolve_channels(const LcmChannels& channels,
                                          const std::vector<std::string>& wanted) {
  const std::pair<std::string_view, const std::string*> known[] = {
      {"frame", &channels.frame},   {"step", &channels.step}, {"fit", &channels.fit},
      {"status", &channels.status}, {"raw", &channels.raw},   {"effects", &channels.effects},
      {"tissue", &channels.tissue}};
  std::vector<std::string> out;
  for (const std::string& name : wanted) {
    const auto match = std::find_if(std::begin(known), std::end(known), [&](const auto& k) {
      return name == k.first || name == *k.second;
    });
    if (match == std::end(known)) {
      throw CLI::ValidationError(
          "channels",
          fmt::format("\"{}\" is not a gaitmon channel: frame, step, fit, status, "
                      "raw, effects, tissue or the config's names {}, {}, {}, {}, "
                      "{}, {}, {}",
                      name, channels.frame, channels.step, channels.fit, channels.status,
                      channels.raw, channels.effects, channels.tissue));
    }
    out.push_back(*match->second);
  }
  return out;
}

void run_spy(const GlobalOptions& global, const SpyArgs& args) {
  LcmSettings settings = load_global_config(global).lcm;
  // Before LCM starts its threads, which inherit the blocked signals: Ctrl-C ends the loop below,
  // so that the closing line is printed.
  StopOnSignal on_signal("the spy", [](int) {});
  const FinishOnExit watching(on_signal);
  if (!args.lcm_url.empty()) settings.url = args.lcm_url;
  std::uint64_t received = 0;
  LcmSubscriber subscriber(
      open_lcm_url(global, settings.url, !args.lcm_url.empty()), settings,
      resolve_channels(settings.channels, args.channels),
      [&received](const std::string& channel, const LcmMessage& message) {
        json line = std::visit([](const auto& m) { return to_json(m); }, message);
        line["channel"] = channel;
        // A string off the bus need not be UTF-8.
        std::cout << line.dump(-1, ' ', false, json::error_handler_t::replace) << '\n'
                  << std::flush;
        ++received;
      });
  // On stderr, so stdout holds only messages: a script may start publishing once it sees this.
  fmt::print(stderr, "gaitmon spy: listening on {}\n", settings.url);
  std::fflush(stderr);

  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(args.timeout_s));
  while ((args.count == 0 || received < args.count) && on_signal.received() == 0) {
    // Short waits, so that a signal ends the loop soon.
    int wait_ms = 100;
    if (args.timeout_s > 0.0) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (left <= 0) break;
      wait_ms = static_cast<int>(std::min<long long>(left, wait_ms));
    }
    subscriber.handle(wait_ms);
  }
  fmt::print(stderr, "gaitmon spy: {} messages printed, {} malformed ones skipped\n", received,
             subscriber.decode_errors());
  if (args.count > 0 && received < args.count && on_signal.received() == 0) {
    throw std::runtime_error(
        fmt::format("spy: {} of {} messages within {} s", received, args.count, args.timeout_s));
  }
}

}  // namespace

void add_spy_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<SpyArgs>();
  CLI::App* sub = app.add_subcommand(
      "spy",
      "Print the gaitmon LCM messages as JSON lines (one per message, with its channel); runs "
      "until --count messages, --timeout-s or Ctrl-C");
  sub->add_option("channels", args->channels,
                  "Channels to print: the config's channel names, or frame, step, fit, status, "
                  "raw, effects, tissue (default: all seven)");
  sub->add_option("--lcm-url", args->lcm_url, "LCM URL (default: [lcm] url of the config)");
  sub->add_option("--count", args->count,
                  "Exit after this many messages (exit code 1 if --timeout-s comes first)")
      ->check(whole_number_in(1, std::numeric_limits<std::uint64_t>::max()));
  sub->add_option("--timeout-s", args->timeout_s, "Exit after this many seconds")
      // From 1 ms, the wait's resolution, to a deadline within the clock's range.
      ->check(number_in(0.001, 1e9));
  sub->callback([&global, args] { run_spy(global, *args); });
}

}  // namespace gaitmon::cli
