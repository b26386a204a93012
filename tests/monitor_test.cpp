// The live monitor against the batch pipeline: the same steps as segment_session, the same fits
// as analyse_step, and the overflow, drop, rejection and shutdown rules of monitor.hpp.
#include "gaitmon/monitor.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <regex>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "allocation_count.hpp"
#include "gaitmon/analysis.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/simulator.hpp"
#include "log_capture.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using test::RecordingPublisher;
using ::testing::HasSubstr;
using ::testing::Not;

using test::shipped_config;

// The first 30 s of the bundled demo: about 50 analysed steps, enough for every rule and short
// enough for the sanitizer builds.
fs::path demo_30s() {
  static const fs::path path = test::cut_session(
      test::demo_session(), test::scratch_dir("monitor-demo") / "demo30.csv", 30.0);
  return path;
}

std::vector<Step> batch_steps(const fs::path& session, const Config& config) {
  std::vector<Step> steps;
  segment_session(session, config, [&](Step&& step) { steps.push_back(std::move(step)); });
  return steps;
}

// The complete steps, in the order the segmenters finalise them: the monitor's for frames in
// file order.
std::vector<Step> complete_steps(const fs::path& session, const Config& config) {
  std::vector<Step> ok;
  for (Step& step : batch_steps(session, config)) {
    if (step.status == StepStatus::Ok) ok.push_back(std::move(step));
  }
  return ok;
}

// Fits cut short (one start, five iterations): for tests about the plumbing, not the numbers.
AnalysisSettings quick_fits() {
  AnalysisSettings settings;
  settings.fit.starts = 1;
  settings.fit.max_iterations = 5;
  return settings;
}

// A replay's options (nothing dropped) with fits cut short.
MonitorOptions quick_replay() {
  MonitorOptions options;
  options.analysis = quick_fits();
  options.backlog_overflow = BacklogOverflow::Wait;
  return options;
}

void offer_all(Monitor& monitor, const std::vector<SensorFrame>& frames) {
  for (const SensorFrame& frame : frames) {
    if (!monitor.offer_wait(frame)) {
      ADD_FAILURE() << "the monitor refused a frame";
      return;
    }
  }
}

std::size_t count_of(const std::string& text, std::string_view what) {
  std::size_t count = 0;
  for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++count;
  return count;
}

// Polls `done` every millisecond for up to 60 s.
bool wait_until(const std::function<bool()>& done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

std::string expected_status(const RegionFit& fit) {
  std::string s(fit_status_name(fit.status));
  if (fit.status == FitStatus::Failed) s += ":" + fit.reason;
  return s;
}

void expect_close(double actual, double expected, const std::string& what) {
  if (!std::isfinite(expected)) {  // an undetermined standard error is infinite
    EXPECT_EQ(actual, expected) << what;
    return;
  }
  EXPECT_NEAR(actual, expected, 1e-9 * std::max(1.0, std::abs(expected))) << what;
}

// What GAITMON_FIT's se_*_total should be for `fit` of `region`, worked from the config's chain
// and step SDs (those of `area`'s tables): ln kbar's and ln cbar's variances are (se / value)^2;
// at a declared (running) m
// its own variance and [pooling.m_per_session]'s chain SD of m reach the others through their
// slopes. At the step's own m a variance v of m beyond the range's, range^2 / 3, is held there,
// and each other's share of it, c^2 / v with c its covariance with m, shrinks to c^2 range^2 /
// (3 v^2). Zeros where the fit has no covariance of its four parameters.
std::array<double, 4> expected_total_se(const RegionFit& fit, Region region, const Config& config,
                                        AreaSource area) {
  if (!fit.material_covariance) return {0.0, 0.0, 0.0, 0.0};
  const bool shared = !fit.m.free;
  const PoolingSettings& tables =
      area == AreaSource::FootprintMean ? config.pooling_footprint_mean : config.pooling;
  const ChainSds& chain = shared ? tables.m_per_session : tables.per_step;
  const std::size_t ri = index_of(region);
  const double m_variance =
      fit.m.se * fit.m.se + (shared ? chain.m_chain_sd[ri] * chain.m_chain_sd[ri] : 0.0);
  const std::array<double, 3> slope =
      shared ? *fit.material_slope_on_m : std::array<double, 3>{0.0, 0.0, 0.0};
  const double range = config.fit_bounds.m.upper - config.fit_bounds.m.lower;
  const double held = range * range / 3.0;
  const double v = fit.m.se * fit.m.se;
  const bool hold = !shared && v > held;
  const MaterialCovariance& c = *fit.material_covariance;
  const auto less = [&](std::size_t p) {
    return hold ? c[p][3] * c[p][3] * (v - held) / (v * v) : 0.0;
  };
  const auto total = [&](double relative_se, double sd, double step, double g, double minus) {
    return std::sqrt(relative_se * relative_se - minus + sd * sd + step * step +
                     g * g * m_variance);
  };
  const double kbar = fit.kbar_n_per_mm3.value, cbar = fit.cbar_ns_per_mm3.value;
  return {kbar * total(fit.kbar_n_per_mm3.se / kbar, chain.kbar_chain_sd_pct[ri] / 100,
                       chain.kbar_step_sd_pct[ri] / 100, slope[0], less(0)),
          total(fit.n.se, chain.n_chain_sd[ri], chain.n_step_sd[ri], slope[1], less(1)),
          cbar * total(fit.cbar_ns_per_mm3.se / cbar, chain.cbar_chain_sd_pct[ri] / 100,
                       chain.cbar_step_sd_pct[ri] / 100, slope[2], less(2)),
          shared ? std::hypot(std::sqrt(m_variance), chain.m_step_sd[ri])
                 : std::sqrt((hold ? held : v) + chain.m_chain_sd[ri] * chain.m_chain_sd[ri] +
                             chain.m_step_sd[ri] * chain.m_step_sd[ri])};
}

void expect_total_se(const RegionFitReport& got, const RegionFit& fit, Region region,
                     const Config& config, const std::string& where,
                     AreaSource area = AreaSource::Footprint) {
  const std::array<double, 4> e = expected_total_se(fit, region, config, area);
  expect_close(got.se_kbar_total, e[0], where + " se_kbar_total");
  expect_close(got.se_n_total, e[1], where + " se_n_total");
  expect_close(got.se_cbar_total, e[2], where + " se_cbar_total");
  expect_close(got.se_m_total, e[3], where + " se_m_total");
}

using StepKey = std::pair<Foot, int>;

// The monitor's step events against the batch pipeline's steps: a heel strike and a toe off per
// step, per foot in step order, at the same frames and times. `ok_steps` counts the Ok steps.
void expect_events_of(const std::vector<StepEvent>& events, const std::vector<Step>& steps,
                      std::size_t& ok_steps) {
  std::map<StepKey, std::pair<StepEvent, StepEvent>> by_step;
  std::map<Foot, int> last_step{{Foot::Left, -1}, {Foot::Right, -1}};
  for (std::size_t i = 0; i + 1 < events.size(); i += 2) {
    const StepEvent& hs = events[i];
    const StepEvent& to = events[i + 1];
    ASSERT_EQ(hs.kind, StepEvent::Kind::HeelStrike);
    ASSERT_EQ(to.kind, StepEvent::Kind::ToeOff);
    ASSERT_EQ(hs.foot, to.foot);
    ASSERT_EQ(hs.step, to.step);
    EXPECT_EQ(hs.step, last_step[hs.foot] + 1);
    last_step[hs.foot] = hs.step;
    by_step[{hs.foot, hs.step}] = {hs, to};
  }
  ASSERT_EQ(events.size(), 2 * steps.size());
  ASSERT_EQ(by_step.size(), steps.size());
  ok_steps = 0;
  for (const Step& step : steps) {
    const auto it = by_step.find({step.foot, step.index});
    ASSERT_NE(it, by_step.end()) << foot_name(step.foot) << step.index;
    const auto& [hs, to] = it->second;
    EXPECT_EQ(hs.frame, step.heel_strike_frame);
    EXPECT_EQ(to.frame, step.toe_off_frame);
    // round(t_s x 1e6) / 1e6 gives back the file's t_s exactly (times have at most 6 decimals).
    EXPECT_EQ(hs.t_s, step.t_heel_strike_s);
    EXPECT_EQ(to.t_s, step.t_toe_off_s);
    EXPECT_EQ(hs.complete, step.status == StepStatus::Ok);
    EXPECT_EQ(to.complete, step.status == StepStatus::Ok);
    if (step.status == StepStatus::Ok) ++ok_steps;
  }
}

TEST(Monitor, StepsAndFitsEqualTheBatchPipeline) {
  const Config config = shipped_config();
  const std::vector<Step> steps = batch_steps(demo_30s(), config);
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s(), &header);

  RecordingPublisher publisher;
  MonitorOptions options;
  options.sample_rate_hz = header.sample_rate_hz;
  options.backlog_overflow = BacklogOverflow::Wait;
  MonitorCounters counters;
  {
    Monitor monitor(config, options, publisher);
    for (const SensorFrame& frame : frames) ASSERT_TRUE(monitor.offer_wait(frame));
    monitor.stop();
    counters = monitor.counters();
    EXPECT_FALSE(monitor.offer(frames.front())) << "a stopped monitor accepts nothing";
  }

  std::size_t ok_steps = 0;
  ASSERT_NO_FATAL_FAILURE(expect_events_of(publisher.events(), steps, ok_steps));
  ASSERT_GT(ok_steps, 20u);

  // Fits: one per Ok step, per foot in step order, equal to analyse_step run directly.
  const auto fits = publisher.fits();
  ASSERT_EQ(fits.size(), ok_steps);
  std::map<Foot, int> last_fit{{Foot::Left, -1}, {Foot::Right, -1}};
  std::map<StepKey, FitReport> fit_of;
  for (const FitReport& fit : fits) {
    EXPECT_GT(fit.step, last_fit[fit.foot]) << "fits out of step order";
    last_fit[fit.foot] = fit.step;
    EXPECT_GE(fit.latency_ms, 0.0);
    fit_of[{fit.foot, fit.step}] = fit;
  }
  const InsoleLayout layout(config.insole(header.insole_size), config.sensor);
  std::vector<StepAnalysis> analysed;
  for (const Step& step : steps) {
    if (step.status != StepStatus::Ok) continue;
    const StepAnalysis& expected =
        analysed.emplace_back(analyse_step(step, layout, config, options.analysis));
    const auto it = fit_of.find({step.foot, step.index});
    ASSERT_NE(it, fit_of.end());
    const FitReport& got = it->second;
    const std::string at = fmt::format("{} step {}", foot_name(step.foot), step.index);
    EXPECT_EQ(got.t_heel_strike_s, expected.t_heel_strike_s) << at;
    EXPECT_EQ(got.t_toe_off_s, expected.t_toe_off_s) << at;
    expect_close(got.nrmse_total_pct, expected.nrmse_total_pct, at + " nrmse_total");
    for (const RegionAnalysis& r : expected.regions) {
      const RegionFitReport& g = got.regions[index_of(r.region)];
      const std::string where = at + " " + std::string(region_name(r.region));
      EXPECT_EQ(g.region, r.region) << where;
      EXPECT_EQ(g.status, expected_status(r.fit)) << where;
      if (r.fit.status != FitStatus::Ok) continue;
      expect_close(g.kbar_n_per_mm3, r.fit.kbar_n_per_mm3.value, where + " kbar");
      expect_close(g.n, r.fit.n.value, where + " n");
      expect_close(g.cbar_ns_per_mm3, r.fit.cbar_ns_per_mm3.value, where + " cbar");
      expect_close(g.m, r.fit.m.value, where + " m");
      expect_close(g.se_kbar, r.fit.kbar_n_per_mm3.se, where + " se_kbar");
      expect_close(g.se_m, r.fit.m.se, where + " se_m");
      expect_total_se(g, r.fit, r.region, config, where);
      expect_close(g.A_mm, r.fit.A_mm.value, where + " A");
      expect_close(g.B_mm, r.fit.B_mm.value, where + " B");
      expect_close(g.C_mm, r.fit.C_mm.value, where + " C");
      expect_close(g.d0_mm, r.fit.d0_mm.value, where + " d0");
      expect_close(g.nrmse_pct, r.fit.nrmse_pct, where + " nrmse");
    }
  }

  // The regions' tissue: the last one, marked final, is every step pooled as `analyze` pools a
  // session (the window of 400 holds them all), at the last step to finish.
  const auto tissues = publisher.tissues();
  ASSERT_GE(tissues.size(), 2u);
  EXPECT_EQ(std::count_if(tissues.begin(), tissues.end(),
                          [](const TissueReport& t) { return t.final_estimate; }),
            1);
  const TissueReport& final_tissue = tissues.back();
  EXPECT_TRUE(final_tissue.final_estimate);
  EXPECT_EQ(final_tissue.t_first_heel_strike_s, analysed.front().t_heel_strike_s);
  double last_toe_off = 0.0;
  for (const StepAnalysis& a : analysed) last_toe_off = std::max(last_toe_off, a.t_toe_off_s);
  EXPECT_EQ(final_tissue.t_last_toe_off_s, last_toe_off);
  const SessionAnalysis session =
      analyse_session(analysed, config, header.insole_size, options.analysis);
  int pooled_regions = 0;
  for (const RegionSessionAnalysis& r : session.regions) {
    const RegionTissueReport& got = final_tissue.regions[index_of(r.region)];
    const std::string where(region_name(r.region));
    EXPECT_EQ(got.region, r.region) << where;
    EXPECT_EQ(got.steps, static_cast<int>(r.pooling.steps.size())) << where;
    if (!r.pooled_mean) {
      EXPECT_EQ(got.status, "not_pooled:" + r.pooling.not_pooled) << where;
      continue;
    }
    ++pooled_regions;
    EXPECT_EQ(got.status, "ok") << where;
    const MaterialParams p = material_params(*r.pooled_mean);
    // The pool's sums run in another order here (the workers' finishing order's window).
    const auto near = [&](double actual, const Estimate& expected, const char* what) {
      EXPECT_NEAR(actual, expected.value, 1e-8 * std::abs(expected.value)) << where << what;
    };
    near(got.kbar_n_per_mm3, p.kbar_n_per_mm3, " kbar");
    near(got.n, p.n, " n");
    near(got.cbar_ns_per_mm3, p.cbar_ns_per_mm3, " cbar");
    near(got.m, p.m, " m");
    EXPECT_NEAR(got.se_kbar, p.kbar_n_per_mm3.se, 1e-8 * p.kbar_n_per_mm3.se) << where;
    EXPECT_NEAR(got.se_n, p.n.se, 1e-8 * p.n.se) << where;
    EXPECT_NEAR(got.se_cbar, p.cbar_ns_per_mm3.se, 1e-8 * p.cbar_ns_per_mm3.se) << where;
    EXPECT_NEAR(got.se_m, p.m.se, 1e-8 * p.m.se) << where;
    // With the chain's SD: never narrower than [pooling]'s share of ln kbar alone.
    EXPECT_GE(got.se_kbar / got.kbar_n_per_mm3,
              config.pooling.per_step.kbar_chain_sd_pct[index_of(r.region)] / 100.0)
        << where;
  }
  EXPECT_GE(pooled_regions, 5) << "the heel, midfoot and metatarsals";
  for (std::size_t i = 1; i < tissues.size(); ++i) {
    EXPECT_GE(tissues[i].regions[0].steps, tissues[i - 1].regions[0].steps)
        << "a window below its 400 steps only grows";
  }

  // Frames: one report per frame, numbered per foot, at the file's times.
  const auto reports = publisher.frames();
  ASSERT_EQ(reports.size(), frames.size());
  std::map<Foot, std::int64_t> next_frame{{Foot::Left, 0}, {Foot::Right, 0}};
  for (std::size_t i = 0; i < reports.size(); ++i) {
    ASSERT_EQ(reports[i].foot, frames[i].foot);
    ASSERT_EQ(reports[i].frame, next_frame[reports[i].foot]++);
    ASSERT_DOUBLE_EQ(reports[i].t_s, frames[i].device_time_us / 1e6);
  }
  // Before a foot's first step there is no bias: the heel's force is its raw bits x 0.28235 N.
  int heel_bits = 0;
  for (std::size_t s : layout.region_sensors(Region::Heel)) heel_bits += frames[0].bits[s];
  EXPECT_NEAR(reports[0].regions[index_of(Region::Heel)].force_n, heel_bits * 0.282353, 1e-3);
  EXPECT_DOUBLE_EQ(reports[0].regions[index_of(Region::Heel)].active_area_mm2,
                   112.5 * static_cast<double>([&] {
                     int active = 0;
                     for (std::size_t s : layout.region_sensors(Region::Heel)) {
                       active += frames[0].bits[s] > 0;
                     }
                     return active;
                   }()));

  // Counters, and the final status as the last message.
  EXPECT_EQ(counters.frames_offered, frames.size());
  EXPECT_EQ(counters.frames_processed, frames.size());
  EXPECT_EQ(counters.frames_rejected, 0u);
  EXPECT_EQ(counters.ring_drops, 0u);
  EXPECT_EQ(counters.steps_detected, steps.size());
  EXPECT_EQ(counters.steps_queued, ok_steps);
  EXPECT_EQ(counters.step_drops, 0u);
  EXPECT_EQ(counters.fits_published, ok_steps);
  const auto order = publisher.order();
  ASSERT_FALSE(order.empty());
  EXPECT_EQ(order.back(), RecordingPublisher::Kind::Status);
  const StatusReport last = publisher.statuses().back();
  EXPECT_EQ(last.connection, "finished");
  EXPECT_EQ(last.frames_processed, frames.size());
  EXPECT_EQ(last.fits_published, ok_steps);
  EXPECT_EQ(last.steps_detected, steps.size());
  EXPECT_EQ(last.step_backlog, 0u);
  EXPECT_GT(last.fit_latency_p99_ms, 0.0);
  EXPECT_GE(last.fit_latency_p99_ms, last.fit_latency_p50_ms);
}

TEST(Monitor, TheTissueIsPooledOverTheLatestStepsOfTheWindow) {
  Config config = shipped_config();
  config.monitor.tissue_window_steps = 8;
  const std::vector<Step> ok = complete_steps(demo_30s(), config);
  ASSERT_GT(ok.size(), 20u);
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s(), &header);
  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  options.sample_rate_hz = header.sample_rate_hz;
  {
    Monitor monitor(config, options, publisher);
    offer_all(monitor, frames);
    monitor.stop();
  }
  const auto tissues = publisher.tissues();
  ASSERT_GE(tissues.size(), 2u);
  for (const TissueReport& t : tissues) {
    for (const RegionTissueReport& r : t.regions) EXPECT_LE(r.steps, 8) << region_name(r.region);
  }
  // The last eight steps the segmenters finalised, of both feet.
  const TissueReport& last = tissues.back();
  ASSERT_TRUE(last.final_estimate);
  const std::span<const Step> window(ok.end() - 8, ok.end());
  double first = window.front().t_heel_strike_s;
  for (const Step& step : window) first = std::min(first, step.t_heel_strike_s);
  EXPECT_EQ(last.t_first_heel_strike_s, first);
  EXPECT_EQ(last.regions[index_of(Region::Heel)].steps, 8);
  EXPECT_EQ(last.regions[index_of(Region::Heel)].status, "ok");
  EXPECT_EQ(publisher.order().back(), RecordingPublisher::Kind::Status)
      << "the final status after the final tissue";
}

TEST(Monitor, EveryStepHasATissueReportWhenStepsComeNoFasterThanWalking) {
  Config config = shipped_config();
  config.monitor.workers = 1;
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s(), &header);
  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  options.sample_rate_hz = header.sample_rate_hz;
  std::size_t events_seen = 0, steps = 0;
  {
    Monitor monitor(config, options, publisher);
    std::uint64_t offered = 0;
    for (const SensorFrame& frame : frames) {
      ASSERT_TRUE(monitor.offer_wait(frame));
      ++offered;
      while (monitor.counters().frames_processed < offered) std::this_thread::yield();
      // A step is finalised when its events are published; no frame more comes until its
      // report, as at real time, where steps are a quarter of a second apart or more.
      const auto events = publisher.events();
      for (; events_seen < events.size(); ++events_seen) {
        const StepEvent& e = events[events_seen];
        if (e.kind != StepEvent::Kind::ToeOff || !e.complete) continue;
        ++steps;
        ASSERT_TRUE(wait_until([&] {
          const auto tissues = publisher.tissues();
          return std::any_of(tissues.begin(), tissues.end(), [&](const TissueReport& t) {
            return t.foot == e.foot && t.step == e.step;
          });
        })) << foot_name(e.foot)
            << " step " << e.step;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
    }
    monitor.stop();
  }
  EXPECT_GT(steps, 20u);
  // The steps the end of input finalises come after the loop; at most one report per fit besides
  // the final one.
  EXPECT_GE(publisher.tissues().size(), steps + 1);
  EXPECT_LE(publisher.tissues().size(), publisher.fits().size() + 1);
}

// A live fit cannot wait for the session's evidence of how its cells read, as analyze's auto
// does, so [model] area "auto" is the footprint live, and the monitor names the footprint the
// cells call for once its steps show it: a warning where the fits take the other kind, else one
// line at info. The raster is the simulator's, not the code's guess. Each fit's standard errors
// against the tissue take the chain's SDs of the area it was fitted on.
TEST(Monitor, NamesTheFootprintTheCellsCallForOnceTheirStepsShowIt) {
  EXPECT_EQ(live_area_source(ModelSettings{}), AreaSource::Footprint);
  ModelSettings model;
  model.area = "footprint-mean";
  EXPECT_EQ(live_area_source(model), AreaSource::FootprintMean);
  model.area = "cells";
  EXPECT_THROW(live_area_source(model), std::invalid_argument);

  const Config config = shipped_config();
  ASSERT_NE(config.pooling_footprint_mean.per_step.kbar_chain_sd_pct[index_of(Region::Heel)],
            config.pooling.per_step.kbar_chain_sd_pct[index_of(Region::Heel)]);
  const fs::path dir = test::scratch_dir("monitor-cells");
  for (const Rasterisation raster : {Rasterisation::CellCentre, Rasterisation::Coverage}) {
    SimulationOptions simulation;
    simulation.size = InsoleSize::S41_42;
    simulation.duration_s = 8.0;
    simulation.seed = 21;
    simulation.rasterisation = raster;
    const fs::path csv = dir / (std::string(rasterisation_name(raster)) + ".csv");
    simulate_session(config, simulation, csv, fs::path(csv).replace_extension(".json"));
    SessionHeader header;
    const std::vector<SensorFrame> frames = test::session_frames(csv, &header);
    const bool averaging = raster == Rasterisation::Coverage;
    for (const AreaSource area : {AreaSource::Footprint, AreaSource::FootprintMean}) {
      const test::LogCapture log;
      RecordingPublisher publisher;
      MonitorOptions options = quick_replay();
      options.analysis.area = area;
      options.sample_rate_hz = header.sample_rate_hz;
      {
        Monitor monitor(config, options, publisher);
        offer_all(monitor, frames);
        monitor.stop();
      }
      const std::string text = log.text.str();
      const std::string what =
          fmt::format("{} raster, {} area", rasterisation_name(raster), area_source_name(area));
      // The fits' standard errors against the tissue take the chain's SDs of the area they were
      // fitted on ([pooling.footprint_mean] on footprint-mean), which differ.
      const std::vector<Step> steps = batch_steps(csv, config);
      const InsoleLayout layout(config.insole(header.insole_size), config.sensor);
      std::map<StepKey, FitReport> fit_of;
      for (const FitReport& fit : publisher.fits()) fit_of[{fit.foot, fit.step}] = fit;
      std::size_t compared = 0;
      for (const Step& step : steps) {
        if (step.status != StepStatus::Ok || compared >= 4) continue;
        const StepAnalysis expected = analyse_step(step, layout, config, options.analysis);
        const auto it = fit_of.find({step.foot, step.index});
        ASSERT_NE(it, fit_of.end()) << what;
        ++compared;
        for (const RegionAnalysis& r : expected.regions) {
          if (r.fit.status != FitStatus::Ok) continue;
          expect_total_se(it->second.regions[index_of(r.region)], r.fit, r.region, config,
                          fmt::format("{}, {} step {} {}", what, foot_name(step.foot), step.index,
                                      region_name(r.region)),
                          area);
        }
      }
      EXPECT_EQ(compared, 4u) << what;
      EXPECT_EQ(count_of(text, "monitor: the cells read the pressure"), 1u) << what << "\n" << text;
      EXPECT_THAT(text, HasSubstr(averaging ? "read the pressure averaged over their area"
                                            : "read the pressure at their centres"))
          << what;
      const bool other_kind = averaging != (area == AreaSource::FootprintMean);
      if (other_kind) {
        EXPECT_THAT(text, HasSubstr(averaging ? R"(set [model] area = "footprint-mean")"
                                              : R"(set [model] area = "footprint")"))
            << what;
        EXPECT_THAT(text, HasSubstr("warn")) << what;
      } else {
        EXPECT_THAT(text,
                    HasSubstr(fmt::format("the fits take the {} area", area_source_name(area))))
            << what;
        EXPECT_THAT(text, Not(HasSubstr("set [model] area"))) << what;
      }
      EXPECT_THAT(text, Not(HasSubstr("a crosstalk of"))) << what;
    }
  }
}

// Crosstalk spreads a cap's readings as averaging cells do; the monitor weighs the cells with it
// undone, names the raster's reading, and warns once that [model] effects leave the crosstalk
// its cells show out. Centre raster, coupling 0.1, the monitor's default area.
TEST(Monitor, WarnsOnceWhereTheCellsShowCrosstalkTheEffectsLeaveOut) {
  const Config config = shipped_config();
  const fs::path dir = test::scratch_dir("monitor-cells-crosstalk");
  SimulationOptions simulation;
  simulation.size = InsoleSize::S41_42;
  simulation.duration_s = 8.0;
  simulation.seed = 21;
  simulation.effects = {"crosstalk"};
  simulation.effect_params["crosstalk"] = {{"coupling", 0.1}};
  const fs::path csv = dir / "crosstalk.csv";
  simulate_session(config, simulation, csv, dir / "crosstalk.json");
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(csv, &header);
  const test::LogCapture log;
  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  options.sample_rate_hz = header.sample_rate_hz;
  {
    Monitor monitor(config, options, publisher);
    offer_all(monitor, frames);
    monitor.stop();
  }
  const std::string text = log.text.str();
  const std::string warning =
      "monitor: the cells' readings fit their caps best with a crosstalk of ";
  ASSERT_EQ(count_of(text, warning), 1u) << text;
  EXPECT_NEAR(std::stod(text.substr(text.find(warning) + warning.size())), 0.1, 0.012) << text;
  EXPECT_THAT(text, HasSubstr(R"(add "crosstalk" to [model] effects to fit it)")) << text;
  EXPECT_THAT(text, HasSubstr("read the pressure at their centres")) << text;
}

TEST(Monitor, TheTissueIsNotPooledOutsideTheDefaultFit) {
  const Config config = shipped_config();
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s(), &header);
  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  options.sample_rate_hz = header.sample_rate_hz;
  options.analysis.fit.mode = FitMode::Seed8;
  {
    Monitor monitor(config, options, publisher);
    offer_all(monitor, frames);
    monitor.stop();
  }
  const auto tissues = publisher.tissues();
  ASSERT_FALSE(tissues.empty());
  for (const RegionTissueReport& r : tissues.back().regions) {
    EXPECT_EQ(r.status, "not_pooled:pooling needs the default fit (identifiable, P declared)");
  }
}

// Holds the first message of one kind inside publish() until released, keeping its thread busy.
template <typename Gated>
class GatedPublisher : public RecordingPublisher {
 public:
  void publish(const Gated& r) override {
    if (entered_.fetch_add(1) == 0) {
      std::unique_lock lock(mutex_);
      open_cv_.wait(lock, [&] { return open_; });
    }
    RecordingPublisher::publish(r);
  }
  using RecordingPublisher::publish;
  int entered() const { return entered_.load(); }
  void release() {
    {
      const std::lock_guard lock(mutex_);
      open_ = true;
    }
    open_cv_.notify_all();
  }

 private:
  std::atomic<int> entered_{0};
  std::mutex mutex_;
  std::condition_variable open_cv_;
  bool open_ = false;
};

TEST(Monitor, BacklogOverflowDropsTheOldestWaitingSteps) {
  Config config = shipped_config();
  config.monitor.workers = 1;
  config.monitor.max_step_backlog = 2;
  config.monitor.publish_frames = false;
  std::vector<StepKey> ok_order;  // the order in which the detector finalises Ok steps
  for (const Step& step : batch_steps(demo_30s(), config)) {
    if (step.status == StepStatus::Ok) ok_order.emplace_back(step.foot, step.index);
  }
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  // The first fit held: the single worker is busy while the detector queues more steps than the
  // backlog holds.
  GatedPublisher<FitReport> publisher;
  const test::LogCapture log;
  Monitor monitor(config, MonitorOptions{}, publisher);

  // Feed frame by frame until the first step is queued, and let the worker take it.
  std::size_t fed = 0;
  while (monitor.counters().steps_queued == 0) {
    ASSERT_LT(fed, frames.size());
    ASSERT_TRUE(monitor.offer_wait(frames[fed++]));
    ASSERT_TRUE(wait_until([&] { return monitor.counters().frames_processed == fed; }));
  }
  ASSERT_TRUE(wait_until([&] { return publisher.entered() == 1; }));
  EXPECT_EQ(monitor.counters().step_backlog, 0u);

  // The worker is stuck publishing step 0: every later step but the newest two is dropped,
  // including those that stop() finalises at the end of the stream.
  while (fed < frames.size()) ASSERT_TRUE(monitor.offer_wait(frames[fed++]));
  std::thread stopper([&] { monitor.stop(); });
  const std::size_t queued = ok_order.size();
  ASSERT_GE(queued, 10u);
  ASSERT_TRUE(wait_until([&] { return monitor.counters().steps_queued == queued; }));
  const MonitorCounters held = monitor.counters();
  EXPECT_EQ(held.step_backlog, 2u);
  EXPECT_EQ(held.step_drops, queued - 3);
  EXPECT_EQ(held.fits_published, 0u);
  publisher.release();
  stopper.join();

  const MonitorCounters end = monitor.counters();
  EXPECT_EQ(end.step_drops, queued - 3);
  EXPECT_EQ(end.fits_published, 3u);
  EXPECT_EQ(publisher.statuses().back().step_drops, queued - 3);
  std::vector<StepKey> published;
  for (const FitReport& fit : publisher.fits()) published.emplace_back(fit.foot, fit.step);
  std::vector<StepKey> expected{ok_order[0], ok_order[queued - 2], ok_order[queued - 1]};
  std::sort(published.begin(), published.end());
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(published, expected);
  // The first drop (the rest follow within the second).
  EXPECT_THAT(log.text.str(),
              testing::HasSubstr(fmt::format(
                  "monitor: dropped foot {} step {}: the step backlog is full ([monitor] "
                  "max_step_backlog); 1 dropped so far",
                  foot_name(ok_order[1].first), ok_order[1].second)));
}

TEST(Monitor, FullRingDropsAndCountsFrames) {
  Config config = shipped_config();
  config.ring.capacity_frames = 8;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  RecordingPublisher publisher;
  MonitorOptions options;
  options.analysis = quick_fits();
  options.publish_raw = true;
  const test::LogCapture log;
  Monitor monitor(config, options, publisher);
  std::uint64_t refused = 0;
  for (const SensorFrame& frame : frames) refused += monitor.offer(frame) ? 0 : 1;
  monitor.stop();
  const MonitorCounters c = monitor.counters();
  ASSERT_GT(refused, 0u) << "the detector kept up with an 8-frame ring; nothing was exercised";
  // Logged too, however short the run: the last status period's drops at the end.
  const std::string text = log.text.str();
  EXPECT_NE(text.find("monitor: ring full: "), std::string::npos) << text;
  EXPECT_NE(text.find(fmt::format(", {} in all", refused)), std::string::npos) << text;
  EXPECT_EQ(c.ring_drops, refused);
  EXPECT_EQ(c.frames_offered, frames.size());
  EXPECT_EQ(c.frames_processed + c.ring_drops, frames.size());
  EXPECT_EQ(c.frames_rejected, 0u);
  EXPECT_EQ(publisher.frames().size(), c.frames_processed);
  const auto raws = publisher.raws();
  ASSERT_EQ(raws.size(), c.frames_processed);
  // The ring was empty when the first frame came, so it is the first one out.
  EXPECT_EQ(raws[0].sequence, frames[0].sequence);
  EXPECT_EQ(raws[0].device_time_us, frames[0].device_time_us);
  EXPECT_TRUE(std::equal(raws[0].bits.begin(), raws[0].bits.end(), frames[0].bits.begin()));
  EXPECT_EQ(raws[0].bits.size(), frames[0].sensor_count);
  const StatusReport last = publisher.statuses().back();
  EXPECT_EQ(last.ring_drops, refused);
  EXPECT_EQ(last.frames_processed, frames.size() - refused);
}

TEST(Monitor, StopDrainsTheRingFinishesTheFitsAndPublishesAFinalStatus) {
  const Config config = shipped_config();
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  const std::size_t n = std::min<std::size_t>(frames.size(), config.ring.capacity_frames);
  RecordingPublisher publisher;
  MonitorOptions options;
  options.analysis = quick_fits();
  Monitor monitor(config, options, publisher);
  for (std::size_t i = 0; i < n; ++i) ASSERT_TRUE(monitor.offer(frames[i]));
  monitor.stop();
  const MonitorCounters c = monitor.counters();
  EXPECT_EQ(c.frames_processed, n);
  EXPECT_EQ(c.ring_depth, 0u);
  EXPECT_GT(c.steps_queued, 0u);
  EXPECT_EQ(c.fits_published + c.step_drops, c.steps_queued);
  EXPECT_EQ(publisher.fits().size(), c.fits_published);
  ASSERT_EQ(publisher.order().back(), RecordingPublisher::Kind::Status);
  EXPECT_EQ(publisher.statuses().back().connection, "finished");
  EXPECT_EQ(publisher.statuses().back().frames_processed, n);
  EXPECT_FALSE(monitor.offer(frames[0]));
  monitor.stop();  // idempotent: no second final status
  const auto order = publisher.order();
  EXPECT_EQ(std::count(order.begin(), order.end(), RecordingPublisher::Kind::Status),
            static_cast<std::ptrdiff_t>(publisher.statuses().size()));
  const auto statuses = publisher.statuses();
  EXPECT_EQ(std::count_if(statuses.begin(), statuses.end(),
                          [](const StatusReport& s) { return s.connection == "finished"; }),
            1);
}

// A driver still delivering after a SIGINT closed the monitor must not lose frames silently.
TEST(Monitor, OffersAfterCloseAreRefusedAndCounted) {
  const Config config = shipped_config();
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  RecordingPublisher publisher;
  MonitorOptions options;
  options.analysis = quick_fits();
  Monitor monitor(config, options, publisher);
  ASSERT_TRUE(monitor.offer(frames[0]));
  monitor.close();
  EXPECT_FALSE(monitor.offer(frames[1]));
  EXPECT_FALSE(monitor.offer_wait(frames[2]));
  monitor.stop();
  EXPECT_FALSE(monitor.offer(frames[3]));
  const MonitorCounters c = monitor.counters();
  EXPECT_EQ(c.frames_offered, 1u);
  EXPECT_EQ(c.frames_refused, 3u);
  EXPECT_EQ(c.frames_processed, 1u);
}

// [model] effects in the config: the monitor fits the extended model to its latest complete
// steps as `gaitmon analyze --effects` fits it to a session (extended_model_input and
// fit_extended_model over the same analyses), now and then and once more at shutdown. Crosstalk
// also needs the steps measured again at its couplings, which the monitor must do too. The whole
// session fits in a window of 100; a window of 20 keeps the latest 20 finalised.
class MonitorEffects : public ::testing::TestWithParam<std::tuple<std::string, int>> {};

TEST_P(MonitorEffects, OfTheConfigAreFittedToTheLatestStepsAsAnalyzeFitsThem) {
  const auto [effect, window] = GetParam();
  if (test::kSanitized && window == 100) {
    GTEST_SKIP() << "the fits of the whole session's window take too long under the sanitizers "
                    "(crosstalk's 30 s of ASan's time at stop 53); the window of 20 runs the same "
                    "monitor code under them";
  }
  Config config = shipped_config();
  config.model.effects = {effect};
  config.model.effects_window_steps = window;
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s(), &header);
  const std::vector<Step> ok = complete_steps(demo_30s(), config);
  const InsoleLayout layout(config.insole(header.insole_size), config.sensor);
  const std::size_t used = std::min(ok.size(), static_cast<std::size_t>(window));
  const std::vector<Step> latest(ok.end() - static_cast<std::ptrdiff_t>(used), ok.end());
  std::vector<StepAnalysis> analyses;
  for (const Step& step : latest)
    analyses.push_back(analyse_step(step, layout, config, quick_fits()));
  const ExtendedModelFit expected =
      fit_extended_model(extended_model_input(latest, std::move(analyses), layout, config,
                                              config.model.effects, quick_fits().area),
                         config.model.effects);

  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  options.sample_rate_hz = header.sample_rate_hz;
  {
    Monitor monitor(config, options, publisher);
    offer_all(monitor, frames);
  }
  ASSERT_GT(ok.size(), 40u) << "the 30 s demo has about 50 complete steps";
  const std::vector<EffectsReport> reports = publisher.effects();
  ASSERT_GE(reports.size(), 2u) << "estimates while running, and the final one";
  for (std::size_t i = 0; i + 1 < reports.size(); ++i) {
    EXPECT_FALSE(reports[i].final_estimate) << i;
    EXPECT_GE(reports[i].steps, 5) << i;
    EXPECT_LE(reports[i].steps, window) << i;
  }
  const EffectsReport& last = reports.back();
  EXPECT_TRUE(last.final_estimate);
  EXPECT_EQ(last.steps, static_cast<int>(used));
  EXPECT_EQ(last.t_first_heel_strike_s, latest.front().t_heel_strike_s);
  expect_close(last.baseline_nrmse_pct, expected.baseline_nrmse_pct, "baseline NRMSE");
  expect_close(last.extended_nrmse_pct, expected.extended_nrmse_pct, "extended NRMSE");
  expect_close(last.baseline_heldout_nrmse_pct, expected.baseline_heldout_nrmse_pct,
               "baseline held-out NRMSE");
  expect_close(last.extended_heldout_nrmse_pct, expected.extended_heldout_nrmse_pct,
               "extended held-out NRMSE");
  ASSERT_EQ(expected.effects.size(), 1u);
  const std::vector<ParamEstimate>& params = expected.effects.front().params;
  ASSERT_EQ(last.params.size(), params.size());
  for (std::size_t i = 0; i < params.size(); ++i) {
    EXPECT_EQ(last.params[i].effect, effect);
    EXPECT_EQ(last.params[i].name, params[i].name);
    expect_close(last.params[i].value, params[i].value, params[i].name);
    if (std::isnan(params[i].se)) {
      EXPECT_TRUE(std::isnan(last.params[i].se)) << params[i].name;
    } else {
      expect_close(last.params[i].se, params[i].se, params[i].name + " SE");
    }
  }
  // The final estimate comes after every fit and before the final status.
  const auto order = publisher.order();
  const auto last_effects =
      std::find(order.rbegin(), order.rend(), RecordingPublisher::Kind::Effects);
  const auto last_fit = std::find(order.rbegin(), order.rend(), RecordingPublisher::Kind::Fit);
  EXPECT_LT(last_effects - order.rbegin(), last_fit - order.rbegin());
  EXPECT_EQ(order.back(), RecordingPublisher::Kind::Status);
}

INSTANTIATE_TEST_SUITE_P(ImpactAndCrosstalk, MonitorEffects,
                         ::testing::Combine(::testing::Values(std::string("impact_transient"),
                                                              std::string("crosstalk")),
                                            ::testing::Values(100, 20)),
                         [](const auto& info) {
                           return fmt::format("{}_window{}", std::get<0>(info.param),
                                              std::get<1>(info.param));
                         });

// Each step fitted after an estimate is fitted with its effects inside the tissue fit, as
// `analyze --effects` fits it (fit_step_with_effects), given its foot's earlier steps in the
// window that still carry into it (stress_relaxation's lag: those ending within 20 tau of its
// heel strike). One worker: each step is then fitted after every earlier one is in the window,
// and which estimate it was fitted with is what its report names.
class MonitorEffectsInside : public ::testing::TestWithParam<std::string> {};

TEST_P(MonitorEffectsInside, FitEachStepAfterAnEstimateWithThem) {
  Config config = shipped_config();
  config.model.effects = {GetParam()};
  config.monitor.workers = 1;
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s(), &header);
  const std::vector<Step> ok = complete_steps(demo_30s(), config);
  const InsoleLayout layout(config.insole(header.insole_size), config.sensor);
  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  options.sample_rate_hz = header.sample_rate_hz;
  {
    // The rest only once the first estimate is out: offered at once, most steps could be
    // fitted before it.
    const auto later = std::find_if(frames.begin(), frames.end(), [](const SensorFrame& f) {
      return f.device_time_us > 10'000'000;
    });
    Monitor monitor(config, options, publisher);
    offer_all(monitor, std::vector<SensorFrame>(frames.begin(), later));
    ASSERT_TRUE(wait_until([&] { return !publisher.effects().empty(); }));
    offer_all(monitor, std::vector<SensorFrame>(later, frames.end()));
  }
  std::map<std::int64_t, EffectsReport> estimates;
  for (const EffectsReport& r : publisher.effects()) {
    if (!r.final_estimate) estimates[r.utime] = r;
  }
  ASSERT_FALSE(estimates.empty());
  const std::vector<FitReport> fits = publisher.fits();
  ASSERT_EQ(fits.size(), ok.size());
  std::size_t before = 0;
  std::size_t compared = 0;
  std::size_t changed_steps = 0;
  constexpr std::size_t kCompared = 12;
  for (const FitReport& fit : fits) {
    SCOPED_TRACE(fmt::format("foot {} step {}", foot_name(fit.foot), fit.step));
    if (fit.effects_utime == 0) {
      EXPECT_EQ(fit.effects_inside, "");
      EXPECT_EQ(compared, 0u) << "a step after the first estimate is fitted with it";
      ++before;
      continue;
    }
    EXPECT_EQ(fit.effects_inside, GetParam());
    ASSERT_EQ(estimates.count(fit.effects_utime), 1u) << "a published estimate's";
    if (compared == kCompared) continue;  // enough, and short enough for the sanitizer builds
    std::vector<EffectEstimate> estimate{{GetParam(), {}}};
    double history_s = 0.0;
    for (const EffectParamReport& p : estimates.at(fit.effects_utime).params) {
      estimate.front().params.push_back({p.name, p.value, p.se});
      if (p.name == "tau_s") history_s = 20.0 * p.value;
    }
    const auto self = std::find_if(ok.begin(), ok.end(), [&](const Step& s) {
      return s.foot == fit.foot && s.index == fit.step;
    });
    ASSERT_NE(self, ok.end());
    std::vector<Step> steps;
    for (auto it = ok.begin(); it != self; ++it) {
      if (it->foot == fit.foot && it->t_toe_off_s > self->t_heel_strike_s - history_s) {
        steps.push_back(*it);
      }
    }
    if (history_s > 0.0 && compared == 0) {
      EXPECT_GE(steps.size(), 1u) << "a history to carry";
    }
    steps.push_back(*self);
    std::vector<StepAnalysis> analyses;
    for (const Step& step : steps)
      analyses.push_back(analyse_step(step, layout, config, quick_fits()));
    const StepAnalysis expected =
        fit_step_with_effects(extended_model_input(steps, std::move(analyses), layout, config,
                                                   config.model.effects, quick_fits().area),
                              steps.size() - 1, estimate, config, quick_fits());
    const StepAnalysis baseline = analyse_step(*self, layout, config, quick_fits());
    expect_close(fit.nrmse_total_pct, expected.nrmse_total_pct, "total NRMSE");
    bool changed = false;
    for (const RegionAnalysis& r : expected.regions) {
      const RegionFitReport& got = fit.regions[index_of(r.region)];
      EXPECT_EQ(got.status, expected_status(r.fit)) << region_name(r.region);
      if (r.fit.status != FitStatus::Ok) continue;
      expect_close(got.kbar_n_per_mm3, r.fit.kbar_n_per_mm3.value, "kbar");
      expect_close(got.n, r.fit.n.value, "n");
      expect_close(got.cbar_ns_per_mm3, r.fit.cbar_ns_per_mm3.value, "cbar");
      expect_close(got.m, r.fit.m.value, "m");
      changed = changed || got.kbar_n_per_mm3 != baseline.at(r.region).fit.kbar_n_per_mm3.value;
    }
    if (changed) ++changed_steps;
    ++compared;
  }
  EXPECT_GE(before, 5u) << "the first estimate needs a step per fold";
  EXPECT_EQ(compared, kCompared);
  // Not all: the demo's impact estimate (about 2.4 N over 12.5 ms) can fall between two frames
  // (5-6 of the 12 steps changed in 10 runs; with relaxation 10-12).
  EXPECT_GE(changed_steps, 3u) << "not the baseline's fits";
}

INSTANTIATE_TEST_SUITE_P(ImpactAndRelaxation, MonitorEffectsInside,
                         ::testing::Values("impact_transient", "stress_relaxation"),
                         [](const auto& info) { return info.param; });

// [model] m_per_session: once the first running m is out, each step is fitted at it, region by
// region, as `analyze --m-per-session` fits a session's steps at its m (fit_at_shared_exponents),
// with the m taken over the complete steps the detector had finalised (both feet, in order); the
// steps before it keep their own m and say so (m_steps 0). One worker: each step is remembered
// before the next is fitted.
TEST(Monitor, RunningMFitsEachStepAfterTheFirstEstimateAtIt) {
  Config config = shipped_config();
  config.model.m_per_session = true;
  config.monitor.workers = 1;
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s(), &header);
  const std::vector<Step> ok = complete_steps(demo_30s(), config);
  const InsoleLayout layout(config.insole(header.insole_size), config.sensor);
  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  options.sample_rate_hz = header.sample_rate_hz;
  std::uint64_t estimates = 0;
  {
    // The rest only once the first estimate is out, so that later steps are fitted at it.
    const auto later = std::find_if(frames.begin(), frames.end(), [](const SensorFrame& f) {
      return f.device_time_us > 12'000'000;
    });
    Monitor monitor(config, options, publisher);
    offer_all(monitor, std::vector<SensorFrame>(frames.begin(), later));
    ASSERT_TRUE(wait_until([&] { return monitor.counters().m_estimates >= 1; }));
    offer_all(monitor, std::vector<SensorFrame>(later, frames.end()));
    monitor.stop();
    estimates = monitor.counters().m_estimates;
  }
  const std::vector<FitReport> fits = publisher.fits();
  ASSERT_EQ(fits.size(), ok.size());
  std::vector<StepAnalysis> own;
  for (const Step& step : ok) own.push_back(analyse_step(step, layout, config, quick_fits()));
  // The running m over the first `count` steps, once per count.
  std::map<std::size_t, SharedExponents> over;
  const auto running_m = [&](std::size_t count) -> const SharedExponents& {
    auto it = over.find(count);
    if (it == over.end()) {
      const std::span<const StepAnalysis> first(own.data(), count);
      it = over.emplace(count, shared_damping_exponents(first, config, quick_fits())).first;
    }
    return it->second;
  };
  const auto heel = index_of(Region::Heel);
  std::size_t before = 0, at_running = 0;
  for (const FitReport& fit : fits) {
    SCOPED_TRACE(fmt::format("foot {} step {}", foot_name(fit.foot), fit.step));
    const int heel_steps = fit.regions[heel].m_steps;
    if (heel_steps == 0) {
      EXPECT_EQ(at_running, 0u) << "a step after the first estimate is fitted at it";
      for (const RegionFitReport& g : fit.regions) EXPECT_EQ(g.m_steps, 0);
      ++before;
      continue;
    }
    // Every step of the demo fits its heel: the heel's m_steps is the estimate's step count.
    const auto count = static_cast<std::size_t>(heel_steps);
    ASSERT_GE(count, static_cast<std::size_t>(kFirstSharedMSteps));
    ASSERT_LE(count, ok.size());
    for (std::size_t k = 0; k < count; ++k)
      ASSERT_EQ(own[k].at(Region::Heel).fit.status, FitStatus::Ok);
    if (at_running++ >= 12) continue;  // enough, and short enough for the sanitizer builds
    const SharedExponents& shared = running_m(count);
    const auto self = std::find_if(ok.begin(), ok.end(), [&](const Step& s) {
      return s.foot == fit.foot && s.index == fit.step;
    });
    ASSERT_NE(self, ok.end());
    StepAnalysis expected = own[static_cast<std::size_t>(self - ok.begin())];
    fit_at_shared_exponents(expected, shared, config, quick_fits());
    expect_close(fit.nrmse_total_pct, expected.nrmse_total_pct, "total NRMSE");
    for (const RegionAnalysis& r : expected.regions) {
      const RegionFitReport& got = fit.regions[index_of(r.region)];
      const std::string where(region_name(r.region));
      EXPECT_EQ(got.status, expected_status(r.fit)) << where;
      if (r.fit.status != FitStatus::Ok) continue;
      const auto& m = shared[index_of(r.region)];
      EXPECT_EQ(got.m_steps, m && !r.fit.m.free ? m->stances : 0) << where;
      expect_close(got.kbar_n_per_mm3, r.fit.kbar_n_per_mm3.value, where + " kbar");
      expect_close(got.n, r.fit.n.value, where + " n");
      expect_close(got.cbar_ns_per_mm3, r.fit.cbar_ns_per_mm3.value, where + " cbar");
      expect_close(got.m, r.fit.m.value, where + " m");
      expect_close(got.se_m, r.fit.m.se, where + " se_m");
      expect_total_se(got, r.fit, r.region, config, where);
    }
    EXPECT_TRUE(shared[heel].has_value());
    EXPECT_EQ(fit.regions[heel].m, shared[heel]->m);
  }
  EXPECT_GE(before, static_cast<std::size_t>(kFirstSharedMSteps));
  EXPECT_GE(at_running, 10u);
  EXPECT_GE(estimates, 2u) << "again as the steps double";
}

// As analyze refuses --m-per-session there: the fit at a declared m is the default fit's, and
// each step's tissue fitted with effects inside has its own m.
TEST(Monitor, RefusesARunningMOutsideTheDefaultFitOrWithEffects) {
  Config config = shipped_config();
  config.model.m_per_session = true;
  RecordingPublisher publisher;
  MonitorOptions seed8 = quick_replay();
  seed8.analysis.fit.mode = FitMode::Seed8;
  EXPECT_THROW(Monitor(config, seed8, publisher), std::invalid_argument);
  MonitorOptions free_scale = quick_replay();
  free_scale.analysis.fit.free_scale = true;
  EXPECT_THROW(Monitor(config, free_scale, publisher), std::invalid_argument);
  config.model.effects = {"impact_transient"};
  EXPECT_THROW(Monitor(config, quick_replay(), publisher), std::invalid_argument);
}

// As `analyze --effects` refuses them: seed8's and the free-scale fit cannot take a map.
TEST(Monitor, RefusesATissueEffectInsideAFitThatCannotTakeIt) {
  Config config = shipped_config();
  RecordingPublisher publisher;
  MonitorOptions seed8;
  seed8.analysis.fit.mode = FitMode::Seed8;
  MonitorOptions free_scale;
  free_scale.analysis.fit.free_scale = true;
  config.model.effects = {"sensor_creep", "hysteresis"};
  EXPECT_THROW(Monitor(config, seed8, publisher), std::invalid_argument);
  EXPECT_THROW(Monitor(config, free_scale, publisher), std::invalid_argument);
  config.model.effects = {"sensor_creep"};  // on top of the tissue fit: any fit takes it
  const test::LogCapture log;
  EXPECT_NO_THROW(Monitor(config, seed8, publisher));
  // Unlike analyze, the monitor does not undo the creep in the readings, and says so.
  EXPECT_NE(log.text.str().find("monitor: sensor_creep is estimated from the steps' zeros and "
                                "published; each step is fitted from the readings as read"),
            std::string::npos)
      << log.text.str();
}

// close() (the commands' SIGINT and SIGTERM) makes the shutdown publish the latest estimate as
// the final one instead of fitting the window again, which could outlast the 2-s shutdown.
TEST(Monitor, AnInterruptedRunPublishesItsLatestEffectsEstimateAsTheFinalOne) {
  Config config = shipped_config();
  config.model.effects = {"impact_transient"};
  RecordingPublisher publisher;
  Monitor monitor(config, quick_replay(), publisher);
  offer_all(monitor, test::session_frames(demo_30s()));
  ASSERT_TRUE(wait_until([&] { return !publisher.effects().empty(); }));
  monitor.close();
  monitor.stop();
  const std::vector<EffectsReport> reports = publisher.effects();
  ASSERT_GE(reports.size(), 2u);
  const EffectsReport& last = reports.back();
  const EffectsReport& before = reports[reports.size() - 2];
  EXPECT_TRUE(last.final_estimate);
  EXPECT_FALSE(before.final_estimate);
  EXPECT_EQ(last.steps, before.steps);
  EXPECT_EQ(last.t_last_toe_off_s, before.t_last_toe_off_s);
  ASSERT_EQ(last.params.size(), before.params.size());
  for (std::size_t i = 0; i < last.params.size(); ++i) {
    EXPECT_EQ(last.params[i].value, before.params[i].value) << last.params[i].name;
  }
}

TEST(Monitor, AStepWaitsForNoFitOfTheEffectsEvenWithOneWorker) {
  Config config = shipped_config();
  config.monitor.workers = 1;
  config.model.effects = {"impact_transient"};
  // The first 10 s (enough steps for a first estimate, fewer than the backlog holds), then the
  // rest while that estimate's fit is held.
  std::vector<SensorFrame> first = test::session_frames(demo_30s());
  const auto later = std::find_if(first.begin(), first.end(), [](const SensorFrame& f) {
    return f.device_time_us > 10'000'000;
  });
  const std::vector<SensorFrame> rest(later, first.end());
  first.erase(later, first.end());
  GatedPublisher<EffectsReport> publisher;  // the first estimate's fit never ends till released
  Monitor monitor(config, quick_replay(), publisher);
  offer_all(monitor, first);
  const bool held = wait_until([&] { return publisher.entered() == 1; });
  const std::uint64_t before = monitor.counters().fits_published;
  std::atomic<bool> offered{false};
  std::thread driver([&] {
    offer_all(monitor, rest);
    offered.store(true);
  });
  // Every step queued meanwhile is fitted and published while the effects fit is still held.
  const bool went_on = held && wait_until([&] {
                         const MonitorCounters c = monitor.counters();
                         return offered.load() &&
                                c.frames_processed == first.size() + rest.size() &&
                                c.fits_published == c.steps_queued;
                       });
  const std::uint64_t during = monitor.counters().fits_published - before;
  publisher.release();
  driver.join();
  monitor.stop();
  ASSERT_TRUE(held);
  EXPECT_TRUE(went_on) << "fits published while the effects fit was held: " << during;
  EXPECT_GE(during, 20u);
  EXPECT_EQ(monitor.counters().fits_published, monitor.counters().steps_queued);
  EXPECT_EQ(monitor.counters().step_drops, 0u);
}

TEST(Monitor, AWindowThatTurnedOverWhileAnEffectsFitRanIsFittedAgain) {
  Config config = shipped_config();
  config.model.effects = {"impact_transient"};
  config.model.effects_window_steps = 10;
  std::vector<SensorFrame> first = test::session_frames(demo_30s());
  const auto later = std::find_if(first.begin(), first.end(), [](const SensorFrame& f) {
    return f.device_time_us > 20'000'000;
  });
  const std::vector<SensorFrame> rest(later, first.end());
  first.erase(later, first.end());
  GatedPublisher<EffectsReport> publisher;
  Monitor monitor(config, quick_replay(), publisher);
  // The first estimate is held while more new steps than the window holds arrive.
  std::thread driver([&] { offer_all(monitor, first); });
  const bool turned_over = wait_until(
      [&] { return publisher.entered() == 1 && monitor.counters().fits_published >= 25; });
  driver.join();
  publisher.release();
  EXPECT_TRUE(wait_until([&] { return publisher.effects().size() == 1; }));
  offer_all(monitor, rest);
  monitor.stop();
  ASSERT_TRUE(turned_over);
  const std::vector<EffectsReport> reports = publisher.effects();
  const auto estimates = std::count_if(reports.begin(), reports.end(),
                                       [](const EffectsReport& r) { return !r.final_estimate; });
  EXPECT_GE(estimates, 2) << "a fit of the new window follows the held one";
}

// The right foot's device is down from 10 to 20 s and its clock starts over, so that foot's time
// then runs 10 s behind the left's. The window keeps the latest steps finalised: by time, the
// left foot's steps of the last 5 s would have shut out every right step after the restart.
TEST(Monitor, TheEffectsWindowKeepsTheLatestStepsOfAFootWhoseDeviceRestarted) {
  Config config = shipped_config();
  config.model.effects = {"impact_transient"};
  config.model.effects_window_steps = 5;
  std::vector<SensorFrame> feed;
  for (SensorFrame f : test::session_frames(demo_30s())) {
    if (f.foot == Foot::Right && f.device_time_us >= 10'000'000) {
      if (f.device_time_us < 20'000'000) continue;
      f.device_time_us -= 20'000'000;
    }
    feed.push_back(f);
  }
  RecordingPublisher publisher;
  {
    Monitor monitor(config, quick_replay(), publisher);
    offer_all(monitor, feed);
  }
  double right_last_heel_strike_s = 0.0;
  double left_last_heel_strike_s = 0.0;
  for (const FitReport& fit : publisher.fits()) {
    double& last = fit.foot == Foot::Right ? right_last_heel_strike_s : left_last_heel_strike_s;
    last = std::max(last, fit.t_heel_strike_s);
  }
  ASSERT_LT(right_last_heel_strike_s, 20.0)
      << "the right foot's clock runs behind after the restart";
  ASSERT_GT(left_last_heel_strike_s, 27.0);
  const std::vector<EffectsReport> reports = publisher.effects();
  ASSERT_FALSE(reports.empty());
  const EffectsReport& final_estimate = reports.back();
  ASSERT_TRUE(final_estimate.final_estimate);
  EXPECT_EQ(final_estimate.steps, 5);
  EXPECT_LE(final_estimate.t_first_heel_strike_s, right_last_heel_strike_s)
      << "the right foot's last step is among the 5 latest finalised";
}

TEST(Monitor, WithoutEffectsNothingIsPublishedOnTheirChannel) {
  const Config config = shipped_config();
  ASSERT_TRUE(config.model.effects.empty());
  RecordingPublisher publisher;
  {
    Monitor monitor(config, quick_replay(), publisher);
    offer_all(monitor, test::session_frames(demo_30s()));
  }
  EXPECT_FALSE(publisher.fits().empty());
  EXPECT_TRUE(publisher.effects().empty());
}

TEST(Monitor, StatusIsPeriodicAndCarriesTheDriverCounters) {
  Config config = shipped_config();
  config.monitor.status_period_s = 0.02;
  RecordingPublisher publisher;
  MonitorOptions options;
  options.driver_status = [](StatusReport& s) {
    s.bytes_received = 12345;
    s.crc_errors = 7;
    s.connection = "disconnected";
  };
  {
    Monitor monitor(config, options, publisher);
    ASSERT_TRUE(wait_until([&] { return publisher.statuses().size() >= 3; }))
        << "no three statuses of a 20 ms period within 60 s";
  }
  const auto statuses = publisher.statuses();
  ASSERT_GE(statuses.size(), 4u) << "three periodic statuses and the final one";
  for (std::size_t i = 0; i + 1 < statuses.size(); ++i) {
    EXPECT_EQ(statuses[i].connection, "disconnected");
    EXPECT_EQ(statuses[i].bytes_received, 12345u);
    EXPECT_EQ(statuses[i].crc_errors, 7u);
  }
  EXPECT_EQ(statuses.back().connection, "finished");
  EXPECT_EQ(statuses.back().bytes_received, 12345u);
  EXPECT_EQ(statuses.back().frames_processed, 0u);
}

// A status counts a frame as processed, rejected or still in the ring, never as none of these:
// statuses every 0.1 ms, while a replay fills the ring and the detector takes frames in batches.
TEST(Monitor, EveryStatusAccountsForEveryFrameOffered) {
  Config config = shipped_config();
  config.monitor.status_period_s = 1e-4;
  config.monitor.publish_frames = false;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  std::atomic<std::uint64_t> offered{0};
  // Read before the monitor's own counters: the frames offered by then.
  options.driver_status = [&](StatusReport& s) { s.frames_decoded = offered.load(); };
  {
    Monitor monitor(config, options, publisher);
    for (const SensorFrame& frame : frames) {
      ASSERT_TRUE(monitor.offer_wait(frame));
      offered.fetch_add(1);
    }
    monitor.stop();
  }
  const auto statuses = publisher.statuses();
  ASSERT_GT(statuses.size(), 10u);
  for (const StatusReport& s : statuses) {
    EXPECT_GE(s.frames_processed + s.frames_rejected + s.ring_depth, s.frames_decoded)
        << "processed " << s.frames_processed << ", rejected " << s.frames_rejected
        << ", in the ring " << s.ring_depth;
  }
  EXPECT_EQ(statuses.back().frames_processed, frames.size());
}

TEST(Monitor, AFailedAnalysisIsPublishedWithItsStatus) {
  const Config config = shipped_config();
  MonitorOptions options;
  options.analysis.fit.max_iterations = 0;  // analyse_step refuses these settings
  options.backlog_overflow = BacklogOverflow::Wait;
  RecordingPublisher publisher;
  {
    Monitor monitor(config, options, publisher);
    for (const SensorFrame& frame : test::session_frames(demo_30s())) {
      ASSERT_TRUE(monitor.offer_wait(frame));
    }
  }
  const auto fits = publisher.fits();
  ASSERT_FALSE(fits.empty());
  for (const FitReport& fit : fits) {
    for (const RegionFitReport& r : fit.regions) {
      EXPECT_EQ(r.status, "fit_failed:max_iterations must be >= 1");
      EXPECT_EQ(r.kbar_n_per_mm3, 0.0);
    }
  }
  EXPECT_EQ(publisher.statuses().back().fits_failed, fits.size());
}

// A Publisher that refuses every frame report: the rest still goes out.
class FrameRefusingPublisher final : public RecordingPublisher {
 public:
  using RecordingPublisher::publish;
  void publish(const FrameReport&) override { throw std::runtime_error("no room for frames"); }
};

TEST(Monitor, APublisherThatThrowsIsCountedAndLogged) {
  const Config config = shipped_config();
  std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  frames.resize(200);
  MonitorOptions options;
  options.analysis = quick_fits();
  options.backlog_overflow = BacklogOverflow::Wait;
  FrameRefusingPublisher publisher;
  const test::LogCapture log;
  Monitor monitor(config, options, publisher);
  for (const SensorFrame& frame : frames) ASSERT_TRUE(monitor.offer_wait(frame));
  monitor.stop();
  EXPECT_EQ(monitor.counters().publish_failures, frames.size());
  EXPECT_EQ(publisher.statuses().back().frames_processed, frames.size());
  const std::string text = log.text.str();
  EXPECT_NE(text.find("monitor: publishing failed, the message is lost: no room for frames; 1 "
                      "lost so far"),
            std::string::npos)
      << text;
}

// The published fits of one foot, by step index.
std::vector<std::int64_t> fitted_steps(const std::vector<FitReport>& fits, Foot foot) {
  std::vector<std::int64_t> steps;
  for (const FitReport& fit : fits) {
    if (fit.foot == foot) steps.push_back(fit.step);
  }
  return steps;
}

// At the first message matching `arm_on` it makes the logging thread's next allocation fail
// (spdlog calls a sink on the thread that logs, and allocates nothing after the last sink), or
// does `action` instead, on that thread.
class ArmingSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  explicit ArmingSink(
      std::regex arm_on, std::function<void()> action = [] { test::allocations_until_failure = 0; })
      : arm_on_(std::move(arm_on)), action_(std::move(action)) {}
  /// The submatches of the message that armed it; empty if none did.
  std::vector<std::string> armed_at() {
    const std::lock_guard lock(mutex_);
    return armed_at_;
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    const std::string line(msg.payload.begin(), msg.payload.end());
    std::smatch match;
    if (armed_at_.empty() && std::regex_search(line, match, arm_on_)) {
      armed_at_.assign(match.begin(), match.end());
      action_();
    }
  }
  void flush_() override {}

 private:
  std::regex arm_on_;
  std::function<void()> action_;
  std::vector<std::string> armed_at_;
};

TEST(Monitor, AStepLostAfterItsAnalysisIsCountedAndLoggedAndHoldsBackNoLaterStep) {
  const Config config = shipped_config();
  MonitorOptions options;
  options.analysis.fit.max_iterations = 0;  // every analysis fails: its report is then built
  options.backlog_overflow = BacklogOverflow::Wait;
  RecordingPublisher publisher;
  // Memory runs out for the first failed analysis's report, on its worker. The arming sink is
  // the last.
  const test::LogCapture log;
  const auto arming =
      std::make_shared<ArmingSink>(std::regex("foot (L|R) step ([0-9]+): analysis failed"));
  const test::ScopedSink attached(arming);
  Monitor monitor(config, options, publisher);
  for (const SensorFrame& frame : test::session_frames(demo_30s())) {
    ASSERT_TRUE(monitor.offer_wait(frame));
  }
  monitor.stop();

  const std::vector<std::string> at = arming->armed_at();
  ASSERT_EQ(at.size(), 3u) << log.text.str();
  const Foot foot = at[1] == "L" ? Foot::Left : Foot::Right;
  const std::int64_t lost = std::stoll(at[2]);
  EXPECT_THAT(log.text.str(),
              testing::HasSubstr(fmt::format("monitor: foot {} step {} lost: std::bad_alloc",
                                             foot_name(foot), lost)));
  const auto fits = publisher.fits();
  const MonitorCounters c = monitor.counters();
  EXPECT_EQ(c.steps_queued, fits.size() + 1);
  EXPECT_EQ(c.fits_failed, fits.size() + 1);
  EXPECT_EQ(c.step_drops, 0u);
  // Every other step of the foot is published, in order, the ones after the lost one too.
  const std::vector<std::int64_t> steps = fitted_steps(fits, foot);
  ASSERT_FALSE(steps.empty());
  EXPECT_GT(steps.back(), lost);
  EXPECT_TRUE(std::is_sorted(steps.begin(), steps.end()));
  EXPECT_EQ(std::count(steps.begin(), steps.end(), lost), 0);
  const std::vector<StepEvent> events = publisher.events();
  const auto detected = std::count_if(events.begin(), events.end(), [&](const StepEvent& e) {
    return e.foot == foot && e.kind == StepEvent::Kind::ToeOff && e.complete;
  });
  EXPECT_EQ(static_cast<std::int64_t>(steps.size()) + 1, detected);
}

// Once it has published the toe off of one step, lets `succeeding` more of the detector's
// allocations succeed and makes the next one fail.
class ArmingPublisher final : public RecordingPublisher {
 public:
  ArmingPublisher(Foot foot, std::int64_t step, int succeeding = 0)
      : foot_(foot), step_(step), succeeding_(succeeding) {}
  using RecordingPublisher::publish;
  void publish(const StepEvent& event) override {
    RecordingPublisher::publish(event);
    if (event.foot == foot_ && event.step == step_ && event.kind == StepEvent::Kind::ToeOff) {
      test::allocations_until_failure = succeeding_;
    }
  }

 private:
  Foot foot_;
  std::int64_t step_;
  int succeeding_;
};

TEST(Monitor, AStepThatMemoryRanOutForBeforeItWasQueuedIsDroppedAndHoldsBackNoLaterStep) {
  const Config config = shipped_config();
  ArmingPublisher publisher(Foot::Left, 3);
  const test::LogCapture log;
  Monitor monitor(config, quick_replay(), publisher);
  for (const SensorFrame& frame : test::session_frames(demo_30s())) {
    ASSERT_TRUE(monitor.offer_wait(frame));
  }
  monitor.stop();

  EXPECT_THAT(log.text.str(),
              testing::HasSubstr("monitor: dropped foot L step 3: std::bad_alloc; 1 "
                                 "dropped so far"));
  const auto fits = publisher.fits();
  const MonitorCounters c = monitor.counters();
  EXPECT_EQ(c.step_drops, 1u);
  EXPECT_EQ(c.steps_queued, fits.size());
  EXPECT_EQ(c.frames_rejected, 0u);
  const std::vector<std::int64_t> left = fitted_steps(fits, Foot::Left);
  EXPECT_TRUE(std::is_sorted(left.begin(), left.end()));
  EXPECT_EQ(std::count(left.begin(), left.end(), 3), 0);
  EXPECT_GT(left.size(), 10u);
  EXPECT_GT(left.back(), 3);
}

TEST(Monitor, AStepWhoseWorkerCouldNotBeStartedWaitsForTheEndOfTheRun) {
  Config config = shipped_config();
  config.monitor.workers = 1;
  // The left foot alone, up to just before its second complete step: one step to queue.
  std::vector<Step> left;
  for (Step& step : batch_steps(demo_30s(), config)) {
    if (step.foot == Foot::Left && step.status == StepStatus::Ok) left.push_back(std::move(step));
  }
  ASSERT_GE(left.size(), 2u);
  std::vector<SensorFrame> frames;
  for (const SensorFrame& frame : test::session_frames(demo_30s())) {
    if (frame.foot == Foot::Left && frame.device_time_us < (left[1].t_heel_strike_s - 0.05) * 1e6) {
      frames.push_back(frame);
    }
  }
  // After its toe off the detector allocates the step's slot, then (the backlog's first block
  // has room for it) the runner's post: that one fails.
  ArmingPublisher publisher(Foot::Left, left[0].index, 1);
  const test::LogCapture log;
  Monitor monitor(config, quick_replay(), publisher);
  for (const SensorFrame& frame : frames) ASSERT_TRUE(monitor.offer_wait(frame));
  monitor.stop();

  EXPECT_THAT(log.text.str(),
              testing::HasSubstr(fmt::format(
                  "monitor: no worker started for foot L step {}: std::bad_alloc; it waits",
                  left[0].index)));
  const auto fits = publisher.fits();
  ASSERT_EQ(fits.size(), 1u) << log.text.str();
  EXPECT_EQ(fits[0].step, left[0].index);
  const MonitorCounters c = monitor.counters();
  EXPECT_EQ(c.steps_queued, 1u);
  EXPECT_EQ(c.step_drops, 0u);
  EXPECT_EQ(c.frames_rejected, 0u);
}

// Once it has published the report of the input's last frame (foot and index), makes the
// detector's next allocation fail: the first foot's finish at the end of input.
class LastFrameArmingPublisher final : public RecordingPublisher {
 public:
  explicit LastFrameArmingPublisher(const std::vector<SensorFrame>& frames)
      : foot_(frames.back().foot),
        index_(std::count_if(frames.begin(), frames.end(),
                             [&](const SensorFrame& f) { return f.foot == foot_; }) -
               1) {}
  using RecordingPublisher::publish;
  void publish(const FrameReport& report) override {
    RecordingPublisher::publish(report);
    if (report.foot == foot_ && report.frame == index_) test::allocations_until_failure = 0;
  }

 private:
  Foot foot_;
  std::int64_t index_;
};

TEST(Monitor, MemoryRunningOutAtOneFootsEndOfInputLosesNotTheOtherFootsLastStep) {
  Config config = shipped_config();
  config.monitor.publish_frames = true;
  config.monitor.status_period_s = 3600.0;  // no status between the last frame and the end
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  std::vector<std::int64_t> batch_right;
  for (const Step& step : batch_steps(demo_30s(), config)) {
    if (step.foot == Foot::Right && step.status == StepStatus::Ok)
      batch_right.push_back(step.index);
  }
  LastFrameArmingPublisher publisher(frames);
  const test::LogCapture log;
  Monitor monitor(config, quick_replay(), publisher);
  offer_all(monitor, frames);
  monitor.stop();

  const std::string text = log.text.str();
  EXPECT_THAT(text, testing::HasSubstr("monitor: foot L: the step still open at the end of input "
                                       "was lost: std::bad_alloc"));
  EXPECT_THAT(text, testing::Not(testing::HasSubstr("detector thread stopped")));
  // The right foot's last step, which only its own finish cuts, is fitted.
  EXPECT_EQ(fitted_steps(publisher.fits(), Foot::Right), batch_right);
  const std::vector<StatusReport> statuses = publisher.statuses();
  ASSERT_FALSE(statuses.empty());
  EXPECT_EQ(statuses.back().frames_processed, frames.size());
  EXPECT_EQ(statuses.back().fits_published, monitor.counters().steps_queued);
}

TEST(Monitor, AStatusThatMemoryRanOutForIsLostAndLoggedAndTheRunGoesOn) {
  Config config = shipped_config();
  config.monitor.status_period_s = 1e-3;
  MonitorOptions options = quick_replay();
  // Once a fit is published its latency is in the window that the status copies: the driver's
  // fields filled, that copy is the status's next allocation, and it fails.
  std::atomic<Monitor*> watched{nullptr};
  std::atomic<int> calls{0};
  bool armed = false;  // the detector thread's only
  options.driver_status = [&](StatusReport&) {
    calls.fetch_add(1);
    const Monitor* monitor = watched.load();
    if (!armed && monitor != nullptr && monitor->counters().fits_published > 0) {
      armed = true;
      test::allocations_until_failure = 0;
    }
  };
  RecordingPublisher publisher;
  const test::LogCapture log;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  Monitor monitor(config, options, publisher);
  watched.store(&monitor);
  for (const SensorFrame& frame : frames) ASSERT_TRUE(monitor.offer_wait(frame));
  monitor.stop();

  EXPECT_THAT(log.text.str(),
              testing::HasSubstr("monitor: a status report was lost: std::bad_alloc"));
  const auto statuses = publisher.statuses();
  EXPECT_EQ(statuses.size() + 1, static_cast<std::size_t>(calls.load()));
  ASSERT_FALSE(statuses.empty());
  EXPECT_EQ(statuses.back().connection, "finished");
  EXPECT_EQ(statuses.back().frames_processed, frames.size());
  EXPECT_EQ(statuses.back().fits_published, monitor.counters().steps_queued);
  EXPECT_EQ(monitor.counters().publish_failures, 0u);
}

// close() while stop() fits the window as it ends (reachable through the API: the commands
// close before they stop) stops that fit; the latest estimate is published as the final one
// instead, as when close() comes first. The close comes from the log line that starts the fit,
// on the stopping thread, before the fit's first step. The first estimate starts at the 5th
// step; frames are offered until one more step is published after it, so that it does not cover
// the window as it ends and stop() fits that, and no further, as another estimate would start
// only at 5 new steps.
TEST(Monitor, AFinalEffectsFitThatCloseStopsLeavesTheLatestEstimateAsTheFinalOne) {
  Config config = shipped_config();
  config.model.effects = {"crosstalk"};
  RecordingPublisher publisher;
  const test::LogCapture log;
  const std::vector<SensorFrame> frames = test::session_frames(demo_30s());
  Monitor monitor(config, quick_replay(), publisher);
  const auto closing = std::make_shared<ArmingSink>(
      std::regex("fitting the extended model to the ([0-9]+) steps"), [&] { monitor.close(); });
  const test::ScopedSink sink(closing);
  std::size_t next = 0;
  const auto offer_until = [&](const std::function<bool()>& done) {
    while (!done()) {
      ASSERT_LT(next, frames.size());
      ASSERT_TRUE(monitor.offer_wait(frames[next++]));
      ASSERT_TRUE(wait_until([&] { return monitor.counters().frames_processed == next; }));
    }
  };
  offer_until([&] { return monitor.counters().steps_queued >= 5; });
  ASSERT_TRUE(wait_until([&] { return !publisher.effects().empty(); }));
  const std::size_t published = publisher.fits().size();
  offer_until([&] { return monitor.counters().steps_queued > published; });
  ASSERT_TRUE(wait_until([&] { return publisher.fits().size() > published; }));
  monitor.stop();
  const std::vector<std::string> armed = closing->armed_at();
  ASSERT_EQ(armed.size(), 2u) << "stop() fitted no window";
  EXPECT_LT(std::stoi(armed[1]), 10);
  EXPECT_THAT(log.text.str(), testing::HasSubstr("over 5 steps, is the final one"));
  EXPECT_THAT(log.text.str(), testing::Not(testing::HasSubstr("could not be fitted")));
  const std::vector<EffectsReport> reports = publisher.effects();
  ASSERT_EQ(reports.size(), 2u);
  EXPECT_FALSE(reports[0].final_estimate);
  EXPECT_TRUE(reports[1].final_estimate);
  EXPECT_EQ(reports[0].steps, 5);
  EXPECT_EQ(reports[1].steps, reports[0].steps);
  ASSERT_EQ(reports[1].params.size(), reports[0].params.size());
  for (std::size_t i = 0; i < reports[1].params.size(); ++i) {
    EXPECT_EQ(reports[1].params[i].value, reports[0].params[i].value) << reports[1].params[i].name;
  }
  EXPECT_EQ(publisher.order().back(), RecordingPublisher::Kind::Status);
}

// Runs the demo with an effect, and stop() with its first allocation failing: the final effects
// estimate's (a copy of the latest, or of the window to fit), on the thread that stops.
struct StoppedWithoutMemory {
  std::string log;
  std::vector<EffectsReport> effects;
};

StoppedWithoutMemory stop_without_memory_for_the_final_effects(bool interrupt) {
  Config config = shipped_config();
  config.model.effects = {"impact_transient"};
  RecordingPublisher publisher;
  const test::LogCapture log;
  Monitor monitor(config, quick_replay(), publisher);
  offer_all(monitor, test::session_frames(demo_30s()));
  EXPECT_TRUE(wait_until([&] { return !publisher.effects().empty(); }));
  if (interrupt) monitor.close();
  test::allocations_until_failure = 0;
  monitor.stop();
  test::allocations_until_failure = -1;
  const std::vector<StatusReport> statuses = publisher.statuses();
  EXPECT_TRUE(!statuses.empty() && statuses.back().connection == "finished") << "no final status";
  return {log.text.str(), publisher.effects()};
}

TEST(Monitor, AnInterruptedRunThatMemoryRanOutForInItsFinalEffectsEstimateStillEnds) {
  const StoppedWithoutMemory run = stop_without_memory_for_the_final_effects(true);
  EXPECT_THAT(
      run.log,
      testing::HasSubstr("monitor: the extended model's final estimate was lost: std::bad_alloc"));
  for (const EffectsReport& report : run.effects) EXPECT_FALSE(report.final_estimate);
}

TEST(Monitor, ARunThatMemoryRanOutForInItsFinalEffectsEstimateStillEnds) {
  // Whether the latest estimate is of the window as it ends depends on when the workers finished.
  // If it is, its copy is what fails, and nothing is final; if not, the fit of the window fails
  // and the latest estimate is the final one.
  const StoppedWithoutMemory run = stop_without_memory_for_the_final_effects(false);
  ASSERT_FALSE(run.effects.empty());
  if (run.log.find("could not be fitted") == std::string::npos) {
    EXPECT_THAT(run.log, testing::HasSubstr("monitor: the extended model's final estimate was "
                                            "lost: std::bad_alloc"));
    for (const EffectsReport& report : run.effects) EXPECT_FALSE(report.final_estimate);
  } else {
    EXPECT_THAT(run.log, testing::ContainsRegex("monitor: the extended model could not be fitted "
                                                "to [0-9]+ steps: std::bad_alloc"));
    ASSERT_GE(run.effects.size(), 2u);
    EXPECT_TRUE(run.effects.back().final_estimate);
    EXPECT_EQ(run.effects.back().steps, run.effects[run.effects.size() - 2].steps);
  }
}

TEST(Monitor, RefusesARateTooLowForTheConfigsWindowsBeforeAnyFrame) {
  Config config = shipped_config();
  config.segmentation.swing_window_frames = 20;
  config.segmentation.max_gap_s = 0.2;
  RecordingPublisher publisher;
  MonitorOptions options;
  options.sample_rate_hz = 10.0;  // a swing midpoint at most 15 frames from its step
  EXPECT_THROW(Monitor(config, options, publisher), std::invalid_argument);
  config.segmentation.swing_window_frames = 15;
  Monitor monitor(config, options, publisher);
  monitor.stop();
}

TEST(Monitor, RejectsBadFramesAndRestartsWhenTheDeviceClockGoesBack) {
  const Config config = shipped_config();
  const std::vector<Step> steps = batch_steps(demo_30s(), config);
  const std::vector<SensorFrame> once = test::session_frames(demo_30s());
  std::map<Foot, std::int64_t> frames_per_foot;
  std::map<Foot, int> steps_per_foot;
  for (const SensorFrame& f : once) ++frames_per_foot[f.foot];
  for (const Step& s : steps) ++steps_per_foot[s.foot];

  // The session twice (the device restarted), with three bad frames in the first pass.
  std::vector<SensorFrame> feed(once.begin(), once.begin() + 100);
  SensorFrame bad = once[99];
  feed.push_back(bad);  // same device time again
  bad.sensor_count = 50;
  feed.push_back(bad);
  bad = once[99];
  bad.size = InsoleSize::S41_42;
  bad.device_time_us += 1;
  feed.push_back(bad);
  feed.insert(feed.end(), once.begin() + 100, once.end());
  feed.insert(feed.end(), once.begin(), once.end());

  RecordingPublisher publisher;
  MonitorOptions options;
  options.backlog_overflow = BacklogOverflow::Wait;
  options.analysis = quick_fits();
  Config quiet = config;
  quiet.monitor.publish_frames = false;
  {
    Monitor monitor(quiet, options, publisher);
    for (const SensorFrame& frame : feed) ASSERT_TRUE(monitor.offer_wait(frame));
    monitor.stop();
    EXPECT_EQ(monitor.counters().frames_rejected, 3u);
    EXPECT_EQ(monitor.counters().frames_processed, 2 * once.size());
  }
  std::map<StepKey, StepEvent> heel_strikes;
  for (const StepEvent& e : publisher.events()) {
    if (e.kind == StepEvent::Kind::HeelStrike) heel_strikes[{e.foot, e.step}] = e;
  }
  ASSERT_EQ(heel_strikes.size(), 2 * steps.size());
  for (const Step& s : steps) {
    const StepEvent& first = heel_strikes.at({s.foot, s.index});
    EXPECT_EQ(first.frame, s.heel_strike_frame);
    EXPECT_EQ(first.t_s, s.t_heel_strike_s);
    // The second pass continues the numbering, and its clock one sample after the first pass.
    const StepEvent& second = heel_strikes.at({s.foot, s.index + steps_per_foot[s.foot]});
    EXPECT_EQ(second.frame, s.heel_strike_frame + frames_per_foot[s.foot]);
    double foot_first_t = -1.0;
    double last_t = 0.0;
    for (const SensorFrame& f : once) {
      if (f.foot != s.foot) continue;
      if (foot_first_t < 0.0) foot_first_t = f.device_time_us / 1e6;
      last_t = f.device_time_us / 1e6;
    }
    EXPECT_NEAR(second.t_s, s.t_heel_strike_s - foot_first_t + last_t + 0.01, 1e-9);
  }
  EXPECT_EQ(publisher.fits().size(),
            2 * static_cast<std::size_t>(std::count_if(steps.begin(), steps.end(), [](auto& s) {
              return s.status == StepStatus::Ok;
            })));
}

// The demo's first 30 s with a gap in each foot's stream: 100 s in the left foot's from 15 s on,
// 0.3 s in the right foot's from 20 s on.
fs::path demo_with_gaps() {
  static const fs::path path = [] {
    const fs::path to = test::scratch_dir("monitor-gap") / "gaps.csv";
    SessionReader reader(demo_30s());
    SessionWriter writer(to, reader.header());
    Frame frame;
    while (reader.next(frame)) {
      const double cut_s = frame.foot == Foot::Left ? 15.0 : 20.0;
      const double gap_s = frame.foot == Foot::Left ? 100.0 : 0.3;
      // Whole microseconds, as a device clock gives them.
      if (frame.t_s >= cut_s) frame.t_s = std::round((frame.t_s + gap_s) * 1e6) / 1e6;
      writer.write(frame);
    }
    writer.close();
    return to;
  }();
  return path;
}

TEST(Monitor, StepsEqualTheBatchPipelinesAcrossAGap) {
  const Config config = shipped_config();
  std::vector<Step> steps;
  const SegmentedSessionInfo info = segment_session(
      demo_with_gaps(), config, [&](Step&& step) { steps.push_back(std::move(step)); });
  EXPECT_EQ(info.gaps_per_foot[0], 1);
  EXPECT_EQ(info.gaps_per_foot[1], 1);
  for (const Step& step : steps) {
    EXPECT_LT(step.t_toe_off_s - step.t_heel_strike_s, 5.0)
        << foot_name(step.foot) << " step " << step.index << " spans a gap";
  }
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(demo_with_gaps(), &header);

  RecordingPublisher publisher;
  MonitorOptions options = quick_replay();
  options.sample_rate_hz = header.sample_rate_hz;
  Config quiet = config;
  quiet.monitor.publish_frames = false;
  MonitorCounters counters;
  {
    Monitor monitor(quiet, options, publisher);
    offer_all(monitor, frames);
    monitor.stop();
    counters = monitor.counters();
  }
  EXPECT_EQ(counters.segmentation_gaps, 2u);
  ASSERT_FALSE(publisher.statuses().empty());
  EXPECT_EQ(publisher.statuses().back().segmentation_gaps, 2u);
  EXPECT_EQ(counters.frames_processed, frames.size());
  std::size_t ok_steps = 0;
  ASSERT_NO_FATAL_FAILURE(expect_events_of(publisher.events(), steps, ok_steps));
  EXPECT_EQ(publisher.fits().size(), ok_steps);
}

// The config's [sensor_creep] is undone in every frame before the segmenter sees it, as
// segment_session undoes it: the same steps and fits as the batch pipeline under that config, and
// not those of the readings as read (on insoles that creep so, the metatarsals' kbar as read was
// 46 % off its truth over the steps of a 12-s session, and 1 % with the creep undone).
TEST(Monitor, UndoesTheConfigsSensorCreepAsTheBatchPipelineDoes) {
  Config config = shipped_config();
  config.sensor_creep = {0.4, 1.0};
  config.monitor.publish_frames = false;
  const fs::path dir = test::scratch_dir("monitor-creep");
  SimulationOptions simulation;
  simulation.size = InsoleSize::S41_42;
  simulation.seed = 117;
  simulation.duration_s = 10.0;
  simulate_session(config, simulation, dir / "creep.csv", dir / "creep.json");
  const std::vector<Step> steps = batch_steps(dir / "creep.csv", config);
  SessionHeader header;
  const std::vector<SensorFrame> frames = test::session_frames(dir / "creep.csv", &header);

  RecordingPublisher publisher;
  MonitorOptions options;
  options.sample_rate_hz = header.sample_rate_hz;
  options.backlog_overflow = BacklogOverflow::Wait;
  {
    Monitor monitor(config, options, publisher);
    offer_all(monitor, frames);
    monitor.stop();
    EXPECT_EQ(monitor.counters().frames_processed, frames.size());
  }
  std::size_t ok_steps = 0;
  ASSERT_NO_FATAL_FAILURE(expect_events_of(publisher.events(), steps, ok_steps));
  ASSERT_GE(ok_steps, 10u);
  std::map<StepKey, FitReport> fit_of;
  for (const FitReport& fit : publisher.fits()) fit_of[{fit.foot, fit.step}] = fit;
  ASSERT_EQ(fit_of.size(), ok_steps);

  const Config as_read = shipped_config();
  std::map<StepKey, Step> read_steps;
  for (Step& step : batch_steps(dir / "creep.csv", as_read)) {
    read_steps.emplace(StepKey{step.foot, step.index}, std::move(step));
  }
  const InsoleLayout layout(config.insole(header.insole_size), config.sensor);
  std::size_t fits = 0, off = 0;
  for (const Step& step : steps) {
    if (step.status != StepStatus::Ok) continue;
    const std::string at = fmt::format("{} step {}", foot_name(step.foot), step.index);
    const FitReport& got = fit_of.at({step.foot, step.index});
    const StepAnalysis expected = analyse_step(step, layout, config, options.analysis);
    expect_close(got.nrmse_total_pct, expected.nrmse_total_pct, at + " nrmse_total");
    for (const RegionAnalysis& r : expected.regions) {
      if (r.fit.status != FitStatus::Ok) continue;
      expect_close(got.regions[index_of(r.region)].kbar_n_per_mm3, r.fit.kbar_n_per_mm3.value,
                   at + " " + std::string(region_name(r.region)) + " kbar");
    }
    const auto read = read_steps.find({step.foot, step.index});
    if (read == read_steps.end() || read->second.status != StepStatus::Ok) continue;
    const StepAnalysis read_analysis =
        analyse_step(read->second, layout, as_read, options.analysis);
    const RegionFit& met = read_analysis.regions[index_of(Region::Met1_2)].fit;
    const RegionFitReport& undone = got.regions[index_of(Region::Met1_2)];
    if (met.status != FitStatus::Ok || undone.status != "ok") continue;
    ++fits;
    off += std::abs(met.kbar_n_per_mm3.value / undone.kbar_n_per_mm3 - 1.0) > 0.1;
  }
  ASSERT_GE(fits, 5u);
  EXPECT_GE(off, fits / 2) << "as read, met1_2's kbar is more than 10 % off in most steps";
}

TEST(Monitor, ADeviceRestartThatReadsAsAJumpForwardRestartsTheSegmentation) {
  // A device that restarts after 2^31 us (36 min) of uptime: modulo 2^32 its counter moves
  // forward by less than 2^31, so DeviceClock sees time jump ahead rather than go back.
  const Config config = shipped_config();
  const std::vector<Step> steps = batch_steps(demo_30s(), config);
  const std::vector<SensorFrame> once = test::session_frames(demo_30s());
  std::map<Foot, std::int64_t> frames_per_foot;
  std::map<Foot, int> steps_per_foot;
  for (const SensorFrame& f : once) ++frames_per_foot[f.foot];
  for (const Step& s : steps) ++steps_per_foot[s.foot];
  std::vector<SensorFrame> feed = once;
  for (SensorFrame& f : feed) f.device_time_us += 2'200'000'000u;
  feed.insert(feed.end(), once.begin(), once.end());

  RecordingPublisher publisher;
  Config quiet = config;
  quiet.monitor.publish_frames = false;
  MonitorCounters counters;
  {
    Monitor monitor(quiet, quick_replay(), publisher);
    offer_all(monitor, feed);
    monitor.stop();
    counters = monitor.counters();
  }
  EXPECT_EQ(counters.segmentation_gaps, 2u);
  std::map<StepKey, StepEvent> heel_strikes;
  for (const StepEvent& e : publisher.events()) {
    if (e.kind == StepEvent::Kind::HeelStrike) heel_strikes[{e.foot, e.step}] = e;
  }
  // Both passes give the session's steps, the second numbered on after the first.
  ASSERT_EQ(heel_strikes.size(), 2 * steps.size());
  for (const Step& s : steps) {
    const StepEvent& second = heel_strikes.at({s.foot, s.index + steps_per_foot[s.foot]});
    EXPECT_EQ(second.frame, s.heel_strike_frame + frames_per_foot[s.foot]);
  }
}

}  // namespace
}  // namespace gaitmon
