// The live monitor's machinery: the detector loop, the bounded step backlog and its workers, the
// per-foot reorder buffer and the status. The threading contract is in monitor.hpp.
#include "gaitmon/monitor.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <boost/asio/post.hpp>
#include <boost/asio/thread_pool.hpp>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <new>
#include <optional>
#include <span>
#include <stdexcept>
#include <stop_token>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "gaitmon/batch.hpp"
#include "gaitmon/creep.hpp"
#include "gaitmon/device_clock.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/frame_ring.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/log_throttle.hpp"
#include "gaitmon/segmentation.hpp"
#include "gaitmon/stance.hpp"

namespace gaitmon {
namespace {

using Clock = std::chrono::steady_clock;

// How long the detector sleeps when the ring is empty: at 200 frames/s it wakes about every
// frame, and the delay it adds to a step's latency stays far below the 20 ms budget.
constexpr auto kIdlePoll = std::chrono::microseconds(500);
// Frames the detector takes from the ring at a time: their slots are free again at once, and the
// ring's indices cross between the cores once per batch rather than per frame.
constexpr std::size_t kPopBatch = 64;
// Fit latencies kept for the status percentiles: the latest ones, about 8 minutes of walking.
constexpr std::size_t kLatencyWindow = 1024;
// The least time between two reports of the regions' tissue: walking gives a step every quarter
// second or more, so each gets its own at real time, and a replay at full speed is not slowed.
constexpr auto kTissuePeriod = std::chrono::milliseconds(100);

double ms_between(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double, std::milli>(to - from).count();
}

std::string region_status(const RegionFit& fit) {
  std::string status(fit_status_name(fit.status));
  if (fit.status == FitStatus::Failed) status += ":" + fit.reason;
  return status;
}

// `pooling`: the tables of the area the step was fitted on (pooling_tables).
FitReport fit_report(const StepAnalysis& analysis, const PoolingSettings& pooling,
                     const FitBounds& bounds, bool& failed) {
  FitReport report;
  report.foot = analysis.foot;
  report.step = analysis.step;
  report.t_heel_strike_s = analysis.t_heel_strike_s;
  report.t_toe_off_s = analysis.t_toe_off_s;
  report.nrmse_total_pct = analysis.nrmse_total_pct;
  failed = false;
  for (const RegionAnalysis& r : analysis.regions) {
    RegionFitReport& out = report.regions[index_of(r.region)];
    const RegionFit& f = r.fit;
    out.region = r.region;
    out.status = region_status(f);
    failed = failed || f.status == FitStatus::Failed;
    if (f.status != FitStatus::Ok) continue;  // parameters stay 0 unless the fit is usable
    out.kbar_n_per_mm3 = f.kbar_n_per_mm3.value;
    out.n = f.n.value;
    out.cbar_ns_per_mm3 = f.cbar_ns_per_mm3.value;
    out.m = f.m.value;
    out.se_kbar = f.kbar_n_per_mm3.se;
    out.se_n = f.n.se;
    out.se_cbar = f.cbar_ns_per_mm3.se;
    out.se_m = f.m.se;
    if (const std::optional<MaterialParams> total =
            with_chain_error(f, r.region, pooling, bounds)) {
      out.se_kbar_total = total->kbar_n_per_mm3.se;
      out.se_n_total = total->n.se;
      out.se_cbar_total = total->cbar_ns_per_mm3.se;
      out.se_m_total = total->m.se;
    }
    out.A_mm = f.A_mm.value;
    out.B_mm = f.B_mm.value;
    out.C_mm = f.C_mm.value;
    out.d0_mm = f.d0_mm.value;
    out.nrmse_pct = f.nrmse_pct;
  }
  return report;
}

FitReport failed_report(const Step& step, const std::string& reason) {
  FitReport report;
  report.foot = step.foot;
  report.step = step.index;
  report.t_heel_strike_s = step.t_heel_strike_s;
  report.t_toe_off_s = step.t_toe_off_s;
  for (Region region : kRegions) {
    report.regions[index_of(region)].region = region;
    report.regions[index_of(region)].status =
        std::string(fit_status_name(FitStatus::Failed)) + ":" + reason;
  }
  return report;
}

EffectsReport effects_report(const ExtendedModelFit& fit, std::span<const Step> steps) {
  EffectsReport report;
  report.steps = static_cast<int>(steps.size());
  report.t_first_heel_strike_s = steps.front().t_heel_strike_s;
  report.t_last_toe_off_s = steps.front().t_toe_off_s;
  for (const Step& step : steps) {
    report.t_first_heel_strike_s = std::min(report.t_first_heel_strike_s, step.t_heel_strike_s);
    report.t_last_toe_off_s = std::max(report.t_last_toe_off_s, step.t_toe_off_s);
  }
  report.baseline_nrmse_pct = fit.baseline_nrmse_pct;
  report.extended_nrmse_pct = fit.extended_nrmse_pct;
  report.baseline_heldout_nrmse_pct = fit.baseline_heldout_nrmse_pct;
  report.extended_heldout_nrmse_pct = fit.extended_heldout_nrmse_pct;
  for (const EffectEstimate& effect : fit.effects) {
    for (const ParamEstimate& p : effect.params) {
      report.params.push_back({effect.name, p.name, p.value, p.se});
    }
  }
  return report;
}

/// The latest estimate's effects that sit inside the tissue fit (effect_inside_tissue_fit), as
/// each step after it is fitted with them.
struct InsideEffects {
  std::vector<EffectEstimate> estimates;
  std::vector<std::string> names;
  std::string joined;      ///< FitReport::effects_inside
  std::int64_t utime = 0;  ///< of the EffectsReport that published the estimate
  double history_s = 0.0;  ///< how far back a foot's earlier steps still carry into its step
};

// stress_relaxation carries a step's lag into the next ones, decaying with its time constant:
// after 20 of them e^-20 (2e-9) of it is left, far below a bit.
constexpr double kCarriedTimeConstants = 20.0;

// Null where no effect of the estimate sits inside the tissue fit.
std::shared_ptr<const InsideEffects> inside_effects(const ExtendedModelFit& fit,
                                                    std::int64_t utime) {
  auto inside = std::make_shared<InsideEffects>();
  for (const EffectEstimate& effect : fit.effects) {
    if (!effect_inside_tissue_fit(effect.name)) continue;
    inside->estimates.push_back(effect);
    inside->names.push_back(effect.name);
    inside->joined += (inside->joined.empty() ? "" : ",") + effect.name;
    for (const ParamEstimate& p : effect.params) {
      if (effect.name == "stress_relaxation" && p.name == "tau_s") {
        inside->history_s = std::max(inside->history_s, kCarriedTimeConstants * p.value);
      }
    }
  }
  if (inside->estimates.empty()) return nullptr;
  inside->utime = utime;
  return inside;
}

// Nearest rank: the smallest value with at least p of the values at or below it.
double percentile(std::vector<double>& values, double p) {
  if (values.empty()) return 0.0;
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(values.size())));
  const auto at = values.begin() + static_cast<std::ptrdiff_t>(std::max<std::size_t>(rank, 1) - 1);
  std::nth_element(values.begin(), at, values.end());
  return *at;
}

}  // namespace

// Region-frames of evidence the monitor weighs before it says how the cells read: about eight
// steps, four times the least that favours a reading (CellReadingEvidence::favoured), as it says
// so once and the first steps of a walk may be a person settling into it.
constexpr int kCellEvidenceFrames = 40;

struct Monitor::Impl {
  struct Ready {
    FitReport report;
    Clock::time_point finalised;
    bool failed = false;
  };
  /// Per foot, by step order: results that finished before an earlier step's. nullopt marks a
  /// step with nothing to publish (dropped, or lost after its analysis).
  using Outcomes = std::map<std::uint64_t, std::optional<Ready>>;
  /// A step's entry in its foot's Outcomes, allocated before the step takes its place in the
  /// order: filing an outcome then allocates nothing, so a step lost because memory ran out
  /// cannot hold back the results after it.
  using Slot = Outcomes::node_type;
  struct Job {
    Foot foot = Foot::Left;
    Slot slot;  ///< its key is the step's place in the foot's order
    Step step;
    std::shared_ptr<const InsoleLayout> layout;
    Clock::time_point finalised;
    std::uint64_t arrival = 0;  ///< among both feet's steps, in the detector's finalising order
  };
  struct Reorder {
    std::uint64_t next = 0;
    bool draining = false;  ///< a thread is publishing from this buffer
    Outcomes pending;
  };
  /// The latest complete steps for the extended model, keyed by the order in which the detector
  /// finalised them (both feet), so that the window and the fit do not depend on the order in
  /// which the workers finish. Not by time: after a device restart its foot's clock runs behind
  /// the other's by the time the device was down, and the window would shut out that foot's
  /// new steps as old.
  struct EffectWindow {
    std::map<std::uint64_t, std::pair<Step, StepAnalysis>> steps;
    std::shared_ptr<const InsoleLayout> layout;  ///< of the first step; one insole per session
    std::size_t fresh = 0;  ///< steps in the window added since the last fit took its copy
    bool fitting = false;   ///< a fit is queued or running
    std::optional<EffectsReport> last;  ///< the latest published
    /// Of the latest estimate published while running, for the steps fitted after it.
    std::shared_ptr<const InsideEffects> inside;
    bool last_is_current = false;  ///< `last` is of the window as it is now
  };
  /// [model] m_per_session: the latest analysed Ok steps' own fits, keyed as the EffectWindow's,
  /// and the running m per region over them.
  struct ExponentWindow {
    std::map<std::uint64_t, StepAnalysis> steps;
    std::size_t fresh = 0;  ///< steps added since the last estimate took its copy
    bool fitting = false;   ///< an estimate is queued or running
    std::shared_ptr<const SharedExponents> current;  ///< the latest, for the steps after it
  };
  /// One step's own fits as the pooled tissue takes them: each region's material estimate where
  /// the fit determined it.
  struct TissueStep {
    Foot foot = Foot::Left;
    int step = 0;
    double t_heel_strike_s = 0.0;
    double t_toe_off_s = 0.0;
    std::array<std::optional<MaterialEstimate>, kRegionCount> regions;
  };
  /// Detector-thread state of one foot.
  struct FootState {
    bool started = false;
    InsoleSize size = InsoleSize::S37_38;
    std::shared_ptr<const InsoleLayout> layout;
    std::optional<StepSegmenter> segmenter;
    Frame frame;  ///< reused: its bits keep their capacity
    std::optional<DeviceClock> clock;
    std::uint32_t last_device_us = 0;  ///< for the logs of a clock reset and of a gap
    std::int64_t gaps = 0;             ///< the segmenter's gaps already counted and logged
    std::uint64_t next_seq = 0;
    std::vector<double> zero;     ///< latest known per-sensor bias
    double threshold_bits = 0.0;  ///< latest known adaptive threshold
  };

  Impl(const Config& config_in, MonitorOptions options_in, Publisher& publisher_in)
      : config(config_in),
        options(std::move(options_in)),
        publisher(publisher_in),
        ring(config.ring.capacity_frames),
        status_period(std::chrono::duration_cast<Clock::duration>(
            std::chrono::duration<double>(config.monitor.status_period_s))),
        pool(static_cast<std::size_t>(config.monitor.workers)),
        insoles_creep(creep_correction_of(config.sensor_creep)) {
    latencies.reserve(kLatencyWindow);
    if (!config.model.effects.empty()) effects_thread.emplace(1);
    if (config.model.m_per_session) exponent_thread.emplace(1);
    detector = std::thread([this] { detector_main(); });
  }

  // ---- detector thread ----

  void detector_main() {
    try {
      std::vector<SensorFrame> batch(kPopBatch);
      next_status = Clock::now() + status_period;
      for (;;) {
        bool any = false;
        while (const std::size_t n = ring.try_pop_batch(batch)) {
          any = true;
          for (std::size_t i = 0; i < n; ++i) handle(batch[i]);
          // Between batches only: within one, its frames are out of the ring but not yet
          // counted as processed or rejected, and a status would miss them.
          maybe_status();
        }
        if (input_done.load(std::memory_order_acquire)) {
          while (const std::size_t n = ring.try_pop_batch(batch)) {
            for (std::size_t i = 0; i < n; ++i) handle(batch[i]);
          }
          break;
        }
        maybe_status();
        if (!any) std::this_thread::sleep_for(kIdlePoll);
      }
      finish_foot(Foot::Left);
      finish_foot(Foot::Right);
    } catch (const std::exception& e) {
      // Only resource exhaustion gets here (handle() contains per-frame errors). Refuse further
      // frames so that a replay waiting for room does not wait forever.
      closed.store(true);
      spdlog::error("monitor: the detector thread stopped: {}", e.what());
    }
  }

  /// At the end of input. Memory running out here loses what this foot still held, and not
  /// the other foot's last step.
  void finish_foot(Foot which) noexcept {
    FootState& foot = feet[static_cast<std::size_t>(which)];
    if (!foot.started) return;
    try {
      finalised.clear();
      foot.segmenter->finish(finalised);
      deliver(foot);
    } catch (const std::exception& e) {
      finalised.clear();
      spdlog::error("monitor: foot {}: the step still open at the end of input was lost: {}",
                    foot_name(which), e.what());
    }
  }

  void handle(const SensorFrame& in) {
    try {
      if (in.foot != Foot::Left && in.foot != Foot::Right) {
        reject("a frame names no known foot");
        return;
      }
      FootState& foot = feet[static_cast<std::size_t>(in.foot)];
      if (!foot.started) start(foot, in);
      if (in.size != foot.size) {
        reject(fmt::format("foot {}: insole size {} after {}", foot_name(in.foot),
                           insole_size_name(in.size), insole_size_name(foot.size)));
        return;
      }
      if (in.sensor_count != foot.layout->sensor_count()) {
        reject(fmt::format("foot {}: {} sensors, the {} layout has {}", foot_name(in.foot),
                           in.sensor_count, insole_size_name(foot.size),
                           foot.layout->sensor_count()));
        return;
      }
      const double previous_t_s = foot.frame.t_s;
      const std::uint32_t previous_us = foot.last_device_us;
      if (!advance_time(foot, in)) return;
      foot.frame.t_s = foot.clock->t_s();
      foot.frame.foot = in.foot;
      foot.frame.bits.assign(in.bits.begin(), in.bits.begin() + in.sensor_count);
      if (insoles_creep) insoles_creep->undo(foot.frame);
      finalised.clear();
      foot.segmenter->push(foot.frame, finalised);
      processed.fetch_add(1, std::memory_order_relaxed);
      if (foot.segmenter->gaps() != foot.gaps) {
        foot.gaps = foot.segmenter->gaps();
        note_gap(in, foot.frame.t_s - previous_t_s, previous_us);
      }
      const std::int64_t index = foot.segmenter->frames() - 1;
      if (config.monitor.publish_frames) publish_frame(foot, index);
      if (options.publish_raw) publish_raw(in);
      deliver(foot);
    } catch (const std::exception& e) {
      reject(e.what());
    }
  }

  void start(FootState& foot, const SensorFrame& in) {
    if (index_of(in.size) >= kInsoleSizeCount) throw std::invalid_argument("unknown insole size");
    const InsoleSpec& spec = config.insole(in.size);
    foot.size = in.size;
    foot.layout = std::make_shared<const InsoleLayout>(spec, config.sensor);
    foot.zero.assign(foot.layout->sensor_count(), 0.0);
    foot.threshold_bits = 0.0;
    foot.clock.emplace(options.sample_rate_hz);
    new_segmenter(foot, in.foot);
    foot.started = true;
    spdlog::info("monitor: foot {} is a {} insole with {} sensors", foot_name(in.foot),
                 insole_size_name(in.size), foot.layout->sensor_count());
  }

  void new_segmenter(FootState& foot, Foot which) {
    const InsoleSpec& spec = config.insole(foot.size);
    foot.segmenter.emplace(which, foot.layout->sensor_count(), config.segmentation,
                           spec.adaptive_threshold_pct,
                           config.calibration.newtons_per_bit(config.sensor.area_mm2()),
                           segmenter_limits(options.sample_rate_hz));
  }

  /// Unwraps the 32-bit device clock; false (rejected) if it did not advance.
  bool advance_time(FootState& foot, const SensorFrame& in) {
    const std::uint32_t previous_us = foot.last_device_us;
    switch (foot.clock->advance(in.device_time_us)) {
      case DeviceClock::Tick::Repeated:
        reject(fmt::format("foot {}: device time {} us did not advance", foot_name(in.foot),
                           in.device_time_us));
        return false;
      case DeviceClock::Tick::WentBack:
        restart(foot, in, previous_us);
        break;
      case DeviceClock::Tick::First:
      case DeviceClock::Tick::Forward:
        break;
    }
    foot.last_device_us = in.device_time_us;
    return true;
  }

  /// The device clock went back: end this foot's segmentation as at the end of a recording.
  void restart(FootState& foot, const SensorFrame& in, std::uint32_t previous_us) {
    spdlog::warn("monitor: foot {}: device clock went back from {} to {} us; segmentation restarts",
                 foot_name(in.foot), previous_us, in.device_time_us);
    finalised.clear();
    foot.segmenter->restart(finalised);
    deliver(foot);
  }

  /// The segmenter restarted after a gap; a flaky link can make many, hence the throttle.
  void note_gap(const SensorFrame& in, double gap_s, std::uint32_t previous_us) {
    segmentation_gaps.fetch_add(1, std::memory_order_relaxed);
    if (auto held = gap_log.allow()) {
      spdlog::warn(
          "monitor: foot {}: {:.3f} s without frames (device time {} -> {} us), over "
          "[segmentation] "
          "max_gap_s; segmentation restarts ({} similar suppressed)",
          foot_name(in.foot), gap_s, previous_us, in.device_time_us, *held);
    }
  }

  void reject(const std::string& why) {
    rejected.fetch_add(1, std::memory_order_relaxed);
    if (auto held = reject_log.allow()) {
      spdlog::warn("monitor: frame rejected: {} ({} similar suppressed)", why, *held);
    }
  }

  void publish_frame(const FootState& foot, std::int64_t index) {
    const auto samples = measure_frame(foot.frame.bits, foot.zero, foot.threshold_bits,
                                       *foot.layout, config.calibration, false, &ellipses, scratch);
    frame_report.utime = now_utime();
    frame_report.foot = foot.frame.foot;
    frame_report.frame = index;
    frame_report.t_s = foot.frame.t_s;
    for (Region region : kRegions) {
      const RegionSample& s = samples[index_of(region)];
      RegionFrameReport& r = frame_report.regions[index_of(region)];
      r.force_n = s.force_n;
      r.active_area_mm2 = s.sensor_area_mm2;
      r.ellipse_case = static_cast<std::uint8_t>(s.ellipse.kase);
      r.centre_x_mm = s.ellipse.cx_mm;
      r.centre_y_mm = s.ellipse.cy_mm;
      r.ra_mm = s.ellipse.ra_mm;
      r.rb_mm = s.ellipse.rb_mm;
      r.angle_rad = s.ellipse.angle_rad;
      r.ellipse_area_mm2 = s.ellipse.area_mm2;
    }
    send(frame_report);
  }

  void publish_raw(const SensorFrame& in) {
    raw_report.utime = now_utime();
    raw_report.foot = in.foot;
    raw_report.sequence = in.sequence;
    raw_report.device_time_us = in.device_time_us;
    raw_report.bits.assign(in.bits.begin(), in.bits.begin() + in.sensor_count);
    send(raw_report);
  }

  /// Publishes the steps in `finalised` (from foot's segmenter) and queues the Ok ones.
  void deliver(FootState& foot) {
    for (Step& step : finalised) {
      steps_detected.fetch_add(1, std::memory_order_relaxed);
      StepEvent event;
      event.utime = now_utime();
      event.foot = step.foot;
      event.step = step.index;
      event.kind = StepEvent::Kind::HeelStrike;
      event.complete = step.status == StepStatus::Ok;
      event.frame = step.heel_strike_frame;
      event.t_s = step.t_heel_strike_s;
      send(event);
      event.kind = StepEvent::Kind::ToeOff;
      event.frame = step.toe_off_frame;
      event.t_s = step.t_toe_off_s;
      send(event);
      if (step.status != StepStatus::Ok) continue;
      foot.zero = step.sensor_zero_bits;
      foot.threshold_bits = step.adaptive_threshold_bits;
      queue_step(foot, std::move(step));
    }
    finalised.clear();
  }

  /// The step takes its place in the foot's order only once its slot is allocated.
  void queue_step(FootState& foot, Step step) {
    Slot slot;
    try {
      Outcomes one;
      one.emplace(foot.next_seq, std::nullopt);
      slot = one.extract(one.begin());
    } catch (const std::bad_alloc& e) {
      count_drop(step, e.what());
      return;
    }
    ++foot.next_seq;
    enqueue(Job{step.foot, std::move(slot), std::move(step), foot.layout, Clock::now(),
                next_arrival++});
  }

  /// A step no worker will take. Allocates nothing, so that a dropped step is always filed.
  void count_drop(const Step& step, const char* why) {
    const std::uint64_t drops = step_drops.fetch_add(1, std::memory_order_relaxed) + 1;
    if (auto held = step_drop_log.allow()) {
      spdlog::warn(
          "monitor: dropped foot {} step {}: {}; {} dropped so far ({} similar messages "
          "suppressed)",
          foot_name(step.foot), step.index, why, drops, *held);
    }
  }

  void enqueue(Job job) {
    const auto max_backlog = static_cast<std::size_t>(config.monitor.max_step_backlog);
    std::optional<Job> dropped;
    {
      std::unique_lock lock(jobs_mutex);
      if (options.backlog_overflow == BacklogOverflow::Wait) {
        room.wait(lock, [&] { return jobs.size() < max_backlog; });
      }
      try {
        jobs.push_back(std::move(job));  // strong guarantee: on failure the job is intact
      } catch (const std::bad_alloc& e) {
        lock.unlock();
        count_drop(job.step, e.what());
        complete(job.foot, std::move(job.slot), std::nullopt);
        return;
      }
      steps_queued.fetch_add(1, std::memory_order_relaxed);
      if (jobs.size() > max_backlog) {
        dropped.emplace(std::move(jobs.front()));
        jobs.pop_front();
      }
      backlog.store(jobs.size(), std::memory_order_relaxed);
      // A runner that could not be posted leaves the step queued for the next, or for stop().
      if (runners < config.monitor.workers) {
        try {
          boost::asio::post(pool, [this] { run_jobs(); });
          ++runners;
        } catch (const std::bad_alloc& e) {
          spdlog::error("monitor: no worker started for foot {} step {}: {}; it waits",
                        foot_name(jobs.back().foot), jobs.back().step.index, e.what());
        }
      }
    }
    if (dropped) {
      count_drop(dropped->step, "the step backlog is full ([monitor] max_step_backlog)");
      complete(dropped->foot, std::move(dropped->slot), std::nullopt);
    }
  }

  void maybe_status() {
    const auto now = Clock::now();
    if (now < next_status) return;
    next_status = now + status_period;
    publish_status(false);
  }

  /// With the ring drops of the period. A status that cannot be built (memory ran out) is lost
  /// and logged, and the run goes on.
  void publish_status(bool final) noexcept {
    try {
      log_ring_drops(final ? std::string("since the last status")
                           : fmt::format("in the last {:.1f} s", config.monitor.status_period_s));
      send(status(final));
    } catch (const std::exception& e) {
      spdlog::error("monitor: a status report was lost: {}", e.what());
    }
  }

  // Once per status period, and at the end for what the last period left: a run shorter than
  // one period still says that it lost frames.
  void log_ring_drops(std::string_view when) {
    const std::uint64_t drops = ring.drops();
    if (drops <= ring_drops_logged) return;
    spdlog::warn("monitor: ring full: {} frames dropped {}, {} in all", drops - ring_drops_logged,
                 when, drops);
    ring_drops_logged = drops;
  }

  // ---- workers ----

  /// Adds the step to the evidence of how the cells read until it holds kCellEvidenceFrames
  /// region-frames, then says once whether the area the fits take is the footprint the favoured
  /// reading calls for: a live fit cannot wait for the session's evidence, as `analyze --area
  /// auto` does. Where the cells show crosstalk that [model] effects leave out, it says so too.
  void weigh_cells(const Job& job) {
    if (cells_clear.load(std::memory_order_relaxed)) return;
    const CellReadingEvidence step = cell_reading_evidence(job.step, *job.layout);
    const std::lock_guard lock(cells_mutex);
    if (cells_clear.load(std::memory_order_relaxed)) return;
    cells += step;
    const CellReadingFits& fits = cells.fits();
    if (fits.frames < kCellEvidenceFrames) return;
    cells_clear.store(true, std::memory_order_relaxed);
    if (crosstalk_left_out(cells, config.model.effects)) {
      spdlog::warn(
          "monitor: the cells' readings fit their caps best with a crosstalk of {:.3f} undone "
          "({} region-frames): neighbouring cells read part of each other's load, which the fits "
          "take up as tissue; add \"crosstalk\" to [model] effects to fit it",
          cells.coupling(), fits.frames);
    }
    const AreaSource area = options.analysis.area;
    const std::optional<CellReading> favoured = cells.favoured();
    if (!favoured) {
      spdlog::info(
          "monitor: {} region-frames do not show how the cells read the pressure ({} fit "
          "averaging cells better); the fits take the {} area",
          fits.frames, fits.mean_better, area_source_name(area));
      return;
    }
    const bool mean = *favoured == CellReading::Mean;
    const double coupling = cells.coupling();
    const std::string evidence = fmt::format(
        "the cells read the pressure {} ({} of {} region-frames fit averaging cells better{})",
        mean ? "averaged over their area" : "at their centres", fits.mean_better, fits.frames,
        coupling > 0.0 ? fmt::format(", with a crosstalk of {:.3f} undone", coupling) : "");
    if (mean && area == AreaSource::Footprint) {
      spdlog::warn(
          "monitor: {}: the footprint the fits take over-reads such cells (n comes out about "
          "twice the truth); set [model] area = \"footprint-mean\" (analyze takes it by itself)",
          evidence);
    } else if (!mean && area == AreaSource::FootprintMean) {
      spdlog::warn(
          "monitor: {}: the footprint-mean the fits take is biased on such cells (n comes out "
          "at a tenth to a quarter of the truth); set [model] area = \"footprint\"",
          evidence);
    } else {
      spdlog::info("monitor: {}; the fits take the {} area", evidence, area_source_name(area));
    }
  }

  /// One runner per worker at most: each takes the oldest waiting step until none is left.
  void run_jobs() {
    static thread_local ContactEllipseCache cache;
    for (;;) {
      std::optional<Job> job;
      {
        const std::lock_guard lock(jobs_mutex);
        if (jobs.empty()) {
          --runners;
          return;
        }
        job.emplace(std::move(jobs.front()));
        jobs.pop_front();
        backlog.store(jobs.size(), std::memory_order_relaxed);
      }
      room.notify_one();
      std::optional<StepAnalysis> analysis;
      std::optional<Ready> ready(Ready{{}, job->finalised, false});
      try {
        try {
          analysis = analyse_step(job->step, *job->layout, config, options.analysis, &cache);
          weigh_cells(*job);
          std::shared_ptr<const InsideEffects> inside;
          const std::optional<StepAnalysis> extended = fit_with_effects(*job, *analysis, inside);
          std::shared_ptr<const SharedExponents> running;
          const std::optional<StepAnalysis> at_running = fit_at_running_m(*job, *analysis, running);
          ready->report = fit_report(extended     ? *extended
                                     : at_running ? *at_running
                                                  : *analysis,
                                     pooling_tables(config, options.analysis.area),
                                     config.fit_bounds, ready->failed);
          if (extended) {
            ready->report.effects_inside = inside->joined;
            ready->report.effects_utime = inside->utime;
          }
          if (at_running) set_m_steps(*at_running, *running, ready->report);
        } catch (const std::exception& e) {
          // Logged before its report is built, which may fail too.
          if (auto held = fit_log.allow()) {
            spdlog::warn("monitor: foot {} step {}: analysis failed: {} ({} similar suppressed)",
                         foot_name(job->foot), job->step.index, e.what(), *held);
          }
          ready->report = failed_report(job->step, e.what());
          ready->failed = true;
        }
      } catch (const std::exception& e) {
        // A failed fit rather than a drop: step_drops counts steps no worker took; this one was
        // taken, and no fit came of it.
        fits_failed.fetch_add(1, std::memory_order_relaxed);
        spdlog::error("monitor: foot {} step {} lost: {}", foot_name(job->foot), job->step.index,
                      e.what());
        ready.reset();
      }
      complete(job->foot, std::move(job->slot), std::move(ready));
      if (analysis) add_to_tissue(job->arrival, *analysis);
      if (analysis && !config.model.effects.empty()) {
        remember_for_effects(job->arrival, std::move(job->step), std::move(*analysis), job->layout);
      } else if (analysis && config.model.m_per_session) {
        remember_for_running_m(job->arrival, std::move(*analysis));
      }
    }
  }

  // ---- each region's tissue over the latest steps (GAITMON_TISSUE) ----

  /// Adds a step's own fits to the window and has the tissue thread publish the pools over it.
  /// Never throws: the step's fit is out.
  void add_to_tissue(std::uint64_t arrival, const StepAnalysis& analysis) noexcept {
    try {
      auto entry = std::make_shared<TissueStep>(TissueStep{
          analysis.foot, analysis.step, analysis.t_heel_strike_s, analysis.t_toe_off_s, {}});
      for (const RegionAnalysis& r : analysis.regions) {
        entry->regions[index_of(r.region)] = material_estimate(r.fit);
      }
      const std::lock_guard lock(tissue_mutex);
      tissue_window.insert_or_assign(arrival, std::move(entry));
      while (tissue_window.size() > static_cast<std::size_t>(config.monitor.tissue_window_steps)) {
        tissue_window.erase(tissue_window.begin());
      }
      tissue_fresh = true;
      if (!tissue_publishing) {
        boost::asio::post(tissue_thread, [this] { publish_tissue(); });
        tissue_publishing = true;
      }
    } catch (const std::exception& e) {
      if (auto held = tissue_log.allow()) {
        spdlog::warn(
            "monitor: foot {} step {}: left out of the regions' tissue over the steps: {} ({} "
            "similar suppressed)",
            foot_name(analysis.foot), analysis.step, e.what(), *held);
      }
    }
  }

  /// The window as it is, oldest first.
  std::vector<std::shared_ptr<const TissueStep>> tissue_snapshot() const {
    std::vector<std::shared_ptr<const TissueStep>> steps;
    steps.reserve(tissue_window.size());
    for (const auto& [arrival, s] : tissue_window) steps.push_back(s);
    return steps;
  }

  /// On the tissue thread: publishes the pools over the window until no step came in during the
  /// last, at most one every kTissuePeriod. Pooling the window takes milliseconds, so that a
  /// replay at full speed would otherwise spend more time on it than on the steps' fits. Never
  /// throws: it runs on a pool thread.
  void publish_tissue() noexcept {
    for (;;) {
      std::vector<std::shared_ptr<const TissueStep>> steps;
      try {
        {
          const std::lock_guard lock(tissue_mutex);
          if (!tissue_fresh) {
            tissue_publishing = false;
            return;
          }
          tissue_fresh = false;
          steps = tissue_snapshot();
        }
        TissueReport report = tissue_report(steps);
        report.utime = now_utime();
        send(report);
      } catch (const std::exception& e) {
        if (auto held = tissue_log.allow()) {
          spdlog::warn(
              "monitor: the regions' tissue over the steps was not published: {} ({} similar "
              "suppressed)",
              e.what(), *held);
        }
      }
      std::unique_lock lock(tissue_mutex);
      tissue_wake.wait_for(lock, kTissuePeriod, [this] { return tissue_ending; });
    }
  }

  /// The pools over `steps` (oldest first, at least one), after the last of them.
  TissueReport tissue_report(std::span<const std::shared_ptr<const TissueStep>> steps) const {
    TissueReport report;
    const TissueStep& latest = *steps.back();
    report.foot = latest.foot;
    report.step = latest.step;
    report.t_first_heel_strike_s = latest.t_heel_strike_s;
    report.t_last_toe_off_s = latest.t_toe_off_s;
    for (const auto& s : steps) {
      report.t_first_heel_strike_s = std::min(report.t_first_heel_strike_s, s->t_heel_strike_s);
      report.t_last_toe_off_s = std::max(report.t_last_toe_off_s, s->t_toe_off_s);
    }
    const bool default_fit =
        options.analysis.fit.mode == FitMode::Identifiable && !options.analysis.fit.free_scale;
    std::vector<MaterialEstimate> estimates;
    for (std::size_t i = 0; i < kRegionCount; ++i) {
      RegionTissueReport& out = report.regions[i];
      out.region = kRegions[i];
      estimates.clear();
      for (const auto& s : steps) {
        if (s->regions[i]) estimates.push_back(*s->regions[i]);
      }
      out.steps = static_cast<int>(estimates.size());
      if (!default_fit) {
        out.status = "not_pooled:pooling needs the default fit (identifiable, P declared)";
        continue;
      }
      const PoolingSettings& tables = pooling_tables(config, options.analysis.area);
      const PooledEstimates pooled =
          pool_region_steps(estimates, kRegions[i], tables, config.fit_bounds);
      const std::optional<MaterialEstimate> mean =
          pooled_mean_with_chain_error(pooled, chain_sd(tables, kRegions[i], false));
      if (!mean) {
        out.status = "not_pooled:" + pooled.not_pooled;
        continue;
      }
      const MaterialParams p = material_params(*mean);
      out.status = "ok";
      out.kbar_n_per_mm3 = p.kbar_n_per_mm3.value;
      out.n = p.n.value;
      out.cbar_ns_per_mm3 = p.cbar_ns_per_mm3.value;
      out.m = p.m.value;
      out.se_kbar = p.kbar_n_per_mm3.se;
      out.se_n = p.n.se;
      out.se_cbar = p.cbar_ns_per_mm3.se;
      out.se_m = p.m.se;
    }
    return report;
  }

  /// At the end of the run, once the workers and the tissue thread are done: the pools over the
  /// window as it ends, marked final.
  void finish_tissue() noexcept {
    try {
      std::vector<std::shared_ptr<const TissueStep>> steps;
      {
        const std::lock_guard lock(tissue_mutex);
        steps = tissue_snapshot();
      }
      if (steps.empty()) return;
      TissueReport report = tissue_report(steps);
      report.final_estimate = true;
      report.utime = now_utime();
      send(report);
    } catch (const std::exception& e) {
      spdlog::error("monitor: the regions' final tissue over the steps was not published: {}",
                    e.what());
    }
  }

  // ---- the running m ([model] m_per_session) ----

  /// The step fitted again at the latest running m per region (fit_at_shared_exponents);
  /// nullopt, and the step's own fit published, before the first estimate, without the setting
  /// and where this fit failed (logged). `used` is the estimate.
  std::optional<StepAnalysis> fit_at_running_m(const Job& job, const StepAnalysis& own,
                                               std::shared_ptr<const SharedExponents>& used) {
    if (!config.model.m_per_session) return std::nullopt;
    {
      const std::lock_guard lock(exponent_mutex);
      used = exponent_window.current;
    }
    if (!used) return std::nullopt;
    try {
      StepAnalysis at = own;
      fit_at_shared_exponents(at, *used, config, options.analysis);
      return at;
    } catch (const std::exception& e) {
      if (auto held = exponent_log.allow()) {
        spdlog::warn(
            "monitor: foot {} step {}: the fit at the running m failed, the step's own fit is "
            "published: {} ({} similar suppressed)",
            foot_name(job.foot), job.step.index, e.what(), *held);
      }
      used.reset();
      return std::nullopt;
    }
  }

  /// Each region fitted at the running m says over how many steps that m was taken.
  static void set_m_steps(const StepAnalysis& at, const SharedExponents& running,
                          FitReport& report) {
    for (const RegionAnalysis& r : at.regions) {
      const auto& shared = running[index_of(r.region)];
      if (shared && r.fit.status == FitStatus::Ok && !r.fit.m.free) {
        report.regions[index_of(r.region)].m_steps = shared->stances;
      }
    }
  }

  /// Adds a step's own fit to the window. An estimate starts once there are kFirstSharedMSteps
  /// steps, then whenever the new steps are as many as the old ones (10, 20, 40, ...; every half
  /// window once full), as the extended model's do. Never throws: the step's fit is out.
  void remember_for_running_m(std::uint64_t arrival, StepAnalysis analysis) noexcept {
    try {
      const std::lock_guard lock(exponent_mutex);
      ExponentWindow& w = exponent_window;
      w.steps.insert_or_assign(arrival, std::move(analysis));
      while (w.steps.size() > static_cast<std::size_t>(config.model.m_window_steps)) {
        w.steps.erase(w.steps.begin());
      }
      w.fresh = std::min(w.fresh + 1, w.steps.size());
      const auto first = static_cast<std::size_t>(kFirstSharedMSteps);
      if (w.fitting || w.steps.size() < first ||
          w.fresh < std::max(first, w.steps.size() - w.fresh)) {
        return;
      }
      boost::asio::post(*exponent_thread, [this] { estimate_running_m(); });
      w.fitting = true;
    } catch (const std::exception& e) {
      if (auto held = exponent_log.allow()) {
        spdlog::warn(
            "monitor: a step was left out of the running m, or its estimate could not "
            "be started: {} ({} similar suppressed)",
            e.what(), *held);
      }
    }
  }

  /// The running m over a copy of the window, for the steps fitted after it. Skipped once the
  /// run is interrupted. Never throws: it runs on a pool thread.
  void estimate_running_m() noexcept {
    std::size_t count = 0;
    std::shared_ptr<const SharedExponents> estimate;
    try {
      std::vector<StepAnalysis> steps;
      {
        const std::lock_guard lock(exponent_mutex);
        if (!interrupted.load()) {
          for (const auto& [arrival, analysis] : exponent_window.steps) steps.push_back(analysis);
          exponent_window.fresh = 0;
        }
      }
      count = steps.size();
      if (count > 0) {
        const auto start = Clock::now();
        estimate = std::make_shared<const SharedExponents>(
            shared_damping_exponents(steps, config, options.analysis));
        spdlog::debug("monitor: the running m over {} steps took {:.0f} ms", count,
                      ms_between(start, Clock::now()));
      }
    } catch (const std::exception& e) {
      if (auto held = exponent_log.allow()) {
        spdlog::warn(
            "monitor: the running m could not be estimated over {} steps: {} ({} similar "
            "suppressed)",
            count, e.what(), *held);
      }
    }
    const std::lock_guard lock(exponent_mutex);
    if (estimate) {
      exponent_window.current = std::move(estimate);
      m_estimates.fetch_add(1, std::memory_order_relaxed);
    }
    exponent_window.fitting = false;
  }

  /// The step fitted again with the latest estimate's effects inside its tissue fit, given the
  /// earlier steps of its foot in the window that still carry into it (as `analyze --effects`
  /// fits a session's steps, with the history the window holds when the step is fitted).
  /// nullopt, and the baseline published, before the first estimate, where no configured effect
  /// sits inside the tissue fit, and where this fit failed (logged). `used` is the estimate.
  std::optional<StepAnalysis> fit_with_effects(const Job& job, const StepAnalysis& baseline,
                                               std::shared_ptr<const InsideEffects>& used) {
    if (config.model.effects.empty()) return std::nullopt;
    {
      const std::lock_guard lock(effects_mutex);
      used = effect_window.inside;
    }
    if (!used) return std::nullopt;
    try {
      std::vector<Step> steps;
      std::vector<StepAnalysis> analyses;
      {
        const std::lock_guard lock(effects_mutex);
        const EffectWindow& w = effect_window;
        // Only earlier steps by the foot's own clock: after a device restart the steps before it
        // run ahead of it, and the restart broke the tissue's history anyway.
        const double from_s = job.step.t_heel_strike_s - used->history_s;
        if (used->history_s > 0.0 && w.layout &&
            w.layout->sensor_count() == job.layout->sensor_count()) {
          for (const auto& [arrival, entry] : w.steps) {
            const Step& s = entry.first;
            if (s.foot == job.step.foot && s.t_heel_strike_s < job.step.t_heel_strike_s &&
                s.t_toe_off_s > from_s) {
              steps.push_back(s);
              analyses.push_back(entry.second);
            }
          }
        }
      }
      steps.push_back(job.step);
      analyses.push_back(baseline);
      const DiscrepancyInput input = extended_model_input(
          steps, std::move(analyses), *job.layout, config, used->names, options.analysis.area);
      return fit_step_with_effects(input, input.steps.size() - 1, used->estimates, config,
                                   options.analysis);
    } catch (const std::exception& e) {
      if (auto held = effects_log.allow()) {
        spdlog::warn(
            "monitor: foot {} step {}: the fit with {} inside failed, the baseline fit is "
            "published: {} ({} similar suppressed)",
            foot_name(job.foot), job.step.index, used->joined, e.what(), *held);
      }
      used.reset();
      return std::nullopt;
    }
  }

  /// Steps still queued once the pool is done: only if posting their runner failed.
  void run_leftover_jobs() {
    {
      const std::lock_guard lock(jobs_mutex);
      if (jobs.empty()) return;
      ++runners;
    }
    run_jobs();
  }

  /// Files one outcome (nullopt: nothing to publish) in its slot and publishes every result now
  /// in order. One thread at a time drains a foot's buffer, publishing outside the lock, so
  /// neither the detector (filing a dropped step) nor another worker ever waits for a slow
  /// publisher. Allocates nothing.
  void complete(Foot foot, Slot slot, std::optional<Ready> ready) {
    slot.mapped() = std::move(ready);
    std::unique_lock lock(publish_mutex);
    Reorder& r = reorder[static_cast<std::size_t>(foot)];
    r.pending.insert(std::move(slot));
    if (r.draining) return;
    r.draining = true;
    while (!r.pending.empty() && r.pending.begin()->first == r.next) {
      auto node = r.pending.extract(r.pending.begin());
      ++r.next;
      if (!node.mapped()) continue;
      Ready& done = *node.mapped();
      lock.unlock();
      done.report.utime = now_utime();
      done.report.latency_ms = ms_between(done.finalised, Clock::now());
      send(done.report);
      lock.lock();
      if (latencies.size() < kLatencyWindow) {
        latencies.push_back(done.report.latency_ms);
      } else {
        latencies[latency_next] = done.report.latency_ms;
      }
      latency_next = (latency_next + 1) % kLatencyWindow;
      fits_published.fetch_add(1, std::memory_order_relaxed);
      if (done.failed) fits_failed.fetch_add(1, std::memory_order_relaxed);
    }
    r.draining = false;
  }

  // ---- the extended model ([model] effects) ----

  /// Adds an analysed step to the window. A fit starts once there is a step per fold, then
  /// whenever the new steps are as many as the old ones (5, 10, 20, ...; every half window once
  /// full), so its cost stays proportional to the steps. Never throws: the step's fit is out.
  void remember_for_effects(std::uint64_t arrival, Step step, StepAnalysis analysis,
                            std::shared_ptr<const InsoleLayout> layout) noexcept {
    try {
      add_to_effect_window(arrival, std::move(step), std::move(analysis), std::move(layout));
    } catch (const std::exception& e) {
      if (auto held = effects_log.allow()) {
        spdlog::warn(
            "monitor: a step was left out of the extended model: {} ({} similar "
            "suppressed)",
            e.what(), *held);
      }
    }
  }

  void add_to_effect_window(std::uint64_t arrival, Step step, StepAnalysis analysis,
                            std::shared_ptr<const InsoleLayout> layout) {
    const std::lock_guard lock(effects_mutex);
    EffectWindow& w = effect_window;
    if (!w.layout) w.layout = layout;
    if (w.layout->sensor_count() != layout->sensor_count()) {
      if (auto held = effects_log.allow()) {
        spdlog::warn(
            "monitor: foot {} step {}: another insole size than the first step's; left "
            "out of the extended model ({} similar suppressed)",
            foot_name(step.foot), step.index, *held);
      }
      return;
    }
    w.steps.insert_or_assign(arrival, std::pair(std::move(step), std::move(analysis)));
    while (w.steps.size() > static_cast<std::size_t>(config.model.effects_window_steps)) {
      w.steps.erase(w.steps.begin());
    }
    // Capped at the window: a step that has left it again is not new in it, and below, size -
    // fresh counts the old steps even when the window turned over while a fit ran.
    w.fresh = std::min(w.fresh + 1, w.steps.size());
    w.last_is_current = false;
    const std::size_t folds = static_cast<std::size_t>(DiscrepancySettings{}.folds);
    if (w.fitting || w.steps.size() < folds ||
        w.fresh < std::max(folds, w.steps.size() - w.fresh)) {
      return;
    }
    // Marked once posted (the fit waits for this lock): the step is in the window either way,
    // and after a post that fails the next step tries again.
    try {
      boost::asio::post(*effects_thread, [this] { fit_effects(false); });
      w.fitting = true;
    } catch (const std::bad_alloc& e) {
      if (auto held = effects_log.allow()) {
        spdlog::warn(
            "monitor: the extended model's fit to {} steps could not be started: {}; the next "
            "step starts it ({} similar suppressed)",
            w.steps.size(), e.what(), *held);
      }
    }
  }

  /// Fits the extended model to a copy of the window and publishes it; false where it published
  /// nothing. When the run is interrupted a fit still queued is skipped and a running one stops.
  /// Never throws: it runs on a pool thread, where an exception would end the program.
  bool fit_effects(bool final_estimate) noexcept {
    std::size_t count = 0;
    std::optional<EffectsReport> report;
    std::shared_ptr<const InsideEffects> inside;
    try {
      std::vector<Step> steps;
      std::vector<StepAnalysis> analyses;
      std::shared_ptr<const InsoleLayout> layout;
      {
        const std::lock_guard lock(effects_mutex);
        if (interrupted.load()) {
          effect_window.fitting = false;
          return false;
        }
        count = effect_window.steps.size();
        for (const auto& [key, entry] : effect_window.steps) {
          steps.push_back(entry.first);
          analyses.push_back(entry.second);
        }
        layout = effect_window.layout;
        effect_window.fresh = 0;
      }
      if (final_estimate) {
        spdlog::info("monitor: fitting the extended model to the {} steps of the window as it ends",
                     count);
      }
      const ExtendedModelFit fit =
          fit_extended_model(extended_model_input(steps, std::move(analyses), *layout, config,
                                                  config.model.effects, options.analysis.area),
                             config.model.effects, {}, effects_stop.get_token());
      report = effects_report(fit, steps);
      report->final_estimate = final_estimate;
      report->utime = now_utime();
      send(*report);
      inside = inside_effects(fit, report->utime);
    } catch (const FitStopped&) {
      spdlog::debug("monitor: the extended model's fit to {} steps stopped", count);
    } catch (const std::exception& e) {
      if (auto held = effects_log.allow()) {
        spdlog::warn(
            "monitor: the extended model could not be fitted to {} steps: {} ({} similar "
            "suppressed)",
            count, e.what(), *held);
      }
    }
    const std::lock_guard lock(effects_mutex);
    const bool sent = report.has_value();
    effect_window.last_is_current = sent && effect_window.fresh == 0;
    if (report) effect_window.last = std::move(report);
    if (inside) effect_window.inside = std::move(inside);
    effect_window.fitting = false;
    return sent;
  }

  /// At shutdown, after the workers: the final estimate, over the window as it ends. An
  /// interrupted run (close()) publishes its latest estimate instead, as a fit of the window
  /// could take longer than a signal's shutdown may; so does a run whose final fit close()
  /// stopped or that failed.
  /// Never throws: stop() runs it, and ~Monitor() calls stop().
  void finish_effects() noexcept {
    if (config.model.effects.empty()) return;
    try {
      std::size_t held = 0;
      bool current = false;
      {
        const std::lock_guard lock(effects_mutex);
        held = effect_window.steps.size();
        current = effect_window.last_is_current;
      }
      const bool refit = !current && !interrupted.load() &&
                         held >= static_cast<std::size_t>(DiscrepancySettings{}.folds);
      if (refit && fit_effects(true)) return;
      std::optional<EffectsReport> last;
      {
        const std::lock_guard lock(effects_mutex);
        last = effect_window.last;
      }
      if (last) {
        if (refit) {
          spdlog::info(
              "monitor: the latest estimate of the extended model, over {} steps, is the "
              "final one",
              last->steps);
        }
        last->final_estimate = true;
        last->utime = now_utime();
        send(*last);
      } else if (held < static_cast<std::size_t>(DiscrepancySettings{}.folds)) {
        spdlog::warn("monitor: {} complete steps are too few for the extended model (it needs {})",
                     held, DiscrepancySettings{}.folds);
      } else if (interrupted.load()) {
        spdlog::warn("monitor: stopped before the extended model's first estimate");
      } else {
        spdlog::warn("monitor: the extended model has no estimate to publish as the final one");
      }
    } catch (const std::exception& e) {
      spdlog::error("monitor: the extended model's final estimate was lost: {}", e.what());
    }
  }

  // ---- any thread ----

  template <typename Message>
  void send(const Message& message) {
    try {
      publisher.publish(message);
    } catch (const std::exception& e) {
      const std::uint64_t failures = publish_failures.fetch_add(1, std::memory_order_relaxed) + 1;
      if (auto held = publish_log.allow()) {
        spdlog::warn(
            "monitor: publishing failed, the message is lost: {}; {} lost so far ({} "
            "similar suppressed)",
            e.what(), failures, *held);
      }
    }
  }

  MonitorCounters counters() const {
    MonitorCounters c;
    c.ring_drops = ring.drops();
    c.frames_offered = ring.pushed() + c.ring_drops;
    c.frames_refused = refused.load(std::memory_order_relaxed);
    c.ring_depth = ring.depth();
    c.frames_processed = processed.load(std::memory_order_relaxed);
    c.frames_rejected = rejected.load(std::memory_order_relaxed);
    c.steps_detected = steps_detected.load(std::memory_order_relaxed);
    c.steps_queued = steps_queued.load(std::memory_order_relaxed);
    c.step_backlog = backlog.load(std::memory_order_relaxed);
    c.step_drops = step_drops.load(std::memory_order_relaxed);
    c.fits_published = fits_published.load(std::memory_order_relaxed);
    c.fits_failed = fits_failed.load(std::memory_order_relaxed);
    c.segmentation_gaps = segmentation_gaps.load(std::memory_order_relaxed);
    c.publish_failures = publish_failures.load(std::memory_order_relaxed);
    c.m_estimates = m_estimates.load(std::memory_order_relaxed);
    return c;
  }

  StatusReport status(bool final) {
    StatusReport s;
    s.connection = "connected";
    if (options.driver_status) {
      try {
        options.driver_status(s);
      } catch (const std::exception& e) {
        spdlog::warn("monitor: the driver's status failed: {}", e.what());
      }
    }
    if (final) s.connection = "finished";
    const MonitorCounters c = counters();
    s.utime = now_utime();
    s.ring_depth = c.ring_depth;
    s.ring_drops = c.ring_drops;
    s.frames_processed = c.frames_processed;
    s.frames_rejected = c.frames_rejected;
    s.segmentation_gaps = c.segmentation_gaps;
    s.steps_detected = c.steps_detected;
    s.step_backlog = c.step_backlog;
    s.step_drops = c.step_drops;
    s.fits_published = c.fits_published;
    s.fits_failed = c.fits_failed;
    std::vector<double> window;
    {
      const std::lock_guard lock(publish_mutex);
      window = latencies;
    }
    s.fit_latency_p50_ms = percentile(window, 0.50);
    s.fit_latency_p99_ms = percentile(window, 0.99);
    return s;
  }

  void stop() {
    const std::lock_guard lock(stop_mutex);
    if (stopped) return;
    closed.store(true);
    input_done.store(true, std::memory_order_release);
    if (detector.joinable()) detector.join();
    pool.join();
    run_leftover_jobs();
    {
      const std::lock_guard lock(tissue_mutex);
      tissue_ending = true;
    }
    tissue_wake.notify_all();
    tissue_thread.join();
    if (effects_thread) effects_thread->join();
    if (exponent_thread) exponent_thread->join();
    finish_effects();
    finish_tissue();
    publish_status(true);
    stopped = true;
  }

  const Config config;
  const MonitorOptions options;
  Publisher& publisher;
  FrameRing ring;
  const Clock::duration status_period;
  std::atomic<bool> closed{false};
  std::atomic<std::uint64_t> refused{0};  ///< offers after close(), by the driver thread
  std::atomic<bool> interrupted{false};   ///< close() was called: a signal, not the end of input
  std::stop_source effects_stop;          ///< requested with `interrupted`
  std::atomic<bool> input_done{false};
  std::mutex stop_mutex;
  bool stopped = false;

  // Detector thread only.
  std::array<FootState, 2> feet;
  ContactEllipseCache ellipses;
  FrameScratch scratch;
  std::vector<Step> finalised;
  FrameReport frame_report;
  RawFrameReport raw_report;
  Clock::time_point next_status;
  std::uint64_t ring_drops_logged = 0;
  std::uint64_t next_arrival = 0;  ///< both feet's steps, in the order they were finalised

  std::atomic<std::uint64_t> processed{0}, rejected{0}, steps_detected{0}, steps_queued{0},
      backlog{0}, step_drops{0}, fits_published{0}, fits_failed{0}, segmentation_gaps{0},
      publish_failures{0}, m_estimates{0};

  // The backlog, shared by the detector and the workers.
  std::mutex jobs_mutex;
  std::condition_variable room;
  std::deque<Job> jobs;
  int runners = 0;

  // Publication of fits, shared by the workers (and the detector for dropped steps).
  std::mutex publish_mutex;
  std::array<Reorder, 2> reorder;
  std::vector<double> latencies;
  std::size_t latency_next = 0;

  LogThrottle reject_log, step_drop_log, fit_log, publish_log, effects_log, gap_log, exponent_log,
      tissue_log;

  // Each region's tissue over the latest steps: the workers fill the window, the tissue thread
  // pools it.
  std::mutex tissue_mutex;
  std::condition_variable tissue_wake;  ///< ends the tissue thread's wait at shutdown
  std::map<std::uint64_t, std::shared_ptr<const TissueStep>> tissue_window;  ///< by arrival
  bool tissue_fresh = false;       ///< steps came in since the last report took its copy
  bool tissue_publishing = false;  ///< the tissue thread is posted or running
  bool tissue_ending = false;
  boost::asio::thread_pool tissue_thread{1};

  // The extended model's window: the workers fill it, the effects thread copies it.
  std::mutex effects_mutex;
  EffectWindow effect_window;

  boost::asio::thread_pool pool;
  /// The config's [sensor_creep], undone by the detector in every frame before it is segmented.
  std::optional<CreepCorrection> insoles_creep;
  /// With [model] effects: one thread for the extended model's fits, which take tenths of a
  /// second, so that a step finalised meanwhile waits for no fit but its own.
  std::optional<boost::asio::thread_pool> effects_thread;

  // How the cells read, from the workers' steps until it is clear (weigh_cells).
  std::mutex cells_mutex;
  CellReadingEvidence cells;
  std::atomic<bool> cells_clear{false};

  // The running m's window: the workers fill it, the exponent thread copies it.
  std::mutex exponent_mutex;
  ExponentWindow exponent_window;
  /// With [model] m_per_session: one thread for the running m's estimates.
  std::optional<boost::asio::thread_pool> exponent_thread;
  std::thread detector;
};

AreaSource live_area_source(const ModelSettings& model) {
  if (model.area == "auto") return AreaSource::Footprint;
  const std::optional<AreaSource> area = parse_area_source(model.area);
  if (!area) {
    throw std::invalid_argument("live_area_source: [model] area \"" + model.area +
                                "\" is not an area (load_config checks it)");
  }
  return *area;
}

Monitor::Monitor(const Config& config, MonitorOptions options, Publisher& publisher) {
  if (!(options.sample_rate_hz > 0.0) || !std::isfinite(options.sample_rate_hz)) {
    throw std::invalid_argument("Monitor: the sample rate must be positive");
  }
  if (config.monitor.workers < 1 || config.monitor.max_step_backlog < 1 ||
      !(config.monitor.status_period_s > 0.0)) {
    throw std::invalid_argument(
        "Monitor: workers, max_step_backlog and status_period_s must be "
        "positive");
  }
  const bool inside = std::any_of(config.model.effects.begin(), config.model.effects.end(),
                                  [](const std::string& e) { return effect_inside_tissue_fit(e); });
  if (inside &&
      (options.analysis.fit.mode != FitMode::Identifiable || options.analysis.fit.free_scale)) {
    throw std::invalid_argument(
        "Monitor: [model] effects inside the tissue fit need the default fit (identifiable "
        "parameters, P declared)");
  }
  if (config.model.m_per_session &&
      (!config.model.effects.empty() || options.analysis.fit.mode != FitMode::Identifiable ||
       options.analysis.fit.free_scale)) {
    throw std::invalid_argument(
        "Monitor: [model] m_per_session needs the default fit (identifiable parameters, P "
        "declared) and no [model] effects");
  }
  if (config.sensor_creep.gain > 0.0) {
    spdlog::info(
        "monitor: undoing the insoles' sensor creep of [sensor_creep] (gain {:.4g}, tau {:.4g} s) "
        "in every frame before it is segmented",
        config.sensor_creep.gain, config.sensor_creep.tau_s);
  }
  if (std::find(config.model.effects.begin(), config.model.effects.end(), "sensor_creep") !=
      config.model.effects.end()) {
    spdlog::info(
        "monitor: sensor_creep is estimated from the steps' zeros and published; each step is "
        "fitted from the readings as read{} (gaitmon analyze --effects sensor_creep undoes the "
        "creep it measures in the readings and measures every step again, and prints the "
        "[sensor_creep] that undoes it here)",
        config.sensor_creep.gain > 0.0 ? " with [sensor_creep] undone" : "");
  }
  // Checked once here: a segmenter that cannot be built would reject every frame.
  (void)StepSegmenter(Foot::Left, 1, config.segmentation, 0.0,
                      config.calibration.newtons_per_bit(config.sensor.area_mm2()),
                      segmenter_limits(options.sample_rate_hz));
  impl_ = std::make_unique<Impl>(config, std::move(options), publisher);
}

Monitor::~Monitor() {
  stop();
}

bool Monitor::offer(const SensorFrame& frame) {
  if (impl_->closed.load(std::memory_order_relaxed)) {
    impl_->refused.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  return impl_->ring.try_push(frame);
}

bool Monitor::offer_wait(const SensorFrame& frame) {
  if (impl_->closed.load(std::memory_order_relaxed) ||
      !impl_->ring.push_wait(frame, impl_->closed)) {
    impl_->refused.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  return true;
}

void Monitor::close() {
  impl_->interrupted.store(true);
  impl_->effects_stop.request_stop();
  impl_->closed.store(true);
}

void Monitor::stop() {
  impl_->stop();
}

MonitorCounters Monitor::counters() const {
  return impl_->counters();
}

}  // namespace gaitmon
