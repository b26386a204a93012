// The live monitor: decoded frames in, per-frame region reports, step events, per-step tissue
// fits and status out, through a Publisher.
//
// Threads and queues:
//  - The driver thread (the caller's) hands frames to offer() or offer_wait(). They go into a
//    FrameRing of config.ring.capacity_frames frames. offer() never waits: when the ring is full
//    the frame is dropped and counted (ring_drops). offer_wait() is for replays, which must not
//    skip frames: it waits for room instead.
//  - The detector thread (owned here) takes frames from the ring, one StepSegmenter per foot
//    (the algorithm of `gaitmon segment`, so the same frames give the same steps). Per frame it
//    publishes a FrameReport, and a RawFrameReport if enabled; per finalised step a HeelStrike
//    and a ToeOff StepEvent, and it queues Ok steps for the workers. It also publishes the
//    status every config.monitor.status_period_s.
//  - The step backlog holds at most config.monitor.max_step_backlog finalised steps waiting for
//    a worker. With BacklogOverflow::DropOldest (live runs) a step beyond it drops the OLDEST
//    waiting step, counted (step_drops), logged at most once a second and reported in the
//    status; nothing is published for a dropped step. With BacklogOverflow::Wait (replays) the
//    detector thread waits for room instead, so backpressure reaches offer_wait().
//  - config.monitor.workers threads (a Boost.Asio thread_pool) run analyse_step. Results are
//    published in step order per foot (a reorder buffer holds those that finish early), each
//    with latency_ms = publication time - the time the detector finalised the step.
//  - With [model] effects in the config, the workers also keep the latest
//    config.model.effects_window_steps analysed Ok steps (both feet, in the order the detector
//    finalised them: a restarted device's clock runs behind the other foot's), and
//    a thread of its own fits the extended model (discrepancy.hpp: make_discrepancy_input,
//    fit_extended_model) to them, once there are as many steps as folds (5) and again whenever
//    the new steps are as many as the old (5, 10, 20, ...; every half window once full), so
//    that no step waits for such a fit; each estimate is published as an EffectsReport. Over a
//    session no longer than the window, the final one equals `gaitmon analyze --effects` on it.
//    Once an estimate is out, each step the workers fit after it is fitted again with that
//    estimate's effects inside its tissue fit (fit_step_with_effects, given the earlier steps of
//    its foot in the window that carry into it), and its FitReport names them (effects_inside,
//    effects_utime); a step whose such fit fails is published with its baseline fit.
//  - With [model] m_per_session, the workers keep each analysed Ok step's own fit in a window of
//    the latest config.model.m_window_steps (both feet, in the detector's order), and a thread of
//    its own takes one damping exponent m per region over them (shared_damping_exponents), once
//    there are kFirstSharedMSteps and again whenever the new steps are as many as the old. Each
//    step the workers fit after an estimate is fitted again at it (fit_at_shared_exponents); its
//    FitReport's regions say over how many steps (m_steps); a step whose such fit fails is
//    published with its own. At shutdown a running estimate is waited for; one not yet started is
//    skipped once close() was called.
//  - Each analysed Ok step's own fits (at each step's own m, without effects, as `gaitmon
//    analyze` pools them) go into a window of the latest config.monitor.tissue_window_steps
//    (both feet, in the detector's order), and a thread of its own pools each region's over it
//    (pool_region_steps, with the SDs of [pooling], or of [pooling.footprint_mean] where [model]
//    area is "footprint-mean") and publishes a TissueReport: after each step, or
//    at most once every 100 ms, the steps that came in meanwhile taken together. Over a session
//    no longer than the window the final one equals `gaitmon analyze`'s pooled means.
//
// Time: a frame's session time is its device_time_us, unwrapped per foot across the 32-bit
// wrap, divided by 1e6 (for replays that is the session's t_s, which the drivers encode as
// round(t_s x 1e6)). A frame whose device time does not advance is rejected; a device clock that
// jumps back (the device restarted) ends that foot's segmentation as at the end of a recording
// and starts a new one, with frame and step numbers continuing and session time continuing one
// sample period after the last frame. A jump forward by more than [segmentation] max_gap_s (a
// link drop-out, lost frames, or a restart of a device whose counter had passed 2^31 us, which
// reads as a jump forward) does the same in the segmenter, as `gaitmon segment` does at a gap in
// a file; it is counted (segmentation_gaps) and logged at most once a second.
//
// Rejected frames (counted in frames_rejected, logged at most once a second): an insole size or
// sensor count other than that foot's first frame's or the config's layout's, and a device time
// that does not advance.
//
// Per-frame reports use the latest bias known for the foot: the per-sensor zero and adaptive
// threshold of its last finalised Ok step (the mean of the swings around that step); before the
// first one, no zeroing and a threshold of 0. Case 1's first-instant exception is not applied
// (the live stream does not know yet which frame starts a stance). The fits use the step's own
// bias, exactly as `gaitmon analyze`.
//
// Latency: a step is final when its post-swing midpoint is known, about one swing plus
// debounce_frames - 1 frames after its toe off (~0.45 s at 100 Hz in walking; segmentation.hpp).
// The fit's latency_ms is measured from then.
//
// Errors: exceptions never cross threads. A step whose analysis throws is published with every
// region's status fit_failed:<reason>; a frame that cannot be processed is rejected and counted;
// a Publisher that throws is counted (publish_failures), logged (rate-limited) and the message
// is lost. Memory running out loses what it hits and nothing after it: a step before a worker
// takes it (step_drops) or after its analysis (fits_failed), a status report, an estimate of
// the extended model, or at the end of input the step one foot's segmentation still held; each
// is logged, and later steps of the foot, and the other foot's, are still published in order.
//
// Shutdown, by stop(): (1) stop accepting: offer() and offer_wait() return false from now on;
// (2) the detector thread drains the ring, ends each foot's segmentation as at the end of a
// recording (its last steps are finalised and queued) and exits; (3) the workers finish every
// queued step and publish it; with effects, the extended model is fitted to the window as it
// ends (unless the last estimate already covers it, or close() was called: see there) and
// published with final_estimate set, and the regions' tissue over the window as it ends, with
// final_estimate set too; (4) the final status is published, its connection "finished"
// (the driver callback fills the other driver fields); (5) every thread is joined. The caller must
// have stopped its driver thread first (offer() may race with stop(), but a frame offered after the
// drain would be lost); close() alone does step (1), from any thread, to release a driver blocked
// in offer_wait(). close() also marks the run as interrupted (the commands call it on SIGINT and
// SIGTERM): stop() then publishes the latest estimate of the effects as the final one rather
// than fitting the window again, skips a fit still waiting for a worker and stops a running
// one (that of step (3) too), so that the shutdown stays within the 2 s. Where that
// last fit fails or is stopped, the latest estimate is the final one as well.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>

#include "gaitmon/analysis.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/publisher.hpp"
#include "gaitmon/sensor_frame.hpp"

namespace gaitmon {

enum class BacklogOverflow : std::uint8_t { DropOldest, Wait };

/// The area the live fits take for [model] area: the footprint for "auto", as a live fit cannot
/// wait for a session's evidence of how its cells read (the monitor names the footprint they call
/// for once its steps show it).
AreaSource live_area_source(const ModelSettings& model);

/// What a command decides at run time, beside the config.
struct MonitorOptions {
  /// The stream's frame rate, for the segmenter's memory bounds (segmenter_limits) and the time
  /// step after a device clock reset. Replays pass the session's.
  double sample_rate_hz = 100.0;
  AnalysisSettings analysis;
  BacklogOverflow backlog_overflow = BacklogOverflow::DropOldest;
  /// Also publish every frame as a RawFrameReport (the commands follow [lcm] raw_enabled).
  bool publish_raw = false;
  /// Fills the driver's fields of each status report (bytes_received, frames_decoded,
  /// crc_errors, resyncs, frames_lost_sequence, reconnects, connection). Called on the detector
  /// thread, and on the thread calling stop() for the final report: it must be thread-safe and
  /// must not block.
  std::function<void(StatusReport&)> driver_status;
};

/// Totals since start; readable from any thread.
struct MonitorCounters {
  std::uint64_t frames_offered = 0;  ///< offers accepted into the ring or dropped
  std::uint64_t frames_refused = 0;  ///< offers refused because the monitor was closed
  std::uint64_t ring_drops = 0;
  std::uint64_t ring_depth = 0;
  std::uint64_t frames_processed = 0;
  std::uint64_t frames_rejected = 0;
  std::uint64_t steps_detected = 0;  ///< finalised steps, Ok and incomplete
  std::uint64_t steps_queued = 0;    ///< Ok steps handed to the backlog
  std::uint64_t step_backlog = 0;    ///< waiting for a worker now
  /// Steps no worker took: the backlog overflowed, or memory ran out in queueing them.
  std::uint64_t step_drops = 0;
  std::uint64_t fits_published = 0;
  /// Steps whose analysis threw or a region failed (published with fit_failed), and steps lost
  /// to an error after their analysis (nothing published for them).
  std::uint64_t fits_failed = 0;
  /// Estimates of the running m made ([model] m_per_session).
  std::uint64_t m_estimates = 0;
  /// Frames of a foot more than [segmentation] max_gap_s after its previous one (lost frames, a
  /// link drop-out, a device restart seen as a jump forward): each restarted its segmentation.
  std::uint64_t segmentation_gaps = 0;
  /// Messages the Publisher threw on, lost (LcmPublisher never throws: it counts its own).
  std::uint64_t publish_failures = 0;
};

class Monitor {
 public:
  /// Starts the detector thread and the workers. Throws std::invalid_argument if the sample
  /// rate is not positive, a setting is out of its range (load_config has checked those), or
  /// an effect of [model] effects sits inside the tissue fit and options.analysis is not the
  /// default fit (fit_steps_with_effects), or [model] m_per_session is set with effects or
  /// outside the default fit.
  /// The publisher must outlive the monitor.
  Monitor(const Config& config, MonitorOptions options, Publisher& publisher);
  /// Calls stop().
  ~Monitor();
  Monitor(const Monitor&) = delete;
  Monitor& operator=(const Monitor&) = delete;

  /// Driver thread only. Queues the frame, or drops and counts it when the ring is full. Never
  /// waits. False if dropped or the monitor is closed (counted as refused).
  [[nodiscard]] bool offer(const SensorFrame& frame);

  /// Driver thread only. Queues the frame, waiting while the ring is full. False once the
  /// monitor is closed (the frame is then not queued, and counted as refused).
  [[nodiscard]] bool offer_wait(const SensorFrame& frame);

  /// Stop accepting frames, as an interrupted run (see above). Any thread; idempotent.
  void close();

  /// The shutdown sequence described above. Any thread but the driver's, once that has stopped
  /// offering; idempotent, later calls return at once.
  void stop();

  MonitorCounters counters() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gaitmon
