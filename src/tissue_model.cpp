// The ellipsoid model in physical terms (deformation, contact geometry, force, pressure field).
#include "gaitmon/tissue_model.hpp"

#include <numbers>
#include <stdexcept>
#include <string>

namespace gaitmon {
namespace {

void check_geometry(const EllipsoidParams& p) {
  const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(p.A_mm) || !positive(p.B_mm) || !positive(p.C_mm) || !positive(p.d0_mm)) {
    throw std::invalid_argument(
        "ellipsoid parameters: A, B, C and d0 must be positive (A=" + std::to_string(p.A_mm) +
        " B=" + std::to_string(p.B_mm) + " C=" + std::to_string(p.C_mm) +
        " d0=" + std::to_string(p.d0_mm) + " mm)");
  }
}

void check_deformation(const EllipsoidParams& p, double d_mm) {
  check_geometry(p);
  if (!(d_mm >= 0.0 && d_mm <= p.C_mm)) {
    throw std::domain_error("deformation " + std::to_string(d_mm) +
                            " mm outside [0, C = " + std::to_string(p.C_mm) + " mm]");
  }
}

double ellipsoid_cross_section_mm2(const EllipsoidParams& p) {
  return std::numbers::pi * p.A_mm * p.B_mm;
}

/// a = Ae / (pi A B), validated to lie in [0, 1].
double area_fraction(const EllipsoidParams& p, double area_mm2) {
  check_geometry(p);
  const double section = ellipsoid_cross_section_mm2(p);
  if (!(area_mm2 >= 0.0 && area_mm2 <= section)) {
    throw std::domain_error("contact area " + std::to_string(area_mm2) +
                            " mm^2 outside [0, pi A B = " + std::to_string(section) + " mm^2]");
  }
  return area_mm2 / section;
}

}  // namespace

std::string_view model_variant_name(ModelVariant variant) {
  switch (variant) {
    case ModelVariant::Correct:
      return "correct";
    case ModelVariant::SeedEq25:
      return "seed_eq25";
    case ModelVariant::MaterialRate:
      return "material_rate";
  }
  return "unknown";
}

std::optional<ModelVariant> parse_model_variant(std::string_view text) {
  if (text == "correct") return ModelVariant::Correct;
  if (text == "seed_eq25") return ModelVariant::SeedEq25;
  if (text == "material_rate") return ModelVariant::MaterialRate;
  return std::nullopt;
}

IdentifiableParams identifiable(const EllipsoidParams& p) {
  check_geometry(p);
  return IdentifiableParams{
      .P_mm2 = ellipsoid_cross_section_mm2(p),
      .K_n_per_mm2 = p.kbar_n_per_mm3 * std::pow(p.C_mm, 1.0 + p.n) * std::pow(p.d0_mm, -p.n),
      .n = p.n,
      .D_ns_per_mm2 = p.cbar_ns_per_mm3 * std::pow(p.C_mm, 1.0 + p.m) * std::pow(p.d0_mm, -p.m),
      .m = p.m,
  };
}

double deformation_mm(const EllipsoidParams& params, double area_mm2) {
  const double a = area_fraction(params, area_mm2);
  return params.C_mm * (1.0 - std::sqrt(1.0 - a));
}

double deformation_rate_mm_per_s(const EllipsoidParams& params, double area_mm2,
                                 double area_rate_mm2_per_s) {
  const double a = area_fraction(params, area_mm2);
  if (a >= 1.0) {
    throw std::domain_error("contact area equals pi A B: the deformation rate is unbounded");
  }
  return params.C_mm * area_rate_mm2_per_s /
         (2.0 * ellipsoid_cross_section_mm2(params) * std::sqrt(1.0 - a));
}

double contact_area_mm2(const EllipsoidParams& params, double d_mm) {
  check_deformation(params, d_mm);
  const double C = params.C_mm;
  return std::numbers::pi * params.A_mm * params.B_mm * (2.0 * C * d_mm - d_mm * d_mm) / (C * C);
}

ContactRadii contact_radii_mm(const EllipsoidParams& params, double d_mm) {
  check_deformation(params, d_mm);
  const double C = params.C_mm;
  const double root = std::sqrt(2.0 * C * d_mm - d_mm * d_mm);
  return ContactRadii{.rA_mm = params.A_mm * root / C, .rB_mm = params.B_mm * root / C};
}

double force_n(const EllipsoidParams& params, double d_mm, double ddot_mm_per_s,
               ModelVariant variant) {
  check_geometry(params);
  if (d_mm <= 0.0) return 0.0;
  check_deformation(params, d_mm);
  const double C = params.C_mm;
  const double d = d_mm;
  const double k = params.kbar_n_per_mm3 * std::pow(d / params.d0_mm, params.n);
  const double c = params.cbar_ns_per_mm3 * std::pow(d / params.d0_mm, params.m);
  const double elastic = k * (d - d * d / (3.0 * C));
  const double damping = c * ddot_mm_per_s * damping_shape(d / C, variant);
  return std::numbers::pi * params.A_mm * params.B_mm * d / C *
         (elastic + damping_sign(variant) * damping);
}

PressureField::PressureField(const EllipsoidParams& params, double d_mm, double ddot_mm_per_s,
                             ModelVariant variant)
    : C_mm_(params.C_mm),
      d_mm_(d_mm),
      ddot_(ddot_mm_per_s),
      k_(0.0),
      c_(0.0),
      sign_(damping_sign(variant)),
      material_rate_(variant == ModelVariant::MaterialRate),
      radii_(contact_radii_mm(params, d_mm)) {
  if (d_mm > 0.0) {
    k_ = params.kbar_n_per_mm3 * std::pow(d_mm / params.d0_mm, params.n);
    c_ = params.cbar_ns_per_mm3 * std::pow(d_mm / params.d0_mm, params.m);
  }
}

double pressure_n_per_mm2(const EllipsoidParams& params, double d_mm, double ddot_mm_per_s,
                          double rho, ModelVariant variant) {
  if (!(rho >= 0.0)) {
    throw std::domain_error("normalised radius " + std::to_string(rho) + " is negative");
  }
  return PressureField(params, d_mm, ddot_mm_per_s, variant).at_rho2(rho * rho);
}

}  // namespace gaitmon
