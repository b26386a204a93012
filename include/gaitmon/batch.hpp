// Batch processing of a recorded session: the same per-foot segmenters the live monitor uses,
// fed from a session file.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>

#include "gaitmon/config.hpp"
#include "gaitmon/segmentation.hpp"
#include "gaitmon/session.hpp"

namespace gaitmon {

struct SegmentedSessionInfo {
  SessionHeader header;
  std::array<std::int64_t, 2> frames_per_foot{};  ///< indexed by Foot
  /// Per foot, the gaps over [segmentation] max_gap_s after which its segmentation restarted.
  std::array<std::int64_t, 2> gaps_per_foot{};
};

/// Throws InputError naming `path` when a session recorded at `sample_rate_hz` cannot be
/// segmented with the config's [segmentation] (its windows in seconds become too few frames).
void check_session_rate(const std::filesystem::path& path, double sample_rate_hz,
                        const Config& config);

/// Streams the session at `path` through one StepSegmenter per foot and hands every step to
/// `on_step` as soon as it is final (feet interleave as in the file; within a foot in time
/// order). `on_progress`, if set, receives the fraction of the file read, now and then.
/// The config's [sensor_creep] is undone in each frame as read; then `correct_frame`, if set,
/// changes it further, before it is segmented (as CreepCorrection::undo does). Warns when the
/// header's rate disagrees with the times (warn_on_rate_mismatch). Throws InputError for a bad
/// session or one without frames, std::invalid_argument if the config lacks the size.
SegmentedSessionInfo segment_session(const std::filesystem::path& path, const Config& config,
                                     const std::function<void(Step&&)>& on_step,
                                     const std::function<void(double)>& on_progress = {},
                                     const std::function<void(Frame&)>& correct_frame = {});

}  // namespace gaitmon
