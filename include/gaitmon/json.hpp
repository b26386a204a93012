// JSON forms of the model's value types, shared by every file gaitmon writes (truth files,
// session.json), so a parameter set is spelt the same way everywhere.
#pragma once

#include <nlohmann/json.hpp>

#include "gaitmon/tissue_model.hpp"

namespace gaitmon {

/// {"A_mm": ..., "B_mm": ..., "C_mm": ..., "d0_mm": ..., "kbar_n_per_mm3": ..., "n": ...,
/// "cbar_ns_per_mm3": ..., "m": ...}; found by nlohmann::json through argument-dependent lookup.
void to_json(nlohmann::json& j, const EllipsoidParams& p);

}  // namespace gaitmon
