// Drives the per-foot segmenters from a session file, exactly as the live monitor would.
#include "gaitmon/batch.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <optional>
#include <vector>

#include "gaitmon/creep.hpp"
#include "gaitmon/error.hpp"
#include "gaitmon/insole.hpp"

namespace gaitmon {

void check_session_rate(const std::filesystem::path& path, double sample_rate_hz,
                        const Config& config) {
  try {
    (void)StepSegmenter(Foot::Left, 1, config.segmentation, 0.0,
                        config.calibration.newtons_per_bit(config.sensor.area_mm2()),
                        segmenter_limits(sample_rate_hz));
  } catch (const std::invalid_argument& e) {
    // The session's rate against the config's windows in frames: both are valid alone.
    throw InputError(path.string(), 0,
                     fmt::format("sample_rate_hz {} does not fit [segmentation] of {}: {}",
                                 sample_rate_hz, config.source.string(), e.what()));
  }
}

SegmentedSessionInfo segment_session(const std::filesystem::path& path, const Config& config,
                                     const std::function<void(Step&&)>& on_step,
                                     const std::function<void(double)>& on_progress,
                                     const std::function<void(Frame&)>& correct_frame) {
  SessionReader reader(path);
  SegmentedSessionInfo info;
  info.header = reader.header();
  const InsoleSpec& spec = config.insole(info.header.insole_size);
  const double newtons_per_bit = config.calibration.newtons_per_bit(config.sensor.area_mm2());
  const SegmenterLimits limits = segmenter_limits(info.header.sample_rate_hz);
  check_session_rate(path, info.header.sample_rate_hz, config);
  std::array<std::optional<StepSegmenter>, 2> segmenters;
  for (Foot foot : kFeet) {
    segmenters[static_cast<std::size_t>(foot)].emplace(
        foot, info.header.sensors, config.segmentation, spec.adaptive_threshold_pct,
        newtons_per_bit, limits);
  }
  std::optional<CreepCorrection> insoles_creep = creep_correction_of(config.sensor_creep);
  const auto file_bytes = static_cast<double>(std::filesystem::file_size(path));
  std::vector<Step> finalised;
  Frame frame;
  auto deliver = [&] {
    for (Step& step : finalised) on_step(std::move(step));
    finalised.clear();
  };
  while (reader.next(frame)) {
    const auto foot = static_cast<std::size_t>(frame.foot);
    try {
      if (insoles_creep) insoles_creep->undo(frame);
      if (correct_frame) correct_frame(frame);
      segmenters[foot]->push(frame, finalised);
    } catch (const std::invalid_argument& e) {
      throw InputError(path.string(), reader.line(), e.what());
    }
    ++info.frames_per_foot[foot];
    deliver();
    if (on_progress && (reader.line() & 0x3FFF) == 0 && file_bytes > 0) {
      on_progress(std::min(1.0, static_cast<double>(reader.bytes_read()) / file_bytes));
    }
  }
  // A header alone would pass as a session in which nobody walked, with outputs of nothing.
  if (info.frames_per_foot[0] + info.frames_per_foot[1] == 0) {
    throw InputError(path.string(), 0, "no frames");
  }
  warn_on_rate_mismatch(reader);
  for (Foot foot : kFeet) {
    StepSegmenter& segmenter = *segmenters[static_cast<std::size_t>(foot)];
    segmenter.finish(finalised);
    info.gaps_per_foot[static_cast<std::size_t>(foot)] = segmenter.gaps();
  }
  deliver();
  if (on_progress) on_progress(1.0);
  return info;
}

}  // namespace gaitmon
