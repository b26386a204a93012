// Partial pooling of per-step tissue fits across a session: a normal random-effects model that
// lets each step borrow strength from the others as far as the steps agree.
//
// One step's stance determines the damping poorly: damping is about 4 % RMS of a region's force
// on the Appendix I parameters, while the contact area the cells give leaves 1-2 % residuals, so a
// per-step fit's cbar scatters by tens of per cent around the truth with hardly any bias (README,
// "Per-step estimates pooled across steps"). Step i's fitted vector theta_i (ln kbar, n, ln cbar,
// m) is modelled as
//
//   theta_i = phi_i + e_i,  e_i ~ N(0, S_i)  (S_i: the fit's covariance from its Jacobian)
//   phi_i ~ N(mu, T)                          (T: how the tissue itself varies from step to step)
//
// mu and T are estimated from the steps (weighted mean; T by the method of moments, sample
// covariance less the mean S_i, clipped to positive semi-definite), and each step gets the
// posterior mean mu + T (T + S_i)^-1 (theta_i - mu). Where the steps scatter no more than their
// own errors say, T is 0 and every step gets mu; where the tissue really varies, T takes it up and
// the steps keep their own values. The posterior covariance includes mu's own uncertainty.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "gaitmon/tissue_fit.hpp"

namespace gaitmon {

/// (ln kbar, n, ln cbar, m): the default fit's free parameters on the scale it fits them (their
/// covariance is a MaterialCovariance, tissue_fit.hpp).
using MaterialVector = std::array<double, 4>;

struct MaterialEstimate {
  MaterialVector value{};
  MaterialCovariance covariance{};
  /// Set where m was declared to every step alike (one m per region over the session,
  /// fit_damping_exponent_per_session), covariance[3][3] then being that m's variance:
  /// d value / d m, its last entry 1 (RegionFit::material_slope_on_m). The m's error is one for
  /// all the steps, so the pool carries it into the mean once instead of averaging it down.
  std::optional<MaterialVector> slope_on_shared_m;
};

/// The fit's bounds on the same scale.
struct MaterialBounds {
  MaterialVector lower{}, upper{};
};
MaterialBounds material_bounds(const FitBounds& bounds);

/// Fewer steps than this are returned as they are: T needs a sample covariance.
inline constexpr std::size_t kMinPoolingSteps = 3;

struct PooledEstimates {
  bool pooled = false;
  std::string not_pooled;               ///< why not, when not
  MaterialVector mean{};                ///< mu
  MaterialCovariance between_step{};    ///< T
  int iterations = 0;                   ///< of the mu-T fixed point
  std::vector<MaterialEstimate> steps;  ///< the posterior per input, in input order
  /// mu's covariance: the steps' own errors and T together (and a shared m's error through
  /// mean_slope_on_shared_m), so the region's tissue over the session, not any one step's. It
  /// does not hold the chain's error, which every step shares (README, "How honest the standard
  /// errors are"): analyse_session adds [pooling]'s chain SDs to it.
  MaterialCovariance mean_covariance{};
  /// At a shared m: how mu moves with it (its last entry 1).
  std::optional<MaterialVector> mean_slope_on_shared_m;
};

/// The pooled posteriors of `steps`. Steps with a parameter at a fit bound take part with the
/// covariance their Jacobian gives: leaving them out would bias mu away from the bound. If mu
/// falls outside `bounds` the normal approximation has failed (steps whose covariances are
/// degenerate in different directions, as on the toes' one to three cells) and the steps are
/// returned unpooled. Steps at one shared m (MaterialEstimate::slope_on_shared_m) are pooled at
/// that m, and its variance then enters the mean's covariance and each posterior's through their
/// slopes on it, as it would through every step's estimate alike. Deterministic. Throws
/// std::invalid_argument if a value is not finite, a covariance is not symmetric positive
/// definite, or only some steps, or steps at different m or with different variances of it,
/// declare a shared m.
PooledEstimates pool_steps(std::span<const MaterialEstimate> steps, const MaterialBounds& bounds);

/// A fit's free material parameters and their covariance, if it has them: an Ok fit in the
/// default (Identifiable, declared scale) mode whose four parameters the data determine, or
/// whose kbar, n and cbar they determine at a declared m with a standard error of its own (one m
/// per session, fit_damping_exponent_per_session): that is m's variance, and the estimate's
/// slope_on_shared_m is set.
std::optional<MaterialEstimate> material_estimate(const RegionFit& fit);

/// `estimate` of a step at its own m with m's variance at most range^2 / 3, range = bounds.upper[3]
/// - bounds.lower[3] (the fit's range of m), and kbar, n and cbar following m through their
/// slopes on it: their covariance given m is kept, and m's share of theirs shrinks with m's.
/// The fit holds m in its range, so against a truth anywhere in it the RMS error of any estimate
/// is at most range / sqrt 3 (a truth uniform over the range, the estimate at an end); where one
/// step leaves m undetermined the Jacobian's variance measures how flat the fit is along m, which
/// is what leaves m at a bound, not how far a bounded m can err (README, "How honest the standard
/// errors are"). Unchanged where m's variance is within it, and at a shared m
/// (slope_on_shared_m set), whose variance is the session's.
MaterialEstimate within_m_range(MaterialEstimate estimate, const MaterialBounds& bounds);

/// `estimate` with sd[i]^2 added to its covariance's diagonal: an error of SD sd[i] in each
/// parameter that every step shares (the measurement chain's, config [pooling]). The errors are
/// taken as independent of each other, which the standard errors do not depend on. At a shared m
/// (slope_on_shared_m set) m's error enters as that m's own does, through the slope: the others
/// were fitted at it. Throws std::invalid_argument for a negative or non-finite SD.
MaterialEstimate with_shared_error(MaterialEstimate estimate, const MaterialVector& sd);

/// kbar, n, cbar, m and their standard errors (delta method for kbar and cbar) of an estimate.
struct MaterialParams {
  Estimate kbar_n_per_mm3, n, cbar_ns_per_mm3, m;
};
MaterialParams material_params(const MaterialEstimate& estimate);

}  // namespace gaitmon
