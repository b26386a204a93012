// The per-region tissue fit: recovery of simulated truths through the whole measurement chain,
// identifiability, the seed's 8-parameter fit, non-negative forces and misuse.
#include "gaitmon/tissue_fit.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <random>
#include <span>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "gaitmon/analysis.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/pooling.hpp"
#include "gaitmon/simulator.hpp"
#include "gaitmon/stance.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

using test::shipped_config;

// One region over one measured stance, with both contact areas and the parameters the simulator
// used.
struct RegionStep {
  RegionSeries ellipse;    ///< the seed's contact-ellipse area
  RegionSeries footprint;  ///< as AreaSource::Footprint gives it
  /// As AreaSource::FootprintMean gives it, where simulated_region_steps was asked for it.
  RegionSeries footprint_mean;
  EllipsoidParams truth;
  Region region = Region::Heel;
  Foot foot = Foot::Left;
  int session = 0;  ///< which simulated session: steps pool within a session, foot and region
  int contact_frames = 0;
  const RegionSeries& series(AreaSource area) const {
    switch (area) {
      case AreaSource::Ellipse:
        return ellipse;
      case AreaSource::FootprintMean:
        return footprint_mean;
      case AreaSource::Footprint:
        break;
    }
    return footprint;
  }
};

std::vector<RegionStep> simulated_region_steps(
    InsoleSize size, std::uint64_t seed, double duration_s, ModelVariant variant,
    Rasterisation rasterisation = Rasterisation::CellCentre,
    CellMeanFootprint cell_mean = CellMeanFootprint::Skip,
    const std::array<std::optional<EllipsoidParams>, kRegionCount>& region_params = {}) {
  const auto dir =
      test::scratch_dir("fit-" + std::string(insole_size_name(size)) + "-" + std::to_string(seed));
  SimulationOptions options;
  options.size = size;
  options.seed = seed;
  options.duration_s = duration_s;
  options.model = variant;
  options.rasterisation = rasterisation;
  options.region_params = region_params;
  const SimulationTruth truth =
      simulate_session(shipped_config(), options, dir / "session.csv", dir / "truth.json");
  const InsoleLayout layout(shipped_config().insole(size), shipped_config().sensor);
  std::vector<RegionStep> out;
  ContactEllipseCache cache;
  segment_session(dir / "session.csv", shipped_config(), [&](Step&& step) {
    if (step.status != StepStatus::Ok) return;
    const StanceSeries stance =
        measure_stance(step, layout, shipped_config().calibration, &cache, cell_mean);
    for (Region region : kRegions) {
      RegionStep rs;
      rs.truth = truth.regions[index_of(region)].params;
      rs.region = region;
      rs.foot = step.foot;
      rs.session = static_cast<int>(seed);
      for (std::size_t f = 0; f < stance.size(); ++f) {
        const RegionSample& s = stance.at(f, region);
        for (RegionSeries* series : {&rs.ellipse, &rs.footprint, &rs.footprint_mean}) {
          series->t_s.push_back(stance.t_s[f]);
          series->force_n.push_back(s.force_n);
        }
        if (s.ellipse.area_mm2 > 0.0) ++rs.contact_frames;
      }
      rs.ellipse.area_mm2 = fit_areas_mm2(stance, region, AreaSource::Ellipse).first;
      rs.footprint.area_mm2 = fit_areas_mm2(stance, region, AreaSource::Footprint).first;
      rs.footprint_mean.area_mm2 = fit_areas_mm2(stance, region, AreaSource::FootprintMean).first;
      out.push_back(std::move(rs));
    }
  });
  return out;
}

const std::vector<RegionStep>& recovery_data() {
  static const std::vector<RegionStep> data = [] {
    std::vector<RegionStep> all;
    const struct {
      InsoleSize size;
      std::uint64_t seed;
    } runs[] = {{InsoleSize::S37_38, 11}, {InsoleSize::S41_42, 12}, {InsoleSize::S45_46, 13}};
    for (const auto& run : runs) {
      auto part = simulated_region_steps(run.size, run.seed, 10.0, ModelVariant::Correct);
      for (auto& rs : part) {
        if (rs.contact_frames >= 10) all.push_back(std::move(rs));
      }
    }
    return all;
  }();
  return data;
}

using test::median;

double rel_error(double fitted, double truth) {
  return std::abs(fitted - truth) / truth;
}

// On the pooled scale (ln kbar, n, ln cbar, m).
double pooled_rel_error(std::size_t k, double fitted, double truth) {
  return k == 0 || k == 2 ? rel_error(std::exp(fitted), std::exp(truth)) : rel_error(fitted, truth);
}

struct Medians {
  double kbar = 0.0, n = 0.0, cbar = 0.0, m = 0.0;
};

// The toes' one to three active cells mostly do not determine their footprint (footprint.hpp):
// the fit gets their contact ellipse's area in most of their frames.
bool area_determined(Region region) {
  return region != Region::Toe1 && region != Region::Toe2 && region != Region::Toes3_5;
}

struct Recovery {
  Medians all;         ///< median relative errors over every region-step
  Medians pooled;      ///< the same after pooling the steps (pooling.hpp)
  Medians determined;  ///< over the regions whose footprint the cells determine
  double nrmse = 0.0, ok_fraction = 0.0;
  double min_force_share = 0.0;  ///< the most negative model force / that fit's peak measured
  std::size_t fits = 0;
};

Recovery recover(Smoothing smoothing, AreaSource area) {
  FitSettings settings;
  settings.smoothing = smoothing;
  std::vector<double> ek, en, ec, em, nrmse;
  // Per region: the relative errors of kbar, n, cbar, m and the NRMSE, printed for diagnosis.
  std::array<std::array<std::vector<double>, 5>, kRegionCount> per_region;
  Recovery r;
  int ok = 0;
  // Per session, foot and region: the steps' estimates for pooling and their truths.
  std::map<std::tuple<int, Foot, Region>, std::vector<std::pair<MaterialEstimate, MaterialVector>>>
      pools;
  // After pooling: every region-step, and those of the regions whose footprint is determined.
  std::array<std::vector<double>, 4> pooled_errors, pooled_determined;
  const auto add_pooled = [&](Region region, std::size_t k, double error) {
    pooled_errors[k].push_back(error);
    if (area_determined(region)) pooled_determined[k].push_back(error);
  };
  for (const RegionStep& rs : recovery_data()) {
    const RegionSeries& series = rs.series(area);
    const RegionFit fit = fit_region(series, rs.truth, shipped_config().fit_bounds, settings);
    ++r.fits;
    if (fit.status != FitStatus::Ok) continue;
    ++ok;
    const MaterialVector truth{std::log(rs.truth.kbar_n_per_mm3), rs.truth.n,
                               std::log(rs.truth.cbar_ns_per_mm3), rs.truth.m};
    if (const auto e = material_estimate(fit)) {
      pools[{rs.session, rs.foot, rs.region}].emplace_back(*e, truth);
    } else {
      const double own[] = {std::log(fit.kbar_n_per_mm3.value), fit.n.value,
                            std::log(fit.cbar_ns_per_mm3.value), fit.m.value};
      for (std::size_t k = 0; k < 4; ++k)
        add_pooled(rs.region, k, pooled_rel_error(k, own[k], truth[k]));
    }
    ek.push_back(rel_error(fit.kbar_n_per_mm3.value, rs.truth.kbar_n_per_mm3));
    en.push_back(rel_error(fit.n.value, rs.truth.n));
    ec.push_back(rel_error(fit.cbar_ns_per_mm3.value, rs.truth.cbar_ns_per_mm3));
    em.push_back(rel_error(fit.m.value, rs.truth.m));
    nrmse.push_back(fit.nrmse_pct);
    const double errors[] = {ek.back(), en.back(), ec.back(), em.back(), nrmse.back()};
    for (std::size_t i = 0; i < 5; ++i) per_region[index_of(rs.region)][i].push_back(errors[i]);
    const double peak = *std::max_element(series.force_n.begin(), series.force_n.end());
    for (double f : fit.model_force_n) r.min_force_share = std::min(r.min_force_share, f / peak);
  }
  for (const auto& [key, pool] : pools) {
    std::vector<MaterialEstimate> estimates;
    for (const auto& [e, truth] : pool) estimates.push_back(e);
    const PooledEstimates p = pool_region_steps(
        estimates, std::get<2>(key), shipped_config().pooling, shipped_config().fit_bounds);
    for (std::size_t i = 0; i < pool.size(); ++i) {
      for (std::size_t k = 0; k < 4; ++k) {
        add_pooled(std::get<2>(key), k,
                   pooled_rel_error(k, p.steps[i].value[k], pool[i].second[k]));
      }
    }
  }
  r.ok_fraction = static_cast<double>(ok) / static_cast<double>(r.fits);
  if (ok > 0) {
    r.all = {median(ek), median(en), median(ec), median(em)};
    r.pooled = {median(pooled_errors[0]), median(pooled_errors[1]), median(pooled_errors[2]),
                median(pooled_errors[3])};
    r.nrmse = median(nrmse);
  }
  std::array<std::vector<double>, 4> determined;
  for (Region region : kRegions) {
    if (!area_determined(region)) continue;
    for (std::size_t i = 0; i < 4; ++i) {
      const auto& e = per_region[index_of(region)][i];
      determined[i].insert(determined[i].end(), e.begin(), e.end());
    }
  }
  if (!determined[0].empty()) {
    r.determined = {median(determined[0]), median(determined[1]), median(determined[2]),
                    median(determined[3])};
  }
  std::printf(
      "[ smoothing %s, area %s ] %zu fits, ok %.1f %%, median rel. error kbar %.3f n %.3f cbar "
      "%.3f m %.3f, median NRMSE %.2f %%\n"
      "    without the toes    %3zu fits: kbar %.3f n %.3f cbar %.3f m %.3f\n"
      "    pooled across steps           kbar %.3f n %.3f cbar %.3f m %.3f\n"
      "    pooled, without the toes      kbar %.3f n %.3f cbar %.3f m %.3f\n",
      std::string(smoothing_name(smoothing)).c_str(), std::string(area_source_name(area)).c_str(),
      r.fits, 100.0 * r.ok_fraction, r.all.kbar, r.all.n, r.all.cbar, r.all.m, r.nrmse,
      determined[0].size(), r.determined.kbar, r.determined.n, r.determined.cbar, r.determined.m,
      r.pooled.kbar, r.pooled.n, r.pooled.cbar, r.pooled.m, median(pooled_determined[0]),
      median(pooled_determined[1]), median(pooled_determined[2]), median(pooled_determined[3]));
  for (Region region : kRegions) {
    const auto& e = per_region[index_of(region)];
    if (e[0].empty()) continue;
    std::printf("    %-18s %3zu fits: kbar %.3f n %.3f cbar %.3f m %.3f NRMSE %.2f %%\n",
                std::string(region_name(region)).c_str(), e[0].size(), median(e[0]), median(e[1]),
                median(e[2]), median(e[3]), median(e[4]));
  }
  return r;
}

const Recovery& recovery(Smoothing smoothing, AreaSource area = AreaSource::Footprint) {
  static const Recovery none = recover(Smoothing::None, AreaSource::Footprint);
  static const Recovery seed = recover(Smoothing::Seed, AreaSource::Footprint);
  static const Recovery none_ellipse = recover(Smoothing::None, AreaSource::Ellipse);
  static const Recovery seed_ellipse = recover(Smoothing::Seed, AreaSource::Ellipse);
  if (area == AreaSource::Ellipse)
    return smoothing == Smoothing::None ? none_ellipse : seed_ellipse;
  return smoothing == Smoothing::None ? none : seed;
}

TEST(TissueFitRecovery, DataCoverThreeSizesWithEnoughRegionSteps) {
  EXPECT_GE(recovery_data().size(), 60u);
}

// Convergence, one of the recovery targets, is met: at least 99 % of region-steps.
TEST(TissueFitRecovery, AtLeast99PercentOfRegionStepsConverge) {
  EXPECT_GE(recovery(Smoothing::Seed).ok_fraction, 0.99);
  EXPECT_GE(recovery(Smoothing::None).ok_fraction, 0.99);
}

// The default smoothing is the one that recovers the truth better where the cells determine the
// contact area: the raw series give lower median errors for kbar, n and cbar there (m is about
// equal, and on the toes, fitted to their contact ellipse, the seed's polynomials do better).
TEST(TissueFitRecovery, NoSmoothingIsTheDefaultBecauseItRecoversBetter) {
  EXPECT_EQ(FitSettings{}.smoothing, Smoothing::None);
  const Medians& none = recovery(Smoothing::None).determined;
  const Medians& seed = recovery(Smoothing::Seed).determined;
  EXPECT_LT(none.kbar, seed.kbar);
  EXPECT_LT(none.n, seed.n);
  EXPECT_LT(none.cbar, seed.cbar);
}

// One of the recovery targets that is met with the defaults: the median NRMSE is below
// 5 % (2.6 % when measured; 12.8 % with the seed's contact-ellipse area).
TEST(TissueFitRecovery, MedianNrmseIsBelowFivePercent) {
  EXPECT_LT(recovery(Smoothing::None).nrmse, 5.0);
}

// Pooling the per-step fits across each session's steps (pooling.hpp) lowers every median error
// over all region-steps; the toes, whose pooled mean leaves the bounds, keep their own fits.
TEST(TissueFitRecovery, PoolingAcrossStepsLowersEveryMedianError) {
  const Recovery& r = recovery(Smoothing::None);
  EXPECT_LT(r.pooled.kbar, r.all.kbar);
  EXPECT_LT(r.pooled.n, r.all.n);
  EXPECT_LT(r.pooled.cbar, r.all.cbar);
  EXPECT_LT(r.pooled.m, r.all.m);
}

// Sessions whose tissue is off the seed's Appendix I means: each region's kbar, n and cbar moved by
// a factor of 0.65, 0.8, 1.25 or 1.5 and m by -0.2 to +0.2 (drawn; the geometry, which the fit
// declares, stays), four sessions of each of three sizes, 10 s each. Grouped per session and
// region, over the regions whose footprint the cells determine.
struct OffMeanGroup {
  MaterialVector truth{}, mean{};  ///< kbar, n, cbar, m
  std::vector<RegionStep> steps;   ///< with at least 10 contact frames
};

const std::vector<OffMeanGroup>& off_mean_groups() {
  static const std::vector<OffMeanGroup> groups = [] {
    constexpr double kFactors[] = {0.65, 0.8, 1.25, 1.5};
    constexpr double kShifts[] = {-0.2, -0.1, 0.1, 0.2};
    const InsoleSize sizes[] = {InsoleSize::S37_38, InsoleSize::S41_42, InsoleSize::S45_46};
    std::vector<OffMeanGroup> out;
    // mt19937's output is the same everywhere (its distributions are not).
    std::mt19937 draw(2026);
    const auto pick = [&draw] { return draw() % 4; };
    for (std::uint64_t s = 0; s < 12; ++s) {
      const InsoleSize size = sizes[s % 3];
      std::array<std::optional<EllipsoidParams>, kRegionCount> params;
      for (Region region : kRegions) {
        EllipsoidParams p = shipped_config().tissue(size, region).mean;
        p.kbar_n_per_mm3 *= kFactors[pick()];
        p.n *= kFactors[pick()];
        p.cbar_ns_per_mm3 *= kFactors[pick()];
        p.m = std::clamp(p.m + kShifts[pick()], 0.84, 1.36);
        params[index_of(region)] = p;
      }
      auto steps =
          simulated_region_steps(size, 31 + s, 10.0, ModelVariant::Correct,
                                 Rasterisation::CellCentre, CellMeanFootprint::Skip, params);
      for (Region region : kRegions) {
        if (!area_determined(region)) continue;
        const EllipsoidParams& mean = shipped_config().tissue(size, region).mean;
        const EllipsoidParams& truth = *params[index_of(region)];
        OffMeanGroup g;
        g.truth = {truth.kbar_n_per_mm3, truth.n, truth.cbar_ns_per_mm3, truth.m};
        g.mean = {mean.kbar_n_per_mm3, mean.n, mean.cbar_ns_per_mm3, mean.m};
        for (RegionStep& rs : steps) {
          if (rs.region == region && rs.contact_frames >= 10) g.steps.push_back(rs);
        }
        out.push_back(std::move(g));
      }
    }
    return out;
  }();
  return groups;
}

std::array<double, 4> material_values(const RegionFit& fit) {
  return {fit.kbar_n_per_mm3.value, fit.n.value, fit.cbar_ns_per_mm3.value, fit.m.value};
}

// The least-squares slope of y on x and its standard error.
std::pair<double, double> slope_with_se(const std::vector<double>& x,
                                        const std::vector<double>& y) {
  const double n = static_cast<double>(x.size());
  const double mx = std::accumulate(x.begin(), x.end(), 0.0) / n;
  const double my = std::accumulate(y.begin(), y.end(), 0.0) / n;
  double sxx = 0.0, sxy = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    sxx += (x[i] - mx) * (x[i] - mx);
    sxy += (x[i] - mx) * (y[i] - my);
  }
  const double slope = sxy / sxx;
  double rss = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double r = y[i] - my - slope * (x[i] - mx);
    rss += r * r;
  }
  return {slope, std::sqrt(rss / (n - 2.0) / sxx)};
}

// Per parameter, over the groups: the slope of each group's median ln(fitted / true) on
// ln(true / mean), a fit that gave the mean having a slope of -1 and one that follows the truth 0.
struct Tracking {
  std::array<double, 4> slope{}, slope_se{}, median_error{};
};

Tracking tracking(const std::vector<std::array<std::vector<double>, 4>>& fitted) {
  const auto& groups = off_mean_groups();
  Tracking t;
  for (std::size_t k = 0; k < 4; ++k) {
    std::vector<double> x, y, errors;
    for (std::size_t g = 0; g < groups.size(); ++g) {
      std::vector<double> log_errors;
      for (double v : fitted[g][k]) {
        log_errors.push_back(std::log(v / groups[g].truth[k]));
        errors.push_back(rel_error(v, groups[g].truth[k]));
      }
      x.push_back(std::log(groups[g].truth[k] / groups[g].mean[k]));
      y.push_back(median(log_errors));
    }
    std::tie(t.slope[k], t.slope_se[k]) = slope_with_se(x, y);
    t.median_error[k] = median(errors);
  }
  return t;
}

constexpr const char* kMaterialNames[] = {"kbar", "n", "cbar", "m"};

void print_tracking(const char* label, const Tracking& t) {
  for (std::size_t k = 0; k < 4; ++k) {
    std::printf("    %s %-4s slope %+.3f (SE %.3f), per-step median error %.3f\n", label,
                kMaterialNames[k], t.slope[k], t.slope_se[k], t.median_error[k]);
  }
}

// Every recovery above simulates the seed's Appendix I means, the values the fit also declares C,
// d0 and P from, near the middle of its bounds. A fit that leaned on them would look better there
// than anywhere else. On the sessions of off_mean_groups, per step and pooled as `analyze` pools a
// region's steps, measured slopes: per step kbar +0.07 (SE 0.05), n -0.16 (0.09), cbar -0.17
// (0.13), m -0.54 (0.14); pooled -0.00 (0.02), -0.02 (0.05), -0.19 (0.11), -0.61 (0.08). m, at a
// bound of its range in half the steps (README, "What one step can determine"), follows the truth
// less than halfway.
TEST(TissueFitRecovery, FollowsATissueAwayFromTheAppendixMeans) {
  const auto& groups = off_mean_groups();
  ASSERT_EQ(groups.size(), 60u);
  std::vector<std::array<std::vector<double>, 4>> fitted(groups.size());
  std::vector<double> pooled_x[4], pooled_y[4];
  int m_at_bound = 0, region_steps = 0, pools = 0;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    ASSERT_GE(groups[g].steps.size(), 10u);
    std::vector<MaterialEstimate> estimates;
    for (const RegionStep& rs : groups[g].steps) {
      const RegionFit fit = fit_region(rs.footprint, rs.truth, shipped_config().fit_bounds, {});
      ASSERT_EQ(fit.status, FitStatus::Ok) << region_name(rs.region);
      const auto v = material_values(fit);
      for (std::size_t k = 0; k < 4; ++k) fitted[g][k].push_back(v[k]);
      ++region_steps;
      if (fit.m.at_bound) ++m_at_bound;
      if (const auto e = material_estimate(fit)) estimates.push_back(*e);
    }
    const PooledEstimates pool =
        pool_region_steps(estimates, groups[g].steps.front().region, shipped_config().pooling,
                          shipped_config().fit_bounds);
    if (!pool.pooled) continue;
    ++pools;
    // The pool holds ln kbar, n, ln cbar, m.
    const MaterialVector pooled{std::exp(pool.mean[0]), pool.mean[1], std::exp(pool.mean[2]),
                                pool.mean[3]};
    for (std::size_t k = 0; k < 4; ++k) {
      pooled_x[k].push_back(std::log(groups[g].truth[k] / groups[g].mean[k]));
      pooled_y[k].push_back(std::log(pooled[k] / groups[g].truth[k]));
    }
  }
  const Tracking per_step = tracking(fitted);
  print_tracking("per step", per_step);
  std::array<double, 4> pooled_slope{};
  for (std::size_t k = 0; k < 4; ++k) {
    const auto [b, se] = slope_with_se(pooled_x[k], pooled_y[k]);
    pooled_slope[k] = b;
    std::printf("    pooled   %-4s slope %+.3f (SE %.3f)\n", kMaterialNames[k], b, se);
  }
  const double m_at_bound_share = static_cast<double>(m_at_bound) / region_steps;
  std::printf("    m at a bound in %.0f %% of %d region-steps; %d of 60 pools\n",
              100.0 * m_at_bound_share, region_steps, pools);
  EXPECT_GE(pools, 55);
  // kbar, n and cbar follow the truth wherever it is, per step and pooled.
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_LT(std::abs(per_step.slope[k]), 0.5) << kMaterialNames[k];
    EXPECT_LT(std::abs(pooled_slope[k]), 0.5) << kMaterialNames[k];
  }
  EXPECT_LT(std::abs(per_step.slope[0]), 0.25);
  EXPECT_LT(std::abs(pooled_slope[0]), 0.25);
  // m carries some of the truth, but what the README says of it holds: a bound in a large share of
  // the steps, and less than half of the truth's offset followed (if these fail, m has become
  // better determined and the README's account of it is out of date).
  EXPECT_GT(per_step.slope[3], -0.9);
  EXPECT_GT(pooled_slope[3], -0.9);
  EXPECT_LT(pooled_slope[3], -0.3);
  EXPECT_GT(m_at_bound_share, 0.3);
  // No worse than at the means (recovery_data's sessions, without the toes).
  const Medians& at_means = recovery(Smoothing::None).determined;
  EXPECT_LT(per_step.median_error[0], 1.25 * at_means.kbar);
  EXPECT_LT(per_step.median_error[1], 1.25 * at_means.n);
  EXPECT_LT(per_step.median_error[2], 1.25 * at_means.cbar);
  EXPECT_LT(per_step.median_error[3], 1.25 * at_means.m);
}

// One m per region and session (fit_damping_exponent_per_session's profile), each step's kbar, n
// and cbar then fitted at it, on the same sessions: m follows the truth further and the per-step
// damping errors fall. Measured: m's slope -0.54 -> -0.30, per-step median errors kbar / n / cbar
// / m 0.071 / 0.132 / 0.291 / 0.133 -> 0.065 / 0.125 / 0.209 / 0.085.
TEST(TissueFitRecovery, OneMPerSessionFollowsTheTruthFurtherAndLowersTheDampingErrors) {
  const auto& groups = off_mean_groups();
  std::vector<std::array<std::vector<double>, 4>> own(groups.size()), shared(groups.size());
  for (std::size_t g = 0; g < groups.size(); ++g) {
    std::vector<RegionSeries> series;
    std::vector<EllipsoidParams> declared;
    for (const RegionStep& rs : groups[g].steps) {
      series.push_back(rs.footprint);
      declared.push_back(rs.truth);
    }
    const auto m = fit_shared_damping_exponent(series, declared, shipped_config().fit_bounds, {});
    ASSERT_TRUE(m.has_value());
    EXPECT_EQ(static_cast<std::size_t>(m->stances), series.size());
    FitSettings at;
    at.declared_m = m->m;
    for (std::size_t i = 0; i < series.size(); ++i) {
      const auto v =
          material_values(fit_region(series[i], declared[i], shipped_config().fit_bounds, {}));
      const RegionFit fit = fit_region(series[i], declared[i], shipped_config().fit_bounds, at);
      ASSERT_EQ(fit.status, FitStatus::Ok);
      const auto w = material_values(fit);
      for (std::size_t k = 0; k < 4; ++k) {
        own[g][k].push_back(v[k]);
        shared[g][k].push_back(w[k]);
      }
    }
  }
  const Tracking before = tracking(own), after = tracking(shared);
  print_tracking("per step          ", before);
  print_tracking("one m per session ", after);
  EXPECT_GT(after.slope[3], before.slope[3] + 0.1);
  EXPECT_LT(after.median_error[2], 0.85 * before.median_error[2]);
  EXPECT_LT(after.median_error[3], 0.8 * before.median_error[3]);
  EXPECT_LT(after.median_error[0], 1.05 * before.median_error[0]);
  EXPECT_LT(after.median_error[1], 1.05 * before.median_error[1]);
}

// How far the standard errors can be trusted, over the regions whose footprint the cells
// determine (README, "How honest the standard errors are"). A region's steps in one session share
// an error of the measurement chain (the footprint's and the threshold's error at each depth,
// the same every step), and no step's residuals show it: so against the truth the standard errors
// of ln kbar and n are too small by about 1.7 (a calibrated estimate's median |z| is 0.674), and
// the pooled ones, which that shared error does not shrink, by about 2.7. Against the scatter of
// the steps about their own region's mean error they are about right for ln kbar and n, and too
// large by about 2 for ln cbar and m, where the misfit of the area enters sigma^2. A step jittered
// on the cell grid (SimulationOptions::placement_sd_mm) does not remove the shared error, so it is
// not the raster's placement (measured, README).
TEST(TissueFitRecovery, StandardErrorsDescribeTheStepToStepScatterNotTheChainsSharedError) {
  std::map<std::tuple<int, Foot, Region>, std::vector<std::pair<MaterialEstimate, MaterialVector>>>
      groups;
  for (const RegionStep& rs : recovery_data()) {
    if (!area_determined(rs.region)) continue;
    const RegionFit fit =
        fit_region(rs.footprint, rs.truth, shipped_config().fit_bounds, FitSettings{});
    if (fit.status != FitStatus::Ok) continue;
    if (const auto e = material_estimate(fit)) {
      groups[{rs.session, rs.foot, rs.region}].emplace_back(
          *e, MaterialVector{std::log(rs.truth.kbar_n_per_mm3), rs.truth.n,
                             std::log(rs.truth.cbar_ns_per_mm3), rs.truth.m});
    }
  }
  // |z| against the truth, against the group's mean error, and of the pooled posteriors.
  std::array<std::vector<double>, 4> z_truth, z_within, z_pooled;
  for (const auto& [key, group] : groups) {
    if (group.size() < kMinPoolingSteps) continue;
    const double steps = static_cast<double>(group.size());
    std::vector<MaterialEstimate> estimates;
    for (const auto& [e, truth] : group) estimates.push_back(e);
    const PooledEstimates pooled =
        pool_steps(estimates, material_bounds(shipped_config().fit_bounds));
    for (std::size_t k = 0; k < 4; ++k) {
      double mean_error = 0.0;
      for (const auto& [e, truth] : group) mean_error += (e.value[k] - truth[k]) / steps;
      for (std::size_t i = 0; i < group.size(); ++i) {
        const auto& [e, truth] = group[i];
        const double se = std::sqrt(e.covariance[k][k]);
        z_truth[k].push_back(std::abs(e.value[k] - truth[k]) / se);
        // The deviation from a mean of `steps` values scatters less by sqrt((steps - 1) / steps).
        z_within[k].push_back(std::abs(e.value[k] - truth[k] - mean_error) / se *
                              std::sqrt(steps / (steps - 1.0)));
        if (pooled.pooled) {
          z_pooled[k].push_back(std::abs(pooled.steps[i].value[k] - truth[k]) /
                                std::sqrt(pooled.steps[i].covariance[k][k]));
        }
      }
    }
  }
  const char* names[] = {"ln kbar", "n", "ln cbar", "m"};
  for (std::size_t k = 0; k < 4; ++k) {
    std::printf(
        "%-8s median |z| (0.674 if calibrated): against the truth %.2f, the steps' own "
        "scatter %.2f, pooled %.2f (%zu region-steps)\n",
        names[k], median(z_truth[k]), median(z_within[k]), median(z_pooled[k]), z_truth[k].size());
  }
  ASSERT_GE(z_truth[0].size(), 200u);
  ASSERT_FALSE(z_pooled[0].empty());
  for (std::size_t k : {0u, 1u}) {
    EXPECT_GT(median(z_within[k]), 0.55) << names[k];
    EXPECT_LT(median(z_within[k]), 0.9) << names[k];
    EXPECT_GT(median(z_truth[k]), 1.0) << names[k];
    EXPECT_GT(median(z_pooled[k]), 1.5) << names[k];
  }
  for (std::size_t k : {2u, 3u}) EXPECT_LT(median(z_within[k]), 0.5) << names[k];
}

// The default contact area is the one that recovers the truth better: the load-fitted footprint
// gives a lower median NRMSE and lower median errors for kbar, n and cbar than the seed's contact
// ellipse, with either smoothing.
TEST(TissueFitRecovery, FootprintAreaIsTheDefaultBecauseItRecoversBetter) {
  EXPECT_EQ(AnalysisSettings{}.area, AreaSource::Footprint);
  for (Smoothing smoothing : {Smoothing::None, Smoothing::Seed}) {
    const Recovery& footprint = recovery(smoothing, AreaSource::Footprint);
    const Recovery& ellipse = recovery(smoothing, AreaSource::Ellipse);
    EXPECT_LT(footprint.nrmse, ellipse.nrmse) << smoothing_name(smoothing);
    EXPECT_LT(footprint.all.kbar, ellipse.all.kbar) << smoothing_name(smoothing);
    EXPECT_LT(footprint.all.n, ellipse.all.n) << smoothing_name(smoothing);
    EXPECT_LT(footprint.all.cbar, ellipse.all.cbar) << smoothing_name(smoothing);
  }
}

// Through the measurement chain the contacts' depth no longer tells P: the log P standard error
// of a free-scale fit is larger than 1, P is off by a third, and kbar and cbar take the error. So
// P is declared by default (from Appendix I), and --free-scale is for data as clean as a model's
// own series (FreeScaleFindsTheContactScaleOfANoiseFreeSeries). Regions whose cells determine a
// footprint.
TEST(TissueFitRecovery, FreeScaleIsNotTheDefaultBecauseTheChainDoesNotDetermineP) {
  if (test::kSanitized) {
    GTEST_SKIP()
        << "twice 255 region-step fits take too long under the sanitizers; the free scale's fit "
           "runs under them in FreeScaleFindsTheContactScaleOfANoiseFreeSeries";
  }
  EXPECT_FALSE(FitSettings{}.free_scale);
  FitSettings free_scale;
  free_scale.free_scale = true;
  std::vector<double> e_p, se_log_p, e_kbar_free, e_kbar, e_cbar_free, e_cbar;
  std::size_t fits = 0;
  for (const RegionStep& rs : recovery_data()) {
    if (!area_determined(rs.region)) continue;
    ++fits;
    const RegionFit f = fit_region(rs.footprint, rs.truth, shipped_config().fit_bounds, free_scale);
    const RegionFit d =
        fit_region(rs.footprint, rs.truth, shipped_config().fit_bounds, FitSettings{});
    if (f.status != FitStatus::Ok || d.status != FitStatus::Ok) continue;
    e_p.push_back(rel_error(f.A_mm.value * f.B_mm.value, rs.truth.A_mm * rs.truth.B_mm));
    se_log_p.push_back(2.0 * f.A_mm.se / f.A_mm.value);  // A = sqrt(P A/B / pi)
    e_kbar_free.push_back(rel_error(f.kbar_n_per_mm3.value, rs.truth.kbar_n_per_mm3));
    e_kbar.push_back(rel_error(d.kbar_n_per_mm3.value, rs.truth.kbar_n_per_mm3));
    e_cbar_free.push_back(rel_error(f.cbar_ns_per_mm3.value, rs.truth.cbar_ns_per_mm3));
    e_cbar.push_back(rel_error(d.cbar_ns_per_mm3.value, rs.truth.cbar_ns_per_mm3));
  }
  std::printf(
      "[ free scale ] %zu of %zu fits ok; median P error %.3f, median SE of ln P %.2f; kbar "
      "%.3f (P declared: %.3f), cbar %.3f (%.3f)\n",
      e_p.size(), fits, median(e_p), median(se_log_p), median(e_kbar_free), median(e_kbar),
      median(e_cbar_free), median(e_cbar));
  ASSERT_GE(fits, 200u);
  EXPECT_GE(static_cast<double>(e_p.size()), 0.99 * static_cast<double>(fits));
  EXPECT_GT(median(se_log_p), 1.0);
  EXPECT_GT(median(e_p), 0.2);
  EXPECT_GT(median(e_kbar_free), 2.0 * median(e_kbar));
  EXPECT_GT(median(e_cbar_free), median(e_cbar));
}

// The other recovery target (median relative error <= 10 % for kbar, n, cbar, m) is not met
// through the simulated measurement chain; issue 3 stays open on it. The toes' one to three cells
// mostly do not determine their footprint, so the fit gets their contact ellipse's area, which
// moves in steps of one 112.5 mm^2 cell and misses the rim below the adaptive threshold. Where the
// cells do determine it the errors are some 2-4 times lower but still above 10 % for n and cbar. A
// noise-free model series is recovered to within a few per cent (RecoversANoiseFreeModelSeries).
// These runs print the figures. OneStepBound below shows that cbar's target is out of reach of any
// unbiased estimator, even with exact contact areas.

// What one step can tell, whatever the estimator: the Cramer-Rao bound on (ln kbar, n, ln cbar, m)
// for one region-step of the simulator's exact contact-area course, with the force read through
// the sensors' white noise only (each contact cell's 0.5-bit Gaussian noise and its rounding,
// 1/12 bit^2; no area error, no threshold loss, no dc bias). Fisher information from central
// differences of the closed-form force, which tissue_model_test checks against quadrature of eq
// 22. An unbiased estimator with Gaussian errors has a median absolute error of 0.674 SD or more.
struct StepBound {
  Region region = Region::Heel;
  InsoleSize size = InsoleSize::S41_42;
  std::array<double, 4> relative_sd{};  ///< kbar, n, cbar, m: SD / value
  RegionSeries exact;                   ///< the model's force on the exact area course
  std::vector<double> noise_sd_n;       ///< per frame
};

constexpr double kCellNoiseBits = 0.5;   // SimulationOptions' default, as in the recovery sessions
constexpr double kStanceS = 1.1 * 0.62;  // the simulator's default stride x stance fraction

EllipsoidParams with_material(EllipsoidParams p, const std::array<double, 4>& theta) {
  p.kbar_n_per_mm3 = std::exp(theta[0]);
  p.n = theta[1];
  p.cbar_ns_per_mm3 = std::exp(theta[2]);
  p.m = theta[3];
  return p;
}

std::vector<double> step_forces(const EllipsoidParams& p, const RegionSeries& course,
                                const std::vector<double>& area_rate) {
  std::vector<double> f(course.t_s.size());
  for (std::size_t i = 0; i < f.size(); ++i) {
    const double a = course.area_mm2[i];
    f[i] = force_n(p, deformation_mm(p, a), deformation_rate_mm_per_s(p, a, area_rate[i]),
                   ModelVariant::Correct);
  }
  return f;
}

StepBound one_step_bound(const SimulatedRegion& simulated, Region region, InsoleSize size) {
  StepBound b;
  b.region = region;
  b.size = size;
  const Config& c = shipped_config();
  const double cell_mm2 = c.sensor.area_mm2();
  const double bit_n = c.calibration.newtons_per_bit(cell_mm2);
  std::vector<double> area_rate;
  const int frames = static_cast<int>(std::floor(kStanceS * c.sample_rate_hz));
  for (int i = 0; i < frames; ++i) {
    const double t = (i + 0.5) / c.sample_rate_hz;
    const auto [area, rate] = planned_contact_area_mm2(simulated, region, t / kStanceS);
    if (area <= 0.0) continue;
    b.exact.t_s.push_back(t);
    b.exact.area_mm2.push_back(area);
    area_rate.push_back(rate / kStanceS);
    const double cells = std::max(1.0, area / cell_mm2);
    b.noise_sd_n.push_back(bit_n * std::sqrt(cells * (kCellNoiseBits * kCellNoiseBits + 1.0 / 12)));
  }
  const EllipsoidParams& p = simulated.params;
  const std::array<double, 4> theta{std::log(p.kbar_n_per_mm3), p.n, std::log(p.cbar_ns_per_mm3),
                                    p.m};
  b.exact.force_n = step_forces(p, b.exact, area_rate);
  Eigen::Matrix4d fisher = Eigen::Matrix4d::Zero();
  std::vector<Eigen::Vector4d> jacobian(b.exact.t_s.size(), Eigen::Vector4d::Zero());
  constexpr double kStep = 1e-5;
  for (int k = 0; k < 4; ++k) {
    auto up = theta;
    auto down = theta;
    up[k] += kStep;
    down[k] -= kStep;
    const auto fu = step_forces(with_material(p, up), b.exact, area_rate);
    const auto fd = step_forces(with_material(p, down), b.exact, area_rate);
    for (std::size_t i = 0; i < fu.size(); ++i) jacobian[i](k) = (fu[i] - fd[i]) / (2 * kStep);
  }
  for (std::size_t i = 0; i < jacobian.size(); ++i) {
    fisher += jacobian[i] * jacobian[i].transpose() / (b.noise_sd_n[i] * b.noise_sd_n[i]);
  }
  const Eigen::Matrix4d cov = fisher.inverse();
  b.relative_sd = {std::sqrt(cov(0, 0)), std::sqrt(cov(1, 1)) / p.n, std::sqrt(cov(2, 2)),
                   std::sqrt(cov(3, 3)) / p.m};
  return b;
}

const std::vector<StepBound>& one_step_bounds() {
  static const std::vector<StepBound> bounds = [] {
    std::vector<StepBound> out;
    for (InsoleSize size : {InsoleSize::S37_38, InsoleSize::S41_42, InsoleSize::S45_46}) {
      const auto dir = test::scratch_dir("bound-" + std::string(insole_size_name(size)));
      SimulationOptions options;
      options.size = size;
      options.duration_s = 0.1;  // only the truth's regions are needed
      const SimulationTruth truth =
          simulate_session(shipped_config(), options, dir / "session.csv", dir / "truth.json");
      for (Region region : kRegions) {
        out.push_back(one_step_bound(truth.regions[index_of(region)], region, size));
      }
    }
    return out;
  }();
  return bounds;
}

TEST(OneStepBound, MedianCbarErrorOfAnyUnbiasedEstimatorExceedsTenPercent) {
  std::array<std::vector<double>, 4> median_error;
  std::printf("Cramer-Rao: 0.674 SD / value of one step, exact areas, white sensor noise only\n");
  std::printf("    %-18s %-6s   kbar      n   cbar      m\n", "region", "size");
  for (const StepBound& b : one_step_bounds()) {
    std::printf("    %-18s %-6s", std::string(region_name(b.region)).c_str(),
                std::string(insole_size_name(b.size)).c_str());
    for (std::size_t k = 0; k < 4; ++k) {
      median_error[k].push_back(0.674 * b.relative_sd[k]);
      std::printf(" %6.3f", 0.674 * b.relative_sd[k]);
    }
    std::printf("\n");
  }
  std::printf("    median over the 24 region-sizes: kbar %.3f n %.3f cbar %.3f m %.3f\n",
              median(median_error[0]), median(median_error[1]), median(median_error[2]),
              median(median_error[3]));
  EXPECT_GT(median(median_error[2]), 0.10);
}

// The bound is a real floor and the fit reaches it: fitting the exact series with the bound's own
// white noise added, many times over, scatters ln kbar and n by what the bound says (heel, size
// 41-42, where the fit is well inside its bounds).
TEST(OneStepBound, TheFitScattersAsTheBoundSaysOnExactAreas) {
  const auto it = std::find_if(
      one_step_bounds().begin(), one_step_bounds().end(),
      [](const StepBound& b) { return b.region == Region::Heel && b.size == InsoleSize::S41_42; });
  ASSERT_NE(it, one_step_bounds().end());
  const StepBound& b = *it;
  const EllipsoidParams& truth = shipped_config().tissue(b.size, b.region).mean;
  std::mt19937_64 rng(42);
  std::normal_distribution<double> unit(0.0, 1.0);
  std::vector<double> ln_kbar;
  std::vector<double> n;
  // The standard errors the fit reports for ln kbar and n, relative as the bound's.
  std::vector<double> se_ln_kbar;
  std::vector<double> se_n;
  for (int draw = 0; draw < 300; ++draw) {
    RegionSeries noisy = b.exact;
    for (std::size_t i = 0; i < noisy.force_n.size(); ++i) {
      noisy.force_n[i] += b.noise_sd_n[i] * unit(rng);
    }
    const RegionFit fit = fit_region(noisy, truth, shipped_config().fit_bounds, FitSettings{});
    ASSERT_EQ(fit.status, FitStatus::Ok);
    ln_kbar.push_back(std::log(fit.kbar_n_per_mm3.value / truth.kbar_n_per_mm3));
    n.push_back(fit.n.value / truth.n - 1.0);
    se_ln_kbar.push_back(fit.kbar_n_per_mm3.se / fit.kbar_n_per_mm3.value);
    se_n.push_back(fit.n.se / truth.n);
  }
  const auto& sd = test::sample_sd;
  std::printf("heel 41-42: scatter / bound  kbar %.3f / %.3f  n %.3f / %.3f\n", sd(ln_kbar),
              b.relative_sd[0], sd(n), b.relative_sd[1]);
  EXPECT_NEAR(sd(ln_kbar) / b.relative_sd[0], 1.0, 0.2);
  EXPECT_NEAR(sd(n) / b.relative_sd[1], 1.0, 0.2);
  // The reported standard errors assume one noise variance for every frame, where the noise here
  // grows with the cells in contact (as a real insole's does), so they are not exact: here they
  // come out larger than the scatter (1.31 times). Printed and bounded on both sides (README, How
  // the fit works).
  const double kbar_ratio = median(se_ln_kbar) / sd(ln_kbar);
  const double n_ratio = median(se_n) / sd(n);
  std::printf("heel 41-42: median reported SE / scatter  kbar %.3f  n %.3f\n", kbar_ratio, n_ratio);
  EXPECT_GT(kbar_ratio, 0.8);
  EXPECT_LT(kbar_ratio, 1.6);
  EXPECT_GT(n_ratio, 0.8);
  EXPECT_LT(n_ratio, 1.6);
}

// The penalty keeps every fitted model essentially non-negative on its own inputs: no model
// force below -0.1 % of the fit's peak measured force.
TEST(TissueFit, FittedModelsAreNotNegative) {
  EXPECT_GE(recovery(Smoothing::None).min_force_share, -1e-3);
  EXPECT_GE(recovery(Smoothing::Seed).min_force_share, -1e-3);
  EXPECT_GE(recovery(Smoothing::None, AreaSource::Ellipse).min_force_share, -1e-3);
  EXPECT_GE(recovery(Smoothing::Seed, AreaSource::Ellipse).min_force_share, -1e-3);
}

// A synthetic series straight from the model: no measurement chain, so the fit must find the
// truth almost exactly. Heel of size 37-38 (Appendix I means), a half-cosine contact bump.
RegionSeries model_series(const EllipsoidParams& p, ModelVariant variant, int frames) {
  RegionSeries s;
  const double P = std::acos(-1.0) * p.A_mm * p.B_mm;
  const double peak_area = 0.25 * P;
  const double duration = 0.6;
  for (int i = 0; i < frames; ++i) {
    const double t = duration * (i + 0.5) / frames;
    const double phase = 2.0 * std::acos(-1.0) * t / duration;
    const double area = 0.5 * peak_area * (1.0 - std::cos(phase));
    const double rate = 0.5 * peak_area * std::sin(phase) * 2.0 * std::acos(-1.0) / duration;
    const double d = deformation_mm(p, area);
    const double ddot = deformation_rate_mm_per_s(p, area, rate);
    s.t_s.push_back(t);
    s.area_mm2.push_back(area);
    s.force_n.push_back(std::max(0.0, force_n(p, d, ddot, variant)));
  }
  return s;
}

using test::kHeel;

// Exact model series are fitted raw: a polynomial would only distort them.
FitSettings raw(ModelVariant model = ModelVariant::Correct) {
  FitSettings settings;
  settings.smoothing = Smoothing::None;
  settings.model = model;
  return settings;
}

// theta = (ln kbar, n, ln cbar, m), the default fit's variables.
std::array<double, 4> material_theta(double kbar, double n, double cbar, double m) {
  return {std::log(kbar), n, std::log(cbar), m};
}

// The Levenberg-Marquardt steps of the default fit rest on its analytic Jacobian, data rows and
// non-negativity penalty rows alike. Reference: central differences of the residuals in each
// variable (h = 1e-5), whose truncation error is O(h^2). Checked for every model variant at the
// truth, at a point across the box, and at a damping strong enough that the model pulls while
// unloading, so that the penalty rows are active. A row whose penalty switches on or off between
// the two difference points sits on its kink and has no derivative there; such rows are skipped
// and counted.
TEST(TissueFit, AnalyticJacobianMatchesCentralDifferences) {
  const std::array<std::array<double, 4>, 3> points{material_theta(0.117, 0.294, 0.011, 1.18),
                                                    material_theta(0.05, 0.7, 0.03, 0.9),
                                                    material_theta(0.117, 0.294, 0.5, 0.2)};
  double worst = 0.0;
  for (ModelVariant variant :
       {ModelVariant::Correct, ModelVariant::SeedEq25, ModelVariant::MaterialRate}) {
    const RegionSeries s = model_series(kHeel, variant, 60);
    for (std::size_t p = 0; p < points.size(); ++p) {
      const auto at = detail::separable_residuals(s, kHeel, raw(variant), points[p]);
      const std::size_t rows = at.residual.size();
      ASSERT_EQ(rows, 2 * s.t_s.size());
      ASSERT_EQ(at.jacobian.size(), rows);
      // The penalty as documented (README): 1000 x max(0, -F_model), F_model = residual + F.
      std::size_t penalised = 0;
      for (std::size_t i = 0; i < rows / 2; ++i) {
        const double model = at.residual[i] + s.force_n[i];
        EXPECT_NEAR(at.residual[rows / 2 + i], 1e3 * std::max(0.0, -model),
                    1e-9 * (1.0 + s.force_n[i]));
        penalised += model < 0.0 ? 1 : 0;
      }
      // The last point's damping outweighs the stiffness over several frames: while unloading,
      // or under SeedEq25, which subtracts it, while loading.
      if (p == 2) {
        EXPECT_GE(penalised, 5U) << model_variant_name(variant);
      }
      int kinks = 0;
      for (std::size_t k = 0; k < 4; ++k) {
        const double h = 1e-5;
        std::array<double, 4> up = points[p];
        std::array<double, 4> down = points[p];
        up[k] += h;
        down[k] -= h;
        const auto plus = detail::separable_residuals(s, kHeel, raw(variant), up);
        const auto minus = detail::separable_residuals(s, kHeel, raw(variant), down);
        double column = 0.0;
        for (std::size_t i = 0; i < rows; ++i)
          column = std::max(column, std::abs(at.jacobian[i][k]));
        ASSERT_GT(column, 0.0);
        for (std::size_t i = 0; i < rows; ++i) {
          if (i >= rows / 2 && (plus.residual[i] > 0.0) != (minus.residual[i] > 0.0)) {
            ++kinks;
            continue;
          }
          const double fd = (plus.residual[i] - minus.residual[i]) / (2.0 * h);
          const double error = std::abs(at.jacobian[i][k] - fd) / column;
          worst = std::max(worst, error);
          EXPECT_LT(error, 1e-6) << model_variant_name(variant) << " point " << p << " row " << i
                                 << " variable " << k << ": analytic " << at.jacobian[i][k]
                                 << " central difference " << fd;
        }
      }
      EXPECT_LE(kinks, 4) << model_variant_name(variant) << " point " << p;
    }
  }
  std::printf("analytic Jacobian against central differences: worst error %.2e of the column\n",
              worst);
}

// The reported standard errors are sigma^2 (J^T J)^-1 with J the data rows' Jacobian at the
// optimum and sigma^2 = SSR / (frames - 4). Reference: J by central differences of the data
// residuals at the reported optimum, and SSR from the reported model forces, inverted here by
// Eigen. The series is the model's own with 2 N of Gaussian noise, so that every parameter is
// determined and off its bounds.
TEST(TissueFit, StandardErrorsFollowTheDataJacobianAtTheOptimum) {
  RegionSeries s = model_series(kHeel, ModelVariant::Correct, 60);
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 2.0);
  for (double& f : s.force_n) f += noise(rng);
  const RegionFit fit = fit_region(s, kHeel, shipped_config().fit_bounds, raw());
  ASSERT_EQ(fit.status, FitStatus::Ok) << fit.reason;
  ASSERT_TRUE(fit.material_covariance.has_value());
  for (const Estimate* e : {&fit.kbar_n_per_mm3, &fit.n, &fit.cbar_ns_per_mm3, &fit.m}) {
    ASSERT_FALSE(e->at_bound);
  }
  const std::array<double, 4> theta =
      material_theta(fit.kbar_n_per_mm3.value, fit.n.value, fit.cbar_ns_per_mm3.value, fit.m.value);
  const Eigen::Index frames = static_cast<Eigen::Index>(s.t_s.size());
  Eigen::MatrixXd J(frames, 4);
  for (Eigen::Index k = 0; k < 4; ++k) {
    const double h = 1e-5;
    std::array<double, 4> up = theta;
    std::array<double, 4> down = theta;
    up[static_cast<std::size_t>(k)] += h;
    down[static_cast<std::size_t>(k)] -= h;
    const auto plus = detail::separable_residuals(s, kHeel, raw(), up);
    const auto minus = detail::separable_residuals(s, kHeel, raw(), down);
    for (Eigen::Index i = 0; i < frames; ++i) {
      const auto row = static_cast<std::size_t>(i);
      J(i, k) = (plus.residual[row] - minus.residual[row]) / (2.0 * h);
    }
  }
  double ssr = 0.0;
  for (std::size_t i = 0; i < s.t_s.size(); ++i) {
    ssr += (fit.model_force_n[i] - s.force_n[i]) * (fit.model_force_n[i] - s.force_n[i]);
  }
  const Eigen::Matrix4d cov = ssr / static_cast<double>(frames - 4) * (J.transpose() * J).inverse();
  const std::array<double, 4> se{fit.kbar_n_per_mm3.se / fit.kbar_n_per_mm3.value, fit.n.se,
                                 fit.cbar_ns_per_mm3.se / fit.cbar_ns_per_mm3.value, fit.m.se};
  double worst = 0.0;
  for (std::size_t a = 0; a < 4; ++a) {
    const auto ia = static_cast<Eigen::Index>(a);
    const double expected = std::sqrt(cov(ia, ia));
    worst = std::max(worst, std::abs(se[a] - expected) / expected);
    EXPECT_NEAR(se[a], expected, 1e-4 * expected) << "parameter " << a;
    for (std::size_t b = 0; b < 4; ++b) {
      const auto ib = static_cast<Eigen::Index>(b);
      const double scale = std::sqrt(cov(ia, ia) * cov(ib, ib));
      EXPECT_NEAR((*fit.material_covariance)[a][b], cov(ia, ib), 1e-4 * scale)
          << "covariance " << a << ", " << b;
    }
  }
  std::printf("standard errors against sigma^2 (J^T J)^-1 by central differences: worst %.2e\n",
              worst);
}

// With m declared the fit finds kbar, n and cbar at it: exactly at the truth's m, and at a wrong
// m at a higher cost. m is then not free: no standard error, and zeros in its row and column of
// the material covariance, whose other entries are those of the three fitted at that m.
TEST(TissueFit, DeclaredMFitsTheOthersAtThatM) {
  const RegionSeries s = model_series(kHeel, ModelVariant::Correct, 60);
  FitSettings at_truth = raw();
  at_truth.declared_m = kHeel.m;
  const RegionFit fit = fit_region(s, kHeel, shipped_config().fit_bounds, at_truth);
  ASSERT_EQ(fit.status, FitStatus::Ok) << fit.reason;
  EXPECT_NEAR(fit.kbar_n_per_mm3.value, kHeel.kbar_n_per_mm3, kHeel.kbar_n_per_mm3 * 0.01);
  EXPECT_NEAR(fit.n.value, kHeel.n, kHeel.n * 0.01);
  EXPECT_NEAR(fit.cbar_ns_per_mm3.value, kHeel.cbar_ns_per_mm3, kHeel.cbar_ns_per_mm3 * 0.01);
  EXPECT_EQ(fit.m.value, kHeel.m);
  EXPECT_FALSE(fit.m.free);
  EXPECT_EQ(fit.m.se, 0.0);
  EXPECT_TRUE(fit.n.free);
  EXPECT_TRUE(fit.undetermined.empty());
  ASSERT_TRUE(fit.material_covariance.has_value());
  for (std::size_t k = 0; k < 4; ++k) {
    EXPECT_EQ((*fit.material_covariance)[3][k], 0.0);
    EXPECT_EQ((*fit.material_covariance)[k][3], 0.0);
  }
  EXPECT_GT((*fit.material_covariance)[2][2], 0.0);
  FitSettings off = raw();
  off.declared_m = kHeel.m - 0.3;
  const RegionFit wrong = fit_region(s, kHeel, shipped_config().fit_bounds, off);
  ASSERT_EQ(wrong.status, FitStatus::Ok) << wrong.reason;
  EXPECT_EQ(wrong.m.value, kHeel.m - 0.3);
  EXPECT_GT(wrong.final_cost, 10.0 * fit.final_cost + 1e-6);
  // A pool of such steps gives back the shared m with the variance it is given.
  RegionFit shared = fit;
  shared.m.se = 0.02;
  const auto e = material_estimate(shared);
  ASSERT_TRUE(e.has_value());
  EXPECT_DOUBLE_EQ(e->covariance[3][3], 0.02 * 0.02);
  ASSERT_TRUE(e->slope_on_shared_m.has_value() && fit.material_slope_on_m.has_value());
  EXPECT_EQ((*e->slope_on_shared_m)[2], (*fit.material_slope_on_m)[2]);
  EXPECT_EQ((*e->slope_on_shared_m)[3], 1.0);
  EXPECT_FALSE(material_estimate(fit).has_value()) << "a declared m without a standard error";
}

// With m declared, how the fitted (ln kbar, n, ln cbar) move with it, -(J^T J)^-1 J^T dr/dm,
// against central differences of fits at m +- 0.01, on the model's own series with 2 N of noise.
// The slope is what carries a shared m's error into a pool's mean (pool_steps).
TEST(TissueFit, DeclaredMsSlopeFollowsTheFitsAtNeighbouringM) {
  RegionSeries s = model_series(kHeel, ModelVariant::Correct, 60);
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 2.0);
  for (double& f : s.force_n) f += noise(rng);
  const auto fitted_at = [&](double m) {
    FitSettings settings = raw();
    settings.declared_m = m;
    return fit_region(s, kHeel, shipped_config().fit_bounds, settings);
  };
  const auto theta = [](const RegionFit& f) {
    return std::array<double, 3>{std::log(f.kbar_n_per_mm3.value), f.n.value,
                                 std::log(f.cbar_ns_per_mm3.value)};
  };
  const double dm = 0.01;
  const RegionFit fit = fitted_at(kHeel.m);
  const RegionFit up = fitted_at(kHeel.m + dm);
  const RegionFit down = fitted_at(kHeel.m - dm);
  for (const RegionFit* f : {&fit, &up, &down}) {
    ASSERT_EQ(f->status, FitStatus::Ok) << f->reason;
    for (const Estimate* e : {&f->kbar_n_per_mm3, &f->n, &f->cbar_ns_per_mm3})
      ASSERT_FALSE(e->at_bound);
  }
  ASSERT_TRUE(fit.material_slope_on_m.has_value());
  const auto& slope = *fit.material_slope_on_m;
  for (std::size_t k = 0; k < 3; ++k) {
    const double numeric = (theta(up)[k] - theta(down)[k]) / (2.0 * dm);
    std::printf("d theta_%zu / dm: %+.3e from the Jacobian, %+.3e by central differences\n", k,
                slope[k], numeric);
    EXPECT_NEAR(slope[k], numeric, 0.03 * std::abs(numeric) + 1e-4) << k;
  }
  EXPECT_FALSE(
      fit_region(s, kHeel, shipped_config().fit_bounds, raw()).material_slope_on_m.has_value())
      << "m fitted: no slope on it";
}

TEST(TissueFit, DeclaredMIsRefusedOutsideTheDefaultFitAndTheBoundsOfM) {
  const RegionSeries s = model_series(kHeel, ModelVariant::Correct, 60);
  FitSettings settings = raw();
  settings.declared_m = 0.5;  // below the bounds' 0.82
  EXPECT_THROW(fit_region(s, kHeel, shipped_config().fit_bounds, settings), std::invalid_argument);
  settings.declared_m = 1.0;
  settings.mode = FitMode::Seed8;
  EXPECT_THROW(fit_region(s, kHeel, shipped_config().fit_bounds, settings), std::invalid_argument);
  settings.mode = FitMode::Identifiable;
  settings.free_scale = true;
  EXPECT_THROW(fit_region(s, kHeel, shipped_config().fit_bounds, settings), std::invalid_argument);
  const std::array<RegionSeries, 1> one{s};
  EXPECT_THROW(fit_shared_damping_exponent(one, {}, shipped_config().fit_bounds, raw()),
               std::invalid_argument);
}

// Six stances of one region, each with its own kbar, n and cbar (0.7 to 1.3 times the heel's)
// and one m away from the Appendix I mean and the middle of the bounds: the summed cost's minimum
// is that m, and its standard error is finite.
TEST(TissueFit, SharedDampingExponentOfSeveralStancesIsTheirs) {
  std::vector<RegionSeries> stances;
  std::vector<EllipsoidParams> declared;
  for (int i = 0; i < 6; ++i) {
    EllipsoidParams p = kHeel;
    p.kbar_n_per_mm3 *= 0.7 + 0.12 * i;
    p.n *= 1.3 - 0.12 * i;
    p.cbar_ns_per_mm3 *= 0.7 + 0.12 * ((i + 3) % 6);
    p.m = 0.95;
    stances.push_back(model_series(p, ModelVariant::Correct, 50 + 4 * i));
    declared.push_back(p);
  }
  const auto shared =
      fit_shared_damping_exponent(stances, declared, shipped_config().fit_bounds, raw());
  ASSERT_TRUE(shared.has_value());
  EXPECT_NEAR(shared->m, 0.95, 0.005);
  EXPECT_EQ(shared->stances, 6);
  EXPECT_FALSE(shared->at_bound);
  EXPECT_TRUE(std::isfinite(shared->se));
  EXPECT_GT(shared->se, 0.0);
}

// The shared m's standard error is the scatter of m over noisy copies of the same stances: 40
// copies of six stances with Gaussian noise of 1 % of each stance's peak force on the force, the
// SD of the fitted m against the median reported standard error (measured: 0.0364 and 0.0355,
// the mean m 1.176 for 1.18).
TEST(TissueFit, SharedDampingExponentsStandardErrorIsItsScatter) {
  std::vector<RegionSeries> exact;
  std::vector<EllipsoidParams> declared;
  for (int i = 0; i < 6; ++i) {
    EllipsoidParams p = kHeel;
    p.kbar_n_per_mm3 *= 0.8 + 0.08 * i;
    p.cbar_ns_per_mm3 *= 1.2 - 0.08 * i;
    exact.push_back(model_series(p, ModelVariant::Correct, 50));
    declared.push_back(p);
  }
  std::mt19937 rng(55);
  std::normal_distribution<double> unit(0.0, 1.0);
  std::vector<double> m, se;
  for (int copy = 0; copy < 40; ++copy) {
    std::vector<RegionSeries> noisy = exact;
    for (RegionSeries& s : noisy) {
      const double peak = *std::max_element(s.force_n.begin(), s.force_n.end());
      for (double& f : s.force_n) f += 0.01 * peak * unit(rng);
    }
    const auto shared =
        fit_shared_damping_exponent(noisy, declared, shipped_config().fit_bounds, raw());
    ASSERT_TRUE(shared.has_value());
    ASSERT_FALSE(shared->at_bound);
    m.push_back(shared->m);
    se.push_back(shared->se);
  }
  const double scatter = test::sample_sd(m);
  const double reported = median(se);
  std::printf("    shared m over 40 noisy copies: SD %.4f, median reported SE %.4f, mean %.4f\n",
              scatter, reported, std::accumulate(m.begin(), m.end(), 0.0) / 40.0);
  EXPECT_GT(reported, 0.7 * scatter);
  EXPECT_LT(reported, 1.4 * scatter);
}

TEST(TissueFit, RecoversANoiseFreeModelSeries) {
  const RegionSeries s = model_series(kHeel, ModelVariant::Correct, 60);
  const RegionFit fit = fit_region(s, kHeel, shipped_config().fit_bounds, raw());
  ASSERT_EQ(fit.status, FitStatus::Ok) << fit.reason << " " << fit.solver_message;
  EXPECT_NEAR(fit.kbar_n_per_mm3.value, 0.117, 0.117 * 0.03);
  EXPECT_NEAR(fit.n.value, 0.294, 0.294 * 0.03);
  EXPECT_NEAR(fit.cbar_ns_per_mm3.value, 0.011, 0.011 * 0.05);
  EXPECT_NEAR(fit.m.value, 1.18, 1.18 * 0.05);
  EXPECT_LT(fit.nrmse_pct, 0.5);
  EXPECT_EQ(fit.frames, 60);
  EXPECT_FALSE(fit.C_mm.free);
  EXPECT_TRUE(fit.kbar_n_per_mm3.free);
  EXPECT_DOUBLE_EQ(fit.C_mm.value, 69.9);
  EXPECT_TRUE(fit.undetermined.empty());
  EXPECT_GT(fit.kbar_n_per_mm3.se, 0.0);
  EXPECT_TRUE(std::isfinite(fit.kbar_n_per_mm3.se));
}

// At a contact's first and last frame the two-frame difference is the area's rate half a frame
// inward; the second-order one-sided difference is exact for a quadratic course, as the central
// difference inside the run is. So on the model's own series over a parabolic area course
// (heel, 25 frames, cut where it falls under a quarter of its peak: through the cells a run of
// measured footprints starts and ends at a sizeable area, footprint.hpp) only the ends' rate
// keeps the damping from its truth, and the second-order ends take most of that away.
TEST(TissueFit, SecondOrderRatesAtTheContactEndsRecoverTheDampingCloser) {
  RegionSeries s;
  const double peak_area = 0.25 * std::acos(-1.0) * kHeel.A_mm * kHeel.B_mm;
  for (int i = 0; i < 25; ++i) {
    const double u = (i + 0.5) / 12.5 - 1.0;  // -1..1 over the stance
    const double area = peak_area * (1.0 - u * u);
    const double rate = peak_area * -2.0 * u / (0.6 / 2.0);
    const bool loaded = area >= 0.25 * peak_area;
    s.t_s.push_back(0.6 * (i + 0.5) / 25.0);
    s.area_mm2.push_back(loaded ? area : 0.0);
    s.force_n.push_back(loaded ? force_n(kHeel, deformation_mm(kHeel, area),
                                         deformation_rate_mm_per_s(kHeel, area, rate),
                                         ModelVariant::Correct)
                               : 0.0);
  }
  FitSettings second_order = raw();
  second_order.end_rate = EndRate::SecondOrder;
  const RegionFit two = fit_region(s, kHeel, shipped_config().fit_bounds, raw());
  const RegionFit three = fit_region(s, kHeel, shipped_config().fit_bounds, second_order);
  ASSERT_EQ(two.status, FitStatus::Ok) << two.reason;
  ASSERT_EQ(three.status, FitStatus::Ok) << three.reason;
  const double two_cbar = rel_error(two.cbar_ns_per_mm3.value, kHeel.cbar_ns_per_mm3);
  const double three_cbar = rel_error(three.cbar_ns_per_mm3.value, kHeel.cbar_ns_per_mm3);
  const double two_m = rel_error(two.m.value, kHeel.m);
  const double three_m = rel_error(three.m.value, kHeel.m);
  std::printf("cbar error %.4f (two-frame) / %.4f (second-order), m %.4f / %.4f\n", two_cbar,
              three_cbar, two_m, three_m);
  EXPECT_LT(three_cbar, 0.5 * two_cbar);
  EXPECT_LT(three_m, 0.5 * two_m);
  EXPECT_LT(three.nrmse_pct, two.nrmse_pct);
}

TEST(TissueFit, EndRateNamesRoundTrip) {
  for (EndRate rate : {EndRate::TwoFrame, EndRate::SecondOrder}) {
    EXPECT_EQ(parse_end_rate(end_rate_name(rate)), rate);
  }
  EXPECT_EQ(parse_end_rate("three-frame"), std::nullopt);
}

// A NaN or negative area is no contact: a rate must never be taken across one.
TEST(TissueFit, ContactRunsSplitAtEveryFrameWithoutContact) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<double> area{0.0, 5.0, 6.0, 0.0, 0.0, 7.0, -1.0, 8.0, nan, 9.0, 9.5};
  const std::vector<FrameRun> runs = contact_runs(area);
  ASSERT_EQ(runs.size(), 4u);
  const std::vector<std::pair<std::size_t, std::size_t>> expected{{1, 3}, {5, 6}, {7, 8}, {9, 11}};
  for (std::size_t r = 0; r < runs.size(); ++r) {
    EXPECT_EQ(runs[r].begin, expected[r].first) << "run " << r;
    EXPECT_EQ(runs[r].end, expected[r].second) << "run " << r;
  }
  EXPECT_TRUE(contact_runs(std::vector<double>{}).empty());
  EXPECT_TRUE(contact_runs(std::vector<double>{0.0, 0.0}).empty());
}

// The identifiability demonstration through the fit: two declared (C, d0) pairs give the same
// K = kbar C^(1+n) d0^(-n) and D, and kbar, cbar rescale by the (C, d0) factors.
TEST(TissueFit, DeclaredCAndD0OnlyRescaleKbarAndCbar) {
  const RegionSeries s = model_series(kHeel, ModelVariant::Correct, 60);
  EllipsoidParams other = kHeel;
  other.C_mm = 40.0;
  other.d0_mm = 10.0;
  FitBounds wide = shipped_config().fit_bounds;
  wide.kbar_n_per_mm3 = {1e-4, 10.0};
  wide.cbar_ns_per_mm3 = {1e-5, 1.0};
  const RegionFit a = fit_region(s, kHeel, wide, raw());
  const RegionFit b = fit_region(s, other, wide, raw());
  ASSERT_EQ(a.status, FitStatus::Ok);
  ASSERT_EQ(b.status, FitStatus::Ok);
  EXPECT_NEAR(b.n.value, a.n.value, 1e-4);
  EXPECT_NEAR(b.m.value, a.m.value, 1e-3);
  const auto K = [](const RegionFit& f) {
    return f.kbar_n_per_mm3.value * std::pow(f.C_mm.value, 1.0 + f.n.value) *
           std::pow(f.d0_mm.value, -f.n.value);
  };
  const auto D = [](const RegionFit& f) {
    return f.cbar_ns_per_mm3.value * std::pow(f.C_mm.value, 1.0 + f.m.value) *
           std::pow(f.d0_mm.value, -f.m.value);
  };
  EXPECT_NEAR(K(b) / K(a), 1.0, 1e-4);
  EXPECT_NEAR(D(b) / D(a), 1.0, 1e-3);
  // kbar_b / kbar_a = (69.9/40)^(1+n) (10/16.4)^n at the fitted n.
  const double n = a.n.value;
  EXPECT_NEAR(b.kbar_n_per_mm3.value / a.kbar_n_per_mm3.value,
              std::pow(69.9 / 40.0, 1.0 + n) * std::pow(10.0 / 16.4, n), 1e-3);
  for (std::size_t i = 0; i < s.t_s.size(); ++i) {
    EXPECT_NEAR(a.model_force_n[i], b.model_force_n[i], 1e-3 * 1000.0);
  }
}

TEST(TissueFit, Seed8ReportsCAndD0Undetermined) {
  const RegionSeries s = model_series(kHeel, ModelVariant::Correct, 60);
  FitSettings settings;
  settings.mode = FitMode::Seed8;
  const RegionFit fit = fit_region(s, EllipsoidParams{}, shipped_config().fit_bounds, settings);
  EXPECT_NE(std::find(fit.undetermined.begin(), fit.undetermined.end(), "C_mm"),
            fit.undetermined.end());
  EXPECT_NE(std::find(fit.undetermined.begin(), fit.undetermined.end(), "d0_mm"),
            fit.undetermined.end());
  EXPECT_TRUE(fit.C_mm.free);
  EXPECT_TRUE(std::isinf(fit.C_mm.se));
}

TEST(TissueFit, Seed8OnASimulatedRegionStepReportsCAndD0Undetermined) {
  const auto& data = recovery_data();
  ASSERT_FALSE(data.empty());
  FitSettings settings;
  settings.mode = FitMode::Seed8;
  const RegionFit fit =
      fit_region(data.front().footprint, EllipsoidParams{}, shipped_config().fit_bounds, settings);
  EXPECT_NE(std::find(fit.undetermined.begin(), fit.undetermined.end(), "C_mm"),
            fit.undetermined.end());
  EXPECT_NE(std::find(fit.undetermined.begin(), fit.undetermined.end(), "d0_mm"),
            fit.undetermined.end());
}

// A seed_eq25 session: the correct-sign fit of its data is worse than the seed_eq25 fit. (How
// closely the seed_eq25 fit recovers the truth through the measurement chain is limited as in
// TissueFitRecovery; the noise-free test below asserts the recovery itself.)
TEST(TissueFit, SeedEq25SessionNeedsTheSeedEq25Model) {
  const auto steps = simulated_region_steps(InsoleSize::S39_40, 21, 8.0, ModelVariant::SeedEq25);
  FitSettings seed;
  seed.model = ModelVariant::SeedEq25;
  std::vector<double> e_seed, e_correct, nrmse_seed, nrmse_correct;
  for (const RegionStep& rs : steps) {
    if (rs.contact_frames < 10) continue;
    const RegionFit a = fit_region(rs.footprint, rs.truth, shipped_config().fit_bounds, seed);
    const RegionFit b =
        fit_region(rs.footprint, rs.truth, shipped_config().fit_bounds, FitSettings{});
    if (a.status != FitStatus::Ok || b.status != FitStatus::Ok) continue;
    e_seed.push_back(rel_error(a.cbar_ns_per_mm3.value, rs.truth.cbar_ns_per_mm3));
    e_correct.push_back(rel_error(b.cbar_ns_per_mm3.value, rs.truth.cbar_ns_per_mm3));
    nrmse_seed.push_back(a.nrmse_pct);
    nrmse_correct.push_back(b.nrmse_pct);
  }
  ASSERT_GE(e_seed.size(), 20u);
  std::printf(
      "[ seed_eq25 ] cbar median rel. error %.3f (seed_eq25 fit) vs %.3f (correct fit), "
      "NRMSE %.2f vs %.2f %%\n",
      median(e_seed), median(e_correct), median(nrmse_seed), median(nrmse_correct));
  EXPECT_GT(median(e_correct), median(e_seed));
  EXPECT_GT(median(nrmse_correct), median(nrmse_seed));
}

TEST(TissueFit, SeedEq25FitRecoversANoiseFreeSeedEq25Series) {
  const RegionSeries s = model_series(kHeel, ModelVariant::SeedEq25, 60);
  const RegionFit a =
      fit_region(s, kHeel, shipped_config().fit_bounds, raw(ModelVariant::SeedEq25));
  const RegionFit b = fit_region(s, kHeel, shipped_config().fit_bounds, raw());
  ASSERT_EQ(a.status, FitStatus::Ok);
  EXPECT_NEAR(a.kbar_n_per_mm3.value, 0.117, 0.117 * 0.05);
  EXPECT_NEAR(a.n.value, 0.294, 0.294 * 0.05);
  EXPECT_NEAR(a.cbar_ns_per_mm3.value, 0.011, 0.011 * 0.10);
  EXPECT_NEAR(a.m.value, 1.18, 1.18 * 0.10);
  EXPECT_GT(b.nrmse_pct, a.nrmse_pct + 0.5);
}

// The material rate's damping force is twice eq 15's at a small contact: a fit with the other
// form finds a cbar that is off by about that factor, while its own recovers the truth.
TEST(TissueFit, MaterialRateFitRecoversANoiseFreeMaterialRateSeries) {
  const RegionSeries s = model_series(kHeel, ModelVariant::MaterialRate, 60);
  const RegionFit a =
      fit_region(s, kHeel, shipped_config().fit_bounds, raw(ModelVariant::MaterialRate));
  const RegionFit b = fit_region(s, kHeel, shipped_config().fit_bounds, raw());
  ASSERT_EQ(a.status, FitStatus::Ok) << a.reason;
  ASSERT_EQ(b.status, FitStatus::Ok) << b.reason;
  EXPECT_NEAR(a.kbar_n_per_mm3.value, 0.117, 0.117 * 0.03);
  EXPECT_NEAR(a.n.value, 0.294, 0.294 * 0.03);
  EXPECT_NEAR(a.cbar_ns_per_mm3.value, 0.011, 0.011 * 0.05);
  EXPECT_NEAR(a.m.value, 1.18, 1.18 * 0.05);
  EXPECT_LT(a.nrmse_pct, 0.5);
  std::printf(
      "material-rate series: cbar %.4f (material_rate fit) / %.4f (correct fit), truth "
      "0.011\n",
      a.cbar_ns_per_mm3.value, b.cbar_ns_per_mm3.value);
  EXPECT_GT(rel_error(b.cbar_ns_per_mm3.value, 0.011), 0.5);
}

// What the material rate does to the measured footprint: its pressure is c ddot on the rim, not
// zero, so the paraboloid fitted to the cells' loads (footprint.hpp, derived for eq 15's field)
// is wider while loading and narrower while unloading, and that carries the damping force
// itself. The fit then finds next to no damping. Measured here so that an estimator made for
// the material rate shows it has changed this.
TEST(TissueFit, OnAMaterialRateSessionTheFootprintAbsorbsTheDamping) {
  const auto steps =
      simulated_region_steps(InsoleSize::S39_40, 23, 8.0, ModelVariant::MaterialRate);
  FitSettings material;
  material.model = ModelVariant::MaterialRate;
  std::vector<double> ratio, nrmse;
  for (const RegionStep& rs : steps) {
    if (rs.contact_frames < 10 || !area_determined(rs.region)) continue;
    const RegionFit fit = fit_region(rs.footprint, rs.truth, shipped_config().fit_bounds, material);
    if (fit.status != FitStatus::Ok) continue;
    ratio.push_back(fit.cbar_ns_per_mm3.value / rs.truth.cbar_ns_per_mm3);
    nrmse.push_back(fit.nrmse_pct);
  }
  ASSERT_GE(ratio.size(), 20u);
  std::printf(
      "[ material_rate session, material_rate fit ] median fitted / true cbar %.3f, "
      "median NRMSE %.2f %%\n",
      median(ratio), median(nrmse));
  EXPECT_LT(median(ratio), 0.3);
}

// Cells that average the pressure over their area (the coverage raster, model-notes section 4)
// break the footprint's premise that a cell reads the pressure at its centre: partly covered rim
// cells read more than the paraboloid through the others, inner cells less (the average of a
// concave quadratic over a 7.5 x 15 mm cell), which flattens and widens the fitted cap, most at
// a small contact, so that the area would grow too slowly against the force and the fit take a
// larger n (the mechanism is inferred; the bias in n is measured). Measured here, as the recovery
// figures are made on the cell-centre raster, so that an estimator for averaging cells shows it
// has changed this.
TEST(TissueFit, OnACoverageRasterTheFootprintOverReadsAndTheStiffnessExponentIsBiased) {
  double ratio_n[2] = {0.0, 0.0};
  int i = 0;
  for (Rasterisation raster : {Rasterisation::CellCentre, Rasterisation::Coverage}) {
    const auto steps =
        simulated_region_steps(InsoleSize::S39_40, 25, 8.0, ModelVariant::Correct, raster);
    std::vector<double> ratio, nrmse;
    for (const RegionStep& rs : steps) {
      if (rs.contact_frames < 10 || !area_determined(rs.region)) continue;
      const RegionFit fit =
          fit_region(rs.footprint, rs.truth, shipped_config().fit_bounds, FitSettings{});
      if (fit.status != FitStatus::Ok) continue;
      ratio.push_back(fit.n.value / rs.truth.n);
      nrmse.push_back(fit.nrmse_pct);
    }
    ASSERT_GE(ratio.size(), 20u);
    ratio_n[i++] = median(ratio);
    std::printf("[ %s raster ] median fitted / true n %.2f, median NRMSE %.2f %%\n",
                std::string(rasterisation_name(raster)).c_str(), median(ratio), median(nrmse));
  }
  EXPECT_NEAR(ratio_n[0], 1.0, 0.2);
  EXPECT_GT(ratio_n[1], 1.5);
}

// The footprint of averaging cells (footprint_area_cell_mean_mm2, AreaSource::FootprintMean) on
// the same sessions as the test above: on the coverage raster it takes out the bias in n and
// kbar; on the cell-centre raster, whose cells do not average, it is the biased one.
TEST(TissueFit, OnACoverageRasterTheCellMeanFootprintRecoversTheStiffnessExponent) {
  struct Ratios {
    double n = 0.0, kbar = 0.0, cbar = 0.0, nrmse = 0.0;
  };
  std::map<std::pair<Rasterisation, AreaSource>, Ratios> measured;
  for (Rasterisation raster : {Rasterisation::CellCentre, Rasterisation::Coverage}) {
    const auto steps = simulated_region_steps(InsoleSize::S39_40, 25, 8.0, ModelVariant::Correct,
                                              raster, CellMeanFootprint::Fit);
    for (AreaSource area : {AreaSource::Footprint, AreaSource::FootprintMean}) {
      std::vector<double> n, kbar, cbar, nrmse;
      for (const RegionStep& rs : steps) {
        if (rs.contact_frames < 10 || !area_determined(rs.region)) continue;
        const RegionFit fit =
            fit_region(rs.series(area), rs.truth, shipped_config().fit_bounds, FitSettings{});
        if (fit.status != FitStatus::Ok) continue;
        n.push_back(fit.n.value / rs.truth.n);
        kbar.push_back(fit.kbar_n_per_mm3.value / rs.truth.kbar_n_per_mm3);
        cbar.push_back(fit.cbar_ns_per_mm3.value / rs.truth.cbar_ns_per_mm3);
        nrmse.push_back(fit.nrmse_pct);
      }
      ASSERT_GE(n.size(), 20u);
      const Ratios r{median(n), median(kbar), median(cbar), median(nrmse)};
      measured[{raster, area}] = r;
      std::printf(
          "[ %s raster, area %s ] %zu fits, median fitted / true n %.2f kbar %.2f cbar %.2f, "
          "median NRMSE %.2f %%\n",
          std::string(rasterisation_name(raster)).c_str(),
          std::string(area_source_name(area)).c_str(), n.size(), r.n, r.kbar, r.cbar, r.nrmse);
    }
  }
  // Measured: n 1.00, kbar 0.99, cbar 1.05, NRMSE 2.2 % against 2.14, 1.91, 1.24 and 5.5 % with
  // the footprint; on the centre raster n 0.07 against 0.95.
  const Ratios& biased = measured[{Rasterisation::Coverage, AreaSource::Footprint}];
  const Ratios& mean = measured[{Rasterisation::Coverage, AreaSource::FootprintMean}];
  EXPECT_GT(biased.n, 1.5);
  EXPECT_NEAR(mean.n, 1.0, 0.15);
  EXPECT_NEAR(mean.kbar, 1.0, 0.15);
  EXPECT_NEAR(mean.cbar, 1.0, 0.25);
  EXPECT_LT(mean.nrmse, 3.0);
  EXPECT_LT(mean.nrmse, biased.nrmse);
  const Ratios& on_centres = measured[{Rasterisation::CellCentre, AreaSource::FootprintMean}];
  EXPECT_LT(on_centres.n, 0.5);
}

TEST(TissueFit, NoContactAndTooFewFrames) {
  RegionSeries s;
  for (int i = 0; i < 20; ++i) {
    s.t_s.push_back(0.01 * i);
    s.area_mm2.push_back(0.0);
    s.force_n.push_back(0.0);
  }
  const RegionFit none = fit_region(s, kHeel, shipped_config().fit_bounds, FitSettings{});
  EXPECT_EQ(none.status, FitStatus::NoContact);
  EXPECT_EQ(none.frames, 0);
  EXPECT_EQ(none.model_force_n.size(), 20u);
  s.area_mm2[5] = 500.0;
  s.area_mm2[6] = 700.0;
  s.force_n[5] = 50.0;
  s.force_n[6] = 80.0;
  const RegionFit few = fit_region(s, kHeel, shipped_config().fit_bounds, FitSettings{});
  EXPECT_EQ(few.status, FitStatus::Failed);
  EXPECT_EQ(few.reason, "too_few_frames");
  EXPECT_EQ(fit_status_name(few.status), "fit_failed");
}

TEST(TissueFit, LengthMismatchThrows) {
  RegionSeries s = model_series(kHeel, ModelVariant::Correct, 30);
  s.force_n.pop_back();
  EXPECT_THROW(fit_region(s, kHeel, shipped_config().fit_bounds, FitSettings{}),
               std::invalid_argument);
}

// A transform between the tissue and the cells, written out here on its own: a relaxing
// Maxwell branch (the force less 0.35 of it low-passed with tau 0.2 s, advanced frame by frame)
// and a constant 4 N that the cells add. The fit given it finds the tissue under it; the fit
// without it does not.
ForceTransform relaxing(const RegionSeries& s) {
  ForceTransform t;
  t.offset_n.assign(s.t_s.size(), 4.0);
  const std::vector<double> times = s.t_s;
  t.linear = [times](std::span<const double> tissue, std::span<double> reported) {
    double r = 0.0;
    for (std::size_t i = 0; i < tissue.size(); ++i) {
      const double keep = std::exp(-(i > 0 ? times[i] - times[i - 1] : 0.01) / 0.2);
      r = r * keep + tissue[i] * (1.0 - keep);
      reported[i] = tissue[i] - 0.35 * r;
    }
  };
  return t;
}

RegionSeries through(const RegionSeries& s, const ForceTransform& t) {
  RegionSeries out = s;
  t.linear(s.force_n, out.force_n);
  for (std::size_t i = 0; i < out.force_n.size(); ++i) out.force_n[i] += t.offset_n[i];
  return out;
}

TEST(TissueFit, AForceTransformFindsTheTissueUnderIt) {
  const RegionSeries tissue = model_series(kHeel, ModelVariant::Correct, 60);
  const ForceTransform t = relaxing(tissue);
  const RegionSeries reported = through(tissue, t);
  const RegionFit with = fit_region(reported, kHeel, shipped_config().fit_bounds, raw(), &t);
  ASSERT_EQ(with.status, FitStatus::Ok) << with.reason << " " << with.solver_message;
  EXPECT_NEAR(with.kbar_n_per_mm3.value, 0.117, 0.117 * 0.03);
  EXPECT_NEAR(with.n.value, 0.294, 0.294 * 0.03);
  EXPECT_NEAR(with.cbar_ns_per_mm3.value, 0.011, 0.011 * 0.05);
  EXPECT_NEAR(with.m.value, 1.18, 1.18 * 0.05);
  EXPECT_TRUE(std::isfinite(with.kbar_n_per_mm3.se));
  // The model force is what the cells report, so it follows the reported series.
  EXPECT_LT(with.nrmse_pct, 0.5);
  for (std::size_t i = 0; i < reported.force_n.size(); ++i) {
    EXPECT_NEAR(with.model_force_n[i], reported.force_n[i], 0.01 * 300.0) << i;
  }
  const RegionFit without = fit_region(reported, kHeel, shipped_config().fit_bounds, raw());
  ASSERT_EQ(without.status, FitStatus::Ok);
  EXPECT_GT(without.nrmse_pct, 2.0 * with.nrmse_pct);

  // Shared by two stances, each with its own transform; nullptr leaves a stance as it is.
  const std::vector<RegionSeries> stances{reported, tissue};
  const std::vector<const ForceTransform*> transforms{&t, nullptr};
  const RegionFit session =
      fit_region_session(stances, kHeel, shipped_config().fit_bounds, raw(), transforms);
  ASSERT_EQ(session.status, FitStatus::Ok);
  EXPECT_NEAR(session.kbar_n_per_mm3.value, 0.117, 0.117 * 0.03);
  EXPECT_NEAR(session.n.value, 0.294, 0.294 * 0.03);
}

TEST(TissueFit, AnIdentityTransformChangesNothing) {
  const RegionSeries s = model_series(kHeel, ModelVariant::Correct, 40);
  ForceTransform identity;
  identity.offset_n.assign(s.t_s.size(), 0.0);
  identity.linear = [](std::span<const double> in, std::span<double> out) {
    std::copy(in.begin(), in.end(), out.begin());
  };
  const RegionFit with = fit_region(s, kHeel, shipped_config().fit_bounds, raw(), &identity);
  const RegionFit without = fit_region(s, kHeel, shipped_config().fit_bounds, raw());
  EXPECT_DOUBLE_EQ(with.kbar_n_per_mm3.value, without.kbar_n_per_mm3.value);
  EXPECT_DOUBLE_EQ(with.n.value, without.n.value);
  EXPECT_DOUBLE_EQ(with.cbar_ns_per_mm3.value, without.cbar_ns_per_mm3.value);
  EXPECT_DOUBLE_EQ(with.m.value, without.m.value);
  EXPECT_DOUBLE_EQ(with.kbar_n_per_mm3.se, without.kbar_n_per_mm3.se);
}

TEST(TissueFit, AForceTransformIsRefusedWhereItCannotBeUsed) {
  const RegionSeries s = model_series(kHeel, ModelVariant::Correct, 40);
  ForceTransform t = relaxing(s);
  FitSettings seed8 = raw();
  seed8.mode = FitMode::Seed8;
  EXPECT_THROW(fit_region(s, kHeel, shipped_config().fit_bounds, seed8, &t), std::invalid_argument);
  FitSettings free_scale = raw();
  free_scale.free_scale = true;
  EXPECT_THROW(fit_region(s, kHeel, shipped_config().fit_bounds, free_scale, &t),
               std::invalid_argument);
  const std::vector<RegionSeries> two{s, s};
  const std::vector<const ForceTransform*> one{&t};
  EXPECT_THROW(fit_region_session(two, kHeel, shipped_config().fit_bounds, raw(), one),
               std::invalid_argument);
  t.offset_n.pop_back();
  EXPECT_THROW(fit_region(s, kHeel, shipped_config().fit_bounds, raw(), &t), std::invalid_argument);
  ForceTransform no_map;
  no_map.offset_n.assign(s.t_s.size(), 0.0);
  EXPECT_THROW(fit_region(s, kHeel, shipped_config().fit_bounds, raw(), &no_map),
               std::invalid_argument);
}

TEST(TissueFit, SessionFitSharesOneParameterSet) {
  const std::vector<RegionSeries> stances{model_series(kHeel, ModelVariant::Correct, 50),
                                          model_series(kHeel, ModelVariant::Correct, 60)};
  const RegionFit fit = fit_region_session(stances, kHeel, shipped_config().fit_bounds, raw());
  ASSERT_EQ(fit.status, FitStatus::Ok);
  EXPECT_EQ(fit.frames, 110);
  EXPECT_EQ(fit.model_force_n.size(), 110u);
  EXPECT_NEAR(fit.kbar_n_per_mm3.value, 0.117, 0.117 * 0.03);
  EXPECT_NEAR(fit.n.value, 0.294, 0.294 * 0.03);
}

TEST(TissueFit, Nrmse) {
  // RMS of (0, 1, -1, 0) = sqrt(0.5); peak 10.
  const std::vector<double> measured{2.0, 10.0, 4.0, 0.0};
  const std::vector<double> model{2.0, 9.0, 5.0, 0.0};
  EXPECT_NEAR(nrmse_pct(measured, model), std::sqrt(0.5) / 10.0 * 100.0, 1e-12);
}

TEST(TissueFit, Names) {
  EXPECT_EQ(parse_smoothing("seed"), Smoothing::Seed);
  EXPECT_EQ(parse_smoothing("none"), Smoothing::None);
  EXPECT_FALSE(parse_smoothing("x"));
  EXPECT_EQ(parse_fit_mode("seed8"), FitMode::Seed8);
  EXPECT_EQ(fit_mode_name(FitMode::Identifiable), "identifiable");
  EXPECT_EQ(fit_status_name(FitStatus::NoContact), "no_contact");
}

// --free-scale also fits P = pi A B, keeping A/B. On the model's own series it finds P from a
// declaration 30 % off either way: the force depends on P beyond the combination kbar P^-(1+n)
// only through the contact's depth g (here up to 0.13), and without noise that is enough. The
// fit with P declared at the wrong value puts the error into kbar and cbar instead.
TEST(TissueFit, FreeScaleFindsTheContactScaleOfANoiseFreeSeries) {
  const RegionSeries s = model_series(kHeel, ModelVariant::Correct, 60);
  const double true_p = std::acos(-1.0) * kHeel.A_mm * kHeel.B_mm;
  FitSettings free_scale = raw();
  free_scale.free_scale = true;
  for (const double scale : {0.7, 1.3}) {
    EllipsoidParams declared = kHeel;
    declared.A_mm *= std::sqrt(scale);
    declared.B_mm *= std::sqrt(scale);
    const RegionFit f = fit_region(s, declared, shipped_config().fit_bounds, free_scale);
    ASSERT_EQ(f.status, FitStatus::Ok) << f.reason << " " << f.solver_message;
    EXPECT_NEAR(std::acos(-1.0) * f.A_mm.value * f.B_mm.value / true_p, 1.0, 0.005) << scale;
    EXPECT_NEAR(f.A_mm.value / f.B_mm.value, kHeel.A_mm / kHeel.B_mm, 1e-9);
    EXPECT_NEAR(f.kbar_n_per_mm3.value, 0.117, 0.117 * 0.02);
    EXPECT_NEAR(f.n.value, 0.294, 0.294 * 0.02);
    EXPECT_NEAR(f.cbar_ns_per_mm3.value, 0.011, 0.011 * 0.02);
    EXPECT_NEAR(f.m.value, 1.18, 1.18 * 0.02);
    EXPECT_TRUE(f.A_mm.free && f.B_mm.free);
    EXPECT_FALSE(f.C_mm.free || f.d0_mm.free);
    EXPECT_GT(f.A_mm.se, 0.0);
    EXPECT_TRUE(std::isfinite(f.A_mm.se));
    EXPECT_TRUE(f.undetermined.empty());

    const RegionFit d = fit_region(s, declared, shipped_config().fit_bounds, raw());
    ASSERT_EQ(d.status, FitStatus::Ok) << d.reason;
    EXPECT_FALSE(d.A_mm.free);
    EXPECT_DOUBLE_EQ(d.A_mm.value, declared.A_mm);
    EXPECT_GT(rel_error(d.kbar_n_per_mm3.value, 0.117), 0.2) << scale;
    EXPECT_GT(d.nrmse_pct, 10.0 * f.nrmse_pct) << scale;
  }
}

}  // namespace
}  // namespace gaitmon
