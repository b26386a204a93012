// Conversions between the Publisher structs and the generated LCM types, shared by the publisher
// and the subscriber so that both directions live side by side.
#pragma once

#include <gaitmon/effects_t.hpp>
#include <gaitmon/fit_t.hpp>
#include <gaitmon/frame_t.hpp>
#include <gaitmon/raw_t.hpp>
#include <gaitmon/status_t.hpp>
#include <gaitmon/step_t.hpp>
#include <gaitmon/tissue_t.hpp>
#include <optional>

#include "gaitmon/publisher.hpp"

namespace gaitmon::lcm_messages {

// Into a message the caller keeps, so that strings and vectors reuse their storage.
void to_lcm(const FrameReport& report, frame_t& message);
void to_lcm(const StepEvent& event, step_t& message);
void to_lcm(const FitReport& report, fit_t& message);
void to_lcm(const StatusReport& report, status_t& message);
void to_lcm(const RawFrameReport& report, raw_t& message);
void to_lcm(const EffectsReport& report, effects_t& message);
void to_lcm(const TissueReport& report, tissue_t& message);

// nullopt when a field holds a value the struct cannot (a foot other than 0 or 1, an unknown
// region or step kind, a negative counter or step count, num_bits or num_params disagreeing with
// its array).
std::optional<FrameReport> from_lcm(const frame_t& message);
std::optional<StepEvent> from_lcm(const step_t& message);
std::optional<FitReport> from_lcm(const fit_t& message);
std::optional<StatusReport> from_lcm(const status_t& message);
std::optional<RawFrameReport> from_lcm(const raw_t& message);
std::optional<EffectsReport> from_lcm(const effects_t& message);
std::optional<TissueReport> from_lcm(const tissue_t& message);

}  // namespace gaitmon::lcm_messages
