// The self-contained HTML page of `gaitmon discrepancy --report`: inline SVG and CSS only.
#pragma once

#include <string>

#include "gaitmon/discrepancy.hpp"

namespace gaitmon::cli {

/// Residual maps before and after, candidates, per-region and per-step held-out NRMSE.
std::string render_discrepancy_html(const std::string& session_name,
                                    const DiscrepancyResult& result);

}  // namespace gaitmon::cli
