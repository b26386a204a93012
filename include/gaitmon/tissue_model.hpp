// The viscoelastic ellipsoid model of plantar tissue (seed ch. 2, corrected per model-notes.md).
// Implemented once, templated on the scalar so the simulator (double) and the fitter (Ceres Jet)
// evaluate the very same expressions.
#pragma once

#include <optional>
#include <string_view>

namespace gaitmon {

/// The seed's eight parameters of one region's ellipsoid (eqs 2, 37, 38). Units in the names.
struct EllipsoidParams {
  double A_mm = 0.0;             ///< semi-axis, lateral-medial
  double B_mm = 0.0;             ///< semi-axis, anterior-posterior
  double C_mm = 0.0;             ///< semi-axis, vertical
  double d0_mm = 0.0;            ///< unloaded tissue thickness in k = kbar (d/d0)^n
  double kbar_n_per_mm3 = 0.0;   ///< stiffness coefficient
  double n = 0.0;                ///< stiffness exponent
  double cbar_ns_per_mm3 = 0.0;  ///< damping coefficient
  double m = 0.0;                ///< damping exponent
};

/// Which sign the damping term carries. `Correct` is the integral of eq 22 (plus);
/// `SeedEq25` is the seed's printed minus (eqs 24, 25, 36, 41), kept for comparison.
enum class ModelVariant { Correct, SeedEq25 };

/// "correct" or "seed_eq25".
std::string_view model_variant_name(ModelVariant variant);
std::optional<ModelVariant> parse_model_variant(std::string_view text);

}  // namespace gaitmon
