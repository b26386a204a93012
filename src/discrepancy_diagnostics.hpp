// The discrepancy workflow's residual diagnostics over its units, apart from the fitting so that
// they are tested on residuals made by hand. Internal: not part of the public API.
#pragma once

#include <span>
#include <vector>

#include "discrepancy_effects.hpp"
#include "gaitmon/discrepancy.hpp"

namespace gaitmon::discrepancy_detail {

/// The SD of white noise on a smooth series, from the scatter of its samples about the 5-point
/// quadratic (Savitzky-Golay) smoother, robust to outliers (MAD); 0 for fewer than 7 samples.
/// The MAD's factor is the Gaussian's: uniform noise (one channel's rounding) reads 5.5 % high.
double savgol_noise_sd(std::span<const double> y);

/// Residual y - pred per region and stance-phase bin (`bins` of normalised stance time): RMS,
/// mean and the noise floor's RMS, in newtons. Every region has `bins` cells, empty ones too.
ResidualMap residual_map(std::span<const Unit> units, const std::vector<std::vector<double>>& preds,
                         int bins);

/// The residuals over the units, each divided by its unit's peak force: the bias per phase bin,
/// the Wald-Wolfowitz runs test pooled over the units, and the Pearson correlation with the
/// model's state. Leaves lag1_autocorrelation and effective_sample_fraction to the caller, who
/// has them from the pooled fit.
ResidualDiagnostics diagnose(std::span<const Unit> units,
                             const std::vector<std::vector<double>>& preds, int bins);

}  // namespace gaitmon::discrepancy_detail
