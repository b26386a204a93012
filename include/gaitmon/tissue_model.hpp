// The viscoelastic ellipsoid model of plantar tissue (seed ch. 2, corrected per model-notes.md).
// Implemented once, templated on the scalar so the simulator (double) and the fitter (Ceres Jet)
// evaluate the very same expressions.
#pragma once

#include <cmath>
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

/// Every function below that takes EllipsoidParams throws std::invalid_argument unless A, B, C
/// and d0 are positive and finite.

/// The damping term's form. `Correct` is the integral of eq 22 with the seed's local rate (eq
/// 15) and the plus sign (model-notes section 1); `SeedEq25` is the seed's printed minus (eqs
/// 24, 25, 36, 41), kept for comparison. `MaterialRate` takes the rate of a fixed column of
/// tissue, which is d-dot everywhere in the contact: eq 15 differentiates eq 14 at a fixed
/// normalised radius rho, and a point at fixed rho moves outward with the growing contact, so
/// its rate is not any tissue's. Its damping force is c ddot Ae.
enum class ModelVariant { Correct, SeedEq25, MaterialRate };

/// "correct", "seed_eq25" or "material_rate".
std::string_view model_variant_name(ModelVariant variant);
std::optional<ModelVariant> parse_model_variant(std::string_view text);

/// The damping term's sign: -1 for SeedEq25, +1 otherwise.
inline double damping_sign(ModelVariant variant) {
  return variant == ModelVariant::SeedEq25 ? -1.0 : 1.0;
}

/// The damping force's shape in g = d/C, so that the damping force is
/// P D g^(1+m) gdot damping_shape(g): (6 - 4g + g^2) / (3 (2 - g)) with eq 15's rate (it tends
/// to 1 at small g), 2 - g with the material rate (the contact area's own shape, Ae / (P g)).
template <class T>
T damping_shape(const T& g, ModelVariant variant) {
  if (variant == ModelVariant::MaterialRate) return T(2.0) - g;
  return (T(6.0) - T(4.0) * g + g * g) / (T(3.0) * (T(2.0) - g));
}

/// The five combinations of the eight parameters that force and contact area determine
/// (model-notes section 2): P = pi A B, K = kbar C^(1+n) d0^(-n), D = cbar C^(1+m) d0^(-m).
struct IdentifiableParams {
  double P_mm2 = 0.0;
  double K_n_per_mm2 = 0.0;
  double n = 0.0;
  double D_ns_per_mm2 = 0.0;
  double m = 0.0;
};

IdentifiableParams identifiable(const EllipsoidParams& params);

/// The force (N) in identifiable form, g = d/C and gdot = ddot/C (1/s):
///   F = P K g^(2+n) (1 - g/3) + s P D g^(1+m) gdot damping_shape(g),
/// s = damping_sign. Zero for g <= 0 (no contact), which is also the limit of every term and of
/// their parameter derivatives for n > -2, m > -1.
template <class T>
T ellipsoid_force(const T& P, const T& K, const T& n, const T& D, const T& m, const T& g,
                  const T& gdot, ModelVariant variant) {
  using std::pow;
  if (g <= T(0.0)) return T(0.0);
  const T elastic = P * K * pow(g, T(2.0) + n) * (T(1.0) - g / T(3.0));
  const T damping = P * D * pow(g, T(1.0) + m) * gdot * damping_shape(g, variant);
  return elastic + T(damping_sign(variant)) * damping;
}

/// Deformation d (mm) that gives contact ellipse area `area_mm2` (eq 32). Zero area gives 0;
/// area == pi A B gives d = C (the contact plane at the equator). Throws std::domain_error
/// for a negative area or one larger than pi A B, which no deformation can produce.
double deformation_mm(const EllipsoidParams& params, double area_mm2);

/// The rate of d (mm/s) for a contact area changing at `area_rate_mm2_per_s`: eq 32
/// differentiated, ddot = C Aedot / (2 pi A B sqrt(1 - Ae / (pi A B))). Throws
/// std::domain_error as deformation_mm does, and for area == pi A B (infinite rate).
double deformation_rate_mm_per_s(const EllipsoidParams& params, double area_mm2,
                                 double area_rate_mm2_per_s);

/// Contact ellipse area (mm^2) at deformation d (eq 28). Throws std::domain_error unless
/// 0 <= d <= C.
double contact_area_mm2(const EllipsoidParams& params, double d_mm);

struct ContactRadii {
  double rA_mm = 0.0;  ///< along the ellipsoid's A axis (lateral-medial)
  double rB_mm = 0.0;  ///< along the ellipsoid's B axis (anterior-posterior)
};

/// Contact ellipse radii at deformation d (eqs 5, 6). Throws std::domain_error unless
/// 0 <= d <= C.
ContactRadii contact_radii_mm(const EllipsoidParams& params, double d_mm);

/// The force (N) at deformation d and rate ddot in physical terms, k = kbar (d/d0)^n and
/// c = cbar (d/d0)^m:  F = (pi A B d / C) (k (d - d^2/(3C)) + s c ddot damping_shape(d/C)); with
/// eq 15's rate damping_shape(d/C) = (6C^2 - 4Cd + d^2) / (3C (2C - d)). Zero for d <= 0. Throws
/// std::domain_error for d > C.
double force_n(const EllipsoidParams& params, double d_mm, double ddot_mm_per_s,
               ModelVariant variant);

/// The local pressure field of one contact state: k delta + s c deltadot with delta from eq
/// 14, deltadot from eq 15 (ddot for MaterialRate), and k, c evaluated once at the global d. Its
/// integral over the contact ellipse is force_n. Eq 15's pressure vanishes on the rim; the
/// material rate's is c ddot there. Built once per state so rasterisation can sample it cheaply.
class PressureField {
 public:
  /// Throws std::domain_error unless 0 <= d <= C.
  PressureField(const EllipsoidParams& params, double d_mm, double ddot_mm_per_s,
                ModelVariant variant);

  const ContactRadii& radii() const { return radii_; }

  /// Pressure (N/mm^2) at squared normalised radius rho^2 (rho = 1 on the contact ellipse's
  /// edge); 0 outside the contact (rho^2 > 1) or when there is no contact (d = 0).
  double at_rho2(double rho2) const {
    if (rho2 > 1.0 || d_mm_ <= 0.0) return 0.0;
    const double root = std::sqrt(C_mm_ * C_mm_ - rho2 * d_mm_ * (2.0 * C_mm_ - d_mm_));
    const double delta = d_mm_ - C_mm_ + root;
    // At d = C the rim's root is 0 but so is C - d: the rate there is ddot throughout.
    const double lateral = C_mm_ - d_mm_;
    const double delta_dot =
        material_rate_ || !(lateral > 0.0) ? ddot_ : ddot_ * (1.0 - rho2 * lateral / root);
    return k_ * delta + sign_ * c_ * delta_dot;
  }

 private:
  double C_mm_;
  double d_mm_;
  double ddot_;
  double k_;
  double c_;
  double sign_;
  bool material_rate_;
  ContactRadii radii_;
};

/// PressureField(params, d, ddot, variant).at_rho2(rho^2) for one point, rho in [0, 1] the
/// normalised radius inside the contact ellipse (0 beyond it). Throws std::domain_error for
/// rho < 0 or d outside [0, C].
double pressure_n_per_mm2(const EllipsoidParams& params, double d_mm, double ddot_mm_per_s,
                          double rho, ModelVariant variant);

}  // namespace gaitmon
