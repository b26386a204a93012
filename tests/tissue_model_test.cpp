// Tests of the ellipsoid model against the seed's eq 22 integrated numerically, model-notes, and
// the damping rate of a fixed tissue column by finite differences.
#include "gaitmon/tissue_model.hpp"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

#include "test_support.hpp"

namespace gaitmon {
namespace {

using test::kPi;

/// Gauss-Legendre nodes and weights on [lo, hi], by Newton iteration on P_n.
struct Quadrature {
  std::vector<double> x;
  std::vector<double> w;
};

Quadrature gauss_legendre(int order, double lo, double hi) {
  Quadrature q;
  for (int i = 1; i <= order; ++i) {
    double z = std::cos(kPi * (i - 0.25) / (order + 0.5));
    double dp = 0.0;
    for (int iter = 0; iter < 100; ++iter) {
      double p0 = 1.0;
      double p1 = z;
      for (int k = 2; k <= order; ++k) {
        const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = order * (z * p1 - p0) / (z * z - 1.0);
      const double step = p1 / dp;
      z -= step;
      if (std::abs(step) < 1e-16) break;
    }
    q.x.push_back(0.5 * (lo + hi) + 0.5 * (hi - lo) * z);
    q.w.push_back((hi - lo) / ((1.0 - z * z) * dp * dp));
  }
  return q;
}

/// Eq 22 integrated numerically over rho in [0, 1] and theta in [0, 2 pi]:
/// (k delta + c deltadot) rho A B d (2C - d) / C^2, with k, c at the global d.
double eq22_quadrature(const EllipsoidParams& p, double d, double ddot) {
  const double C = p.C_mm;
  const double k = p.kbar_n_per_mm3 * std::pow(d / p.d0_mm, p.n);
  const double c = p.cbar_ns_per_mm3 * std::pow(d / p.d0_mm, p.m);
  const Quadrature rho_q = gauss_legendre(96, 0.0, 1.0);
  const Quadrature theta_q = gauss_legendre(16, 0.0, 2.0 * kPi);
  double sum = 0.0;
  for (std::size_t i = 0; i < rho_q.x.size(); ++i) {
    const double rho = rho_q.x[i];
    const double delta = d - C + std::sqrt(C * C - rho * rho * (2.0 * C * d - d * d));
    const double delta_dot =
        ddot * (1.0 - rho * rho * (C - d) /
                          std::sqrt(C * C - 2.0 * C * rho * rho * d + rho * rho * d * d));
    const double jacobian = rho * p.A_mm * p.B_mm * d * (2.0 * C - d) / (C * C);
    for (std::size_t j = 0; j < theta_q.x.size(); ++j) {
      sum += rho_q.w[i] * theta_q.w[j] * (k * delta + c * delta_dot) * jacobian;
    }
  }
  return sum;
}

/// The pressure field integrated over the contact ellipse, dA = rho rA rB drho dtheta (eq 21).
double pressure_quadrature(const EllipsoidParams& p, double d, double ddot, ModelVariant v) {
  const double C = p.C_mm;
  const double rA_rB = p.A_mm * p.B_mm * (2.0 * C * d - d * d) / (C * C);
  const Quadrature rho_q = gauss_legendre(96, 0.0, 1.0);
  const Quadrature theta_q = gauss_legendre(16, 0.0, 2.0 * kPi);
  double sum = 0.0;
  for (std::size_t i = 0; i < rho_q.x.size(); ++i) {
    const double pressure = pressure_n_per_mm2(p, d, ddot, rho_q.x[i], v);
    for (std::size_t j = 0; j < theta_q.x.size(); ++j) {
      sum += rho_q.w[i] * theta_q.w[j] * pressure * rho_q.x[i] * rA_rB;
    }
  }
  return sum;
}

// The seed's Appendix I means (size 37-38) for three regions, plus a made-up stiff case.
using test::kHeel;
const EllipsoidParams kMet3_5{139.7, 141.0, 116.5, 11.6, 0.140, 0.311, 0.023, 1.08};
const EllipsoidParams kToe2{43.7, 17.6, 36.3, 7.2, 0.144, 0.310, 0.012, 1.11};
const EllipsoidParams kOdd{50.0, 90.0, 30.0, 5.0, 0.5, 1.5, 0.05, 0.4};

struct State {
  EllipsoidParams params;
  double d_mm;
  double ddot_mm_per_s;
};

const std::vector<State> kStates{
    {kHeel, 2.5, 40.0},  {kHeel, 10.0, -25.0}, {kMet3_5, 4.0, 15.0}, {kToe2, 1.2, 60.0},
    {kToe2, 25.0, -5.0}, {kOdd, 0.3, 100.0},   {kOdd, 20.0, -80.0},
};

EllipsoidParams without_damping(EllipsoidParams p) {
  p.cbar_ns_per_mm3 = 0.0;
  return p;
}

EllipsoidParams without_stiffness(EllipsoidParams p) {
  p.kbar_n_per_mm3 = 0.0;
  return p;
}

TEST(TissueModel, ModelNotesCheckValues) {
  // model-notes section 1: constant k and c (n = m = 0, so d0 does not matter).
  const EllipsoidParams p{80.0, 70.0, 60.0, 10.0, 0.1, 0.0, 0.002, 0.0};
  EXPECT_NEAR(force_n(p, 5.0, 30.0, ModelVariant::Correct), 799.472, 5e-4);
  EXPECT_NEAR(force_n(p, 5.0, 30.0, ModelVariant::SeedEq25), 625.880, 5e-4);
  EXPECT_NEAR(eq22_quadrature(p, 5.0, 30.0), 799.472, 5e-4);
}

TEST(TissueModel, StiffnessPartEqualsQuadratureOfEq22) {
  for (const State& s : kStates) {
    const EllipsoidParams p = without_damping(s.params);
    const double expected = eq22_quadrature(p, s.d_mm, s.ddot_mm_per_s);
    ASSERT_GT(expected, 0.0);
    EXPECT_NEAR(force_n(p, s.d_mm, s.ddot_mm_per_s, ModelVariant::Correct), expected,
                1e-8 * expected)
        << "d = " << s.d_mm;
    EXPECT_NEAR(force_n(p, s.d_mm, s.ddot_mm_per_s, ModelVariant::SeedEq25), expected,
                1e-8 * expected);
  }
}

TEST(TissueModel, DampingPartEqualsQuadratureOfEq22WithPlusSign) {
  for (const State& s : kStates) {
    const EllipsoidParams p = without_stiffness(s.params);
    const double expected = eq22_quadrature(p, s.d_mm, s.ddot_mm_per_s);
    ASSERT_NE(expected, 0.0);
    const double tol = 1e-8 * std::abs(expected);
    EXPECT_NEAR(force_n(p, s.d_mm, s.ddot_mm_per_s, ModelVariant::Correct), expected, tol)
        << "d = " << s.d_mm;
    EXPECT_NEAR(force_n(p, s.d_mm, s.ddot_mm_per_s, ModelVariant::SeedEq25), -expected, tol);
  }
}

/// The damping force as the integral over the contact of c times the local rate, the rate by a
/// central difference in time of delta at one point, d moving at ddot: at a fixed tissue column
/// (x, y) (delta = d - C + C sqrt(1 - x^2/A^2 - y^2/B^2), the ellipsoid's surface over the
/// plane), or at a fixed normalised radius rho (eq 14, the point moving with the rim).
double damping_by_rate_difference(const EllipsoidParams& p, double d, double ddot,
                                  bool fixed_column) {
  const double C = p.C_mm;
  const double c = p.cbar_ns_per_mm3 * std::pow(d / p.d0_mm, p.m);
  const double h = 1e-4;  // s; delta is linear in d at a fixed column and smooth at a fixed rho
  const auto delta_at = [&](double rho, double theta, double dd) {
    if (fixed_column) {
      const ContactRadii r = contact_radii_mm(p, d);
      const double x = rho * r.rA_mm * std::cos(theta);
      const double y = rho * r.rB_mm * std::sin(theta);
      return dd - C + C * std::sqrt(1.0 - x * x / (p.A_mm * p.A_mm) - y * y / (p.B_mm * p.B_mm));
    }
    return dd - C + std::sqrt(C * C - rho * rho * (2.0 * C * dd - dd * dd));
  };
  const double rA_rB = p.A_mm * p.B_mm * (2.0 * C * d - d * d) / (C * C);
  const Quadrature rho_q = gauss_legendre(96, 0.0, 1.0);
  const Quadrature theta_q = gauss_legendre(16, 0.0, 2.0 * kPi);
  double sum = 0.0;
  for (std::size_t i = 0; i < rho_q.x.size(); ++i) {
    for (std::size_t j = 0; j < theta_q.x.size(); ++j) {
      const double rate = (delta_at(rho_q.x[i], theta_q.x[j], d + ddot * h) -
                           delta_at(rho_q.x[i], theta_q.x[j], d - ddot * h)) /
                          (2.0 * h);
      sum += rho_q.w[i] * theta_q.w[j] * c * rate * rho_q.x[i] * rA_rB;
    }
  }
  return sum;
}

// Eq 15 is the rate at a fixed rho; the tissue's own rate, at a fixed column, is d-dot all over
// the contact, and its damping force c ddot Ae is MaterialRate's.
TEST(TissueModel, MaterialRateIsTheFixedColumnsRateAndEq15TheFixedRhos) {
  for (const State& s : kStates) {
    const EllipsoidParams p = without_stiffness(s.params);
    const double column = damping_by_rate_difference(p, s.d_mm, s.ddot_mm_per_s, true);
    const double rho = damping_by_rate_difference(p, s.d_mm, s.ddot_mm_per_s, false);
    const double c = p.cbar_ns_per_mm3 * std::pow(s.d_mm / p.d0_mm, p.m);
    const double tol = 1e-6 * std::abs(column);
    EXPECT_NEAR(column, c * s.ddot_mm_per_s * contact_area_mm2(p, s.d_mm), tol);
    EXPECT_NEAR(force_n(p, s.d_mm, s.ddot_mm_per_s, ModelVariant::MaterialRate), column, tol)
        << "d = " << s.d_mm;
    EXPECT_NEAR(force_n(p, s.d_mm, s.ddot_mm_per_s, ModelVariant::Correct), rho,
                1e-6 * std::abs(rho))
        << "d = " << s.d_mm;
    // At a small contact the fixed column's rate gives twice eq 15's damping.
    if (s.d_mm / p.C_mm < 0.05) {
      EXPECT_NEAR(column / rho, 2.0, 0.1) << "d = " << s.d_mm;
    }
  }
  // The elastic part is the same in every variant.
  const EllipsoidParams p = without_damping(kHeel);
  EXPECT_EQ(force_n(p, 2.5, 40.0, ModelVariant::MaterialRate),
            force_n(p, 2.5, 40.0, ModelVariant::Correct));
}

TEST(TissueModel, PressureFieldIntegratesToTheForce) {
  for (const State& s : kStates) {
    for (ModelVariant v :
         {ModelVariant::Correct, ModelVariant::SeedEq25, ModelVariant::MaterialRate}) {
      const double expected = force_n(s.params, s.d_mm, s.ddot_mm_per_s, v);
      EXPECT_NEAR(pressure_quadrature(s.params, s.d_mm, s.ddot_mm_per_s, v), expected,
                  1e-8 * std::abs(expected))
          << "d = " << s.d_mm;
    }
  }
}

TEST(TissueModel, PressureAtCentreAndRim) {
  // At rho = 0: delta = d, deltadot = ddot; at the rim delta = 0, deltadot = 0 (eqs 14, 15).
  const EllipsoidParams p{80.0, 70.0, 60.0, 10.0, 0.1, 0.0, 0.002, 0.0};
  EXPECT_NEAR(pressure_n_per_mm2(p, 5.0, 30.0, 0.0, ModelVariant::Correct), 0.5 + 0.06, 1e-12);
  EXPECT_NEAR(pressure_n_per_mm2(p, 5.0, 30.0, 0.0, ModelVariant::SeedEq25), 0.5 - 0.06, 1e-12);
  EXPECT_NEAR(pressure_n_per_mm2(p, 5.0, 30.0, 1.0, ModelVariant::Correct), 0.0, 1e-12);
  EXPECT_EQ(pressure_n_per_mm2(p, 5.0, 30.0, 1.01, ModelVariant::Correct), 0.0);
  EXPECT_EQ(pressure_n_per_mm2(p, 0.0, 30.0, 0.5, ModelVariant::Correct), 0.0);
  EXPECT_THROW(pressure_n_per_mm2(p, 5.0, 30.0, -0.1, ModelVariant::Correct), std::domain_error);
  // d = C: the contact plane at the equator, delta = C sqrt(1 - rho^2), deltadot = ddot.
  EXPECT_NEAR(pressure_n_per_mm2(p, 60.0, 30.0, 0.5, ModelVariant::Correct),
              0.1 * 60.0 * std::sqrt(0.75) + 0.002 * 30.0, 1e-12);
  // The material rate: c ddot everywhere in the contact, the rim included.
  EXPECT_NEAR(pressure_n_per_mm2(p, 5.0, 30.0, 0.0, ModelVariant::MaterialRate), 0.5 + 0.06, 1e-12);
  EXPECT_NEAR(pressure_n_per_mm2(p, 5.0, 30.0, 1.0, ModelVariant::MaterialRate), 0.06, 1e-12);
  EXPECT_EQ(pressure_n_per_mm2(p, 5.0, 30.0, 1.01, ModelVariant::MaterialRate), 0.0);
}

TEST(TissueModel, DeformationFromAreaByHand) {
  // a = 1000 / (pi 80 70) = 0.0568410511; d = 60 (1 - sqrt(1 - a)) = 1.73017748 mm.
  const EllipsoidParams p{80.0, 70.0, 60.0, 10.0, 0.1, 0.0, 0.002, 0.0};
  EXPECT_NEAR(deformation_mm(p, 1000.0), 1.7301774841839, 1e-12);
  const ContactRadii r = contact_radii_mm(p, 1.7301774841839257);
  EXPECT_NEAR(r.rA_mm, 19.0730890803558, 1e-10);
  EXPECT_NEAR(r.rB_mm, 16.6889529453114, 1e-10);
  EXPECT_EQ(deformation_mm(p, 0.0), 0.0);
  EXPECT_NEAR(deformation_mm(p, kPi * 80.0 * 70.0), 60.0, 1e-12);
}

TEST(TissueModel, AreaDeformationRoundTrip) {
  for (const EllipsoidParams& p : {kHeel, kMet3_5, kToe2, kOdd}) {
    const double section = kPi * p.A_mm * p.B_mm;
    for (double fraction : {1e-6, 0.01, 0.1, 0.5, 0.9, 0.999}) {
      const double area = fraction * section;
      const double d = deformation_mm(p, area);
      EXPECT_NEAR(contact_area_mm2(p, d), area, 1e-10 * area);
      const ContactRadii r = contact_radii_mm(p, d);
      EXPECT_NEAR(kPi * r.rA_mm * r.rB_mm, area, 1e-10 * area);
      EXPECT_NEAR(r.rA_mm / r.rB_mm, p.A_mm / p.B_mm, 1e-12);
    }
  }
}

TEST(TissueModel, DeformationRateMatchesFiniteDifference) {
  for (const EllipsoidParams& p : {kHeel, kToe2}) {
    const double section = kPi * p.A_mm * p.B_mm;
    for (double fraction : {0.01, 0.3, 0.8}) {
      const double area = fraction * section;
      const double h = 1e-4 * area;
      const double slope = (deformation_mm(p, area + h) - deformation_mm(p, area - h)) / (2 * h);
      const double rate = -250.0;  // mm^2/s
      EXPECT_NEAR(deformation_rate_mm_per_s(p, area, rate), slope * rate,
                  1e-6 * std::abs(slope * rate));
    }
  }
}

TEST(TissueModel, IdentifiableFormEqualsPhysicalForm) {
  for (const State& s : kStates) {
    const EllipsoidParams& p = s.params;
    const IdentifiableParams q = identifiable(p);
    const double P = kPi * p.A_mm * p.B_mm;
    const double K = p.kbar_n_per_mm3 * std::pow(p.C_mm, 1 + p.n) / std::pow(p.d0_mm, p.n);
    const double D = p.cbar_ns_per_mm3 * std::pow(p.C_mm, 1 + p.m) / std::pow(p.d0_mm, p.m);
    EXPECT_NEAR(q.P_mm2, P, 1e-12 * P);
    EXPECT_NEAR(q.K_n_per_mm2, K, 1e-12 * K);
    EXPECT_NEAR(q.D_ns_per_mm2, D, 1e-12 * D);
    EXPECT_EQ(q.n, p.n);
    EXPECT_EQ(q.m, p.m);
    for (ModelVariant v :
         {ModelVariant::Correct, ModelVariant::SeedEq25, ModelVariant::MaterialRate}) {
      const double g = s.d_mm / p.C_mm;
      const double gdot = s.ddot_mm_per_s / p.C_mm;
      const double physical = force_n(p, s.d_mm, s.ddot_mm_per_s, v);
      EXPECT_NEAR(ellipsoid_force(P, K, p.n, D, p.m, g, gdot, v), physical,
                  1e-12 * std::abs(physical));
    }
  }
}

TEST(TissueModel, TemplateWorksWithJetsAndGivesDerivatives) {
  using Jet = ceres::Jet<double, 2>;
  // dF/dK is the elastic part over K; dF/dD is the damping part over D.
  const double P = 20000.0, K = 3.0, n = 0.3, D = 0.5, m = 1.1, g = 0.05, gdot = 0.4;
  const Jet F = ellipsoid_force(Jet(P), Jet(K, 0), Jet(n), Jet(D, 1), Jet(m), Jet(g), Jet(gdot),
                                ModelVariant::Correct);
  const double elastic = P * K * std::pow(g, 2 + n) * (1 - g / 3);
  const double damping = P * D * std::pow(g, 1 + m) * gdot * (6 - 4 * g + g * g) / (3 * (2 - g));
  EXPECT_NEAR(F.a, elastic + damping, 1e-12 * F.a);
  EXPECT_NEAR(F.v[0], elastic / K, 1e-12 * elastic / K);
  EXPECT_NEAR(F.v[1], damping / D, 1e-12 * damping / D);
  const Jet none = ellipsoid_force(Jet(P), Jet(K, 0), Jet(n), Jet(D, 1), Jet(m), Jet(0.0),
                                   Jet(gdot), ModelVariant::Correct);
  EXPECT_EQ(none.a, 0.0);
  EXPECT_EQ(none.v[0], 0.0);
}

TEST(TissueModel, OnlyFiveParametersAreIdentifiable) {
  // model-notes section 2: C 69.9 -> 40 mm and d0 16.4 -> 25 mm with kbar, cbar rescaled so
  // that K and D stay put leave the force of a whole contact-area trajectory unchanged.
  const EllipsoidParams a = kHeel;
  EllipsoidParams b = kHeel;
  b.C_mm = 40.0;
  b.d0_mm = 25.0;
  b.kbar_n_per_mm3 =
      a.kbar_n_per_mm3 * std::pow(a.C_mm / b.C_mm, 1 + a.n) * std::pow(b.d0_mm / a.d0_mm, a.n);
  b.cbar_ns_per_mm3 =
      a.cbar_ns_per_mm3 * std::pow(a.C_mm / b.C_mm, 1 + a.m) * std::pow(b.d0_mm / a.d0_mm, a.m);
  const double peak_area = 2400.0;
  const double stance = 0.6;
  for (ModelVariant v : {ModelVariant::Correct, ModelVariant::SeedEq25}) {
    double peak_force = 0.0;
    std::vector<std::pair<double, double>> forces;
    for (int i = 1; i < 100; ++i) {
      const double t = stance * i / 100.0;
      const double area = peak_area * std::pow(std::sin(kPi * t / stance), 2);
      const double rate = peak_area * kPi / stance * std::sin(2 * kPi * t / stance);
      const double fa =
          force_n(a, deformation_mm(a, area), deformation_rate_mm_per_s(a, area, rate), v);
      const double fb =
          force_n(b, deformation_mm(b, area), deformation_rate_mm_per_s(b, area, rate), v);
      forces.emplace_back(fa, fb);
      peak_force = std::max(peak_force, std::abs(fa));
    }
    ASSERT_GT(peak_force, 100.0);
    for (const auto& [fa, fb] : forces) EXPECT_NEAR(fb, fa, 1e-9 * peak_force);
    // The deformations themselves differ: the data cannot tell the two ellipsoids apart.
    EXPECT_GT(std::abs(deformation_mm(a, 1000.0) - deformation_mm(b, 1000.0)), 0.1);
  }
}

TEST(TissueModel, NoContactAndBadInput) {
  EXPECT_EQ(force_n(kHeel, 0.0, 50.0, ModelVariant::Correct), 0.0);
  EXPECT_THROW(force_n(kHeel, kHeel.C_mm + 0.1, 0.0, ModelVariant::Correct), std::domain_error);
  EXPECT_THROW(deformation_mm(kHeel, -1.0), std::domain_error);
  EXPECT_THROW(deformation_mm(kHeel, kPi * kHeel.A_mm * kHeel.B_mm * 1.0001), std::domain_error);
  EXPECT_THROW(deformation_rate_mm_per_s(kHeel, kPi * kHeel.A_mm * kHeel.B_mm, 1.0),
               std::domain_error);
  EXPECT_THROW(contact_radii_mm(kHeel, -0.5), std::domain_error);
  EllipsoidParams flat = kHeel;
  flat.C_mm = 0.0;
  EXPECT_THROW(force_n(flat, 1.0, 0.0, ModelVariant::Correct), std::invalid_argument);
  EXPECT_THROW(identifiable(flat), std::invalid_argument);
}

TEST(TissueModel, VariantNames) {
  EXPECT_EQ(model_variant_name(ModelVariant::Correct), "correct");
  EXPECT_EQ(model_variant_name(ModelVariant::SeedEq25), "seed_eq25");
  EXPECT_EQ(parse_model_variant("correct"), ModelVariant::Correct);
  EXPECT_EQ(parse_model_variant("seed_eq25"), ModelVariant::SeedEq25);
  EXPECT_EQ(model_variant_name(ModelVariant::MaterialRate), "material_rate");
  EXPECT_EQ(parse_model_variant("material_rate"), ModelVariant::MaterialRate);
  EXPECT_EQ(parse_model_variant("Correct"), std::nullopt);
  EXPECT_EQ(parse_model_variant(""), std::nullopt);
}

}  // namespace
}  // namespace gaitmon
