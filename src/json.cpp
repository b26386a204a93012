// JSON forms of the model's value types.
#include "gaitmon/json.hpp"

#include <cmath>

namespace gaitmon {

void to_json(nlohmann::json& j, const EllipsoidParams& p) {
  j = {{"A_mm", p.A_mm},
       {"B_mm", p.B_mm},
       {"C_mm", p.C_mm},
       {"d0_mm", p.d0_mm},
       {"kbar_n_per_mm3", p.kbar_n_per_mm3},
       {"n", p.n},
       {"cbar_ns_per_mm3", p.cbar_ns_per_mm3},
       {"m", p.m}};
}

void to_json(nlohmann::json& j, const RegionComparison& c) {
  const auto nrmse = [&](double pct) { return c.step_regions > 0 ? nlohmann::json(pct) : nullptr; };
  j = {{"step_regions", c.step_regions},
       {"baseline_heldout_nrmse_pct", nrmse(c.baseline_heldout_nrmse_pct)},
       {"extended_heldout_nrmse_pct", nrmse(c.extended_heldout_nrmse_pct)}};
}

void to_json(nlohmann::json& j, const ParamEstimate& p) {
  const auto finite = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nullptr; };
  j = {{"value", p.value}, {"se", finite(p.se)}, {"robust_se", finite(p.robust_se)}};
}

std::string json_file_text(const nlohmann::json& j) {
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

}  // namespace gaitmon
