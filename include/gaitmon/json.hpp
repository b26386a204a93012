// JSON forms of the model's value types, shared by every file gaitmon writes (truth files,
// session.json), so a parameter set is spelt the same way everywhere.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "gaitmon/discrepancy.hpp"
#include "gaitmon/tissue_model.hpp"

namespace gaitmon {

/// {"A_mm": ..., "B_mm": ..., "C_mm": ..., "d0_mm": ..., "kbar_n_per_mm3": ..., "n": ...,
/// "cbar_ns_per_mm3": ..., "m": ...}; found by nlohmann::json through argument-dependent lookup.
void to_json(nlohmann::json& j, const EllipsoidParams& p);

/// {"step_regions": ..., "baseline_heldout_nrmse_pct": ..., "extended_heldout_nrmse_pct": ...},
/// the two errors null where no step-region of the region was fitted (0 would read as a fit
/// without error).
void to_json(nlohmann::json& j, const RegionComparison& c);

/// {"value": ..., "se": ..., "robust_se": ...}, an error null where it is not finite.
void to_json(nlohmann::json& j, const ParamEstimate& p);

/// `j` as the text of a file, indented by 2, with bytes that are not UTF-8 (a file name or a
/// header's subject given in another encoding) replaced by U+FFFD rather than thrown on after
/// all the work.
std::string json_file_text(const nlohmann::json& j);

}  // namespace gaitmon
