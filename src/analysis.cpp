// The per-step analysis pipeline and the session-level summary.
#include "gaitmon/analysis.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <tuple>

#include "gaitmon/stance.hpp"
#include "parallel_for.hpp"

namespace gaitmon {
namespace {

double median_of(std::vector<double> values) {
  return spread_of(std::move(values)).median;
}

}  // namespace

std::string_view area_source_name(AreaSource source) {
  switch (source) {
    case AreaSource::Ellipse:
      return "ellipse";
    case AreaSource::Footprint:
      return "footprint";
    case AreaSource::FootprintMean:
      return "footprint-mean";
  }
  return "footprint";
}

AreaSource footprint_for(const CellReadingEvidence& evidence) {
  return evidence.favoured() == CellReading::Mean ? AreaSource::FootprintMean
                                                  : AreaSource::Footprint;
}

std::optional<AreaSource> parse_area_source(std::string_view text) {
  if (text == "ellipse") return AreaSource::Ellipse;
  if (text == "footprint") return AreaSource::Footprint;
  if (text == "footprint-mean") return AreaSource::FootprintMean;
  return std::nullopt;
}

std::pair<std::vector<double>, AreaSource> fit_areas_mm2(const StanceSeries& stance, Region region,
                                                         AreaSource source) {
  std::vector<double> ellipse(stance.size(), 0.0);
  std::vector<double> footprint(stance.size(), 0.0);
  int determined = 0;
  for (std::size_t f = 0; f < stance.size(); ++f) {
    const RegionSample& s = stance.at(f, region);
    ellipse[f] = s.ellipse.area_mm2;
    const auto& area =
        source == AreaSource::FootprintMean ? s.footprint_cell_mean_area_mm2 : s.footprint_area_mm2;
    if (ellipse[f] > 0.0 && area) {
      footprint[f] = *area;
      ++determined;
    }
  }
  if (source != AreaSource::Ellipse && determined >= kMinFootprintFrames) {
    return {std::move(footprint), source};
  }
  return {std::move(ellipse), AreaSource::Ellipse};
}

Spread spread_of(std::vector<double> values) {
  Spread s;
  if (values.empty()) return s;
  std::sort(values.begin(), values.end());
  s.count = static_cast<int>(values.size());
  const auto quantile = [&](double q) {
    const double pos = q * static_cast<double>(values.size() - 1);
    const auto lo = static_cast<std::size_t>(std::floor(pos));
    const std::size_t hi = std::min(lo + 1, values.size() - 1);
    return values[lo] + (pos - static_cast<double>(lo)) * (values[hi] - values[lo]);
  };
  s.median = quantile(0.5);
  s.q1 = quantile(0.25);
  s.q3 = quantile(0.75);
  return s;
}

EllipsoidParams declared_params(const SeedTissueStats& seed, double aspect) {
  if (!(aspect > 0.0) || !std::isfinite(aspect)) {
    throw std::invalid_argument("declared_params: aspect A/B must be positive and finite");
  }
  EllipsoidParams p = seed.mean;
  const double P = std::numbers::pi * seed.mean.A_mm * seed.mean.B_mm;
  p.A_mm = std::sqrt(P * aspect / std::numbers::pi);
  p.B_mm = std::sqrt(P / (std::numbers::pi * aspect));
  return p;
}

StepAnalysis analyse_step(const Step& step, const InsoleLayout& layout, const Config& config,
                          const AnalysisSettings& settings, ContactEllipseCache* cache) {
  const StanceSeries stance =
      measure_stance(step, layout, config.calibration, cache,
                     settings.area == AreaSource::FootprintMean ? CellMeanFootprint::Fit
                                                                : CellMeanFootprint::Skip);
  const std::size_t frames = stance.size();
  StepAnalysis out;
  out.foot = step.foot;
  out.step = step.index;
  out.t_heel_strike_s = step.t_heel_strike_s;
  out.t_toe_off_s = step.t_toe_off_s;
  out.model = settings.fit.model;
  out.t_s = stance.t_s;
  out.measured_total_force_n.assign(frames, 0.0);

  std::vector<double> aspects;
  for (Region region : kRegions) {
    RegionAnalysis& r = out.regions[index_of(region)];
    r.region = region;
    r.series.t_s = stance.t_s;
    std::tie(r.series.area_mm2, r.area) = fit_areas_mm2(stance, region, settings.area);
    r.series.force_n.resize(frames);
    aspects.clear();
    for (std::size_t f = 0; f < frames; ++f) {
      const RegionSample& s = stance.at(f, region);
      r.series.force_n[f] = s.force_n;
      r.peak_force_n = std::max(r.peak_force_n, s.force_n);
      r.peak_area_mm2 = std::max(r.peak_area_mm2, r.series.area_mm2[f]);
      out.measured_total_force_n[f] += s.force_n;
      if (s.ellipse.kase != EllipseCase::None && s.ellipse.rb_mm > 0.0) {
        if (r.frames++ == 0) r.t_contact_s = stance.t_s[f];
        aspects.push_back(s.ellipse.ra_mm / s.ellipse.rb_mm);
      }
    }
    const SeedTissueStats& seed = config.tissue(layout.size(), region);
    r.aspect = aspects.empty() ? seed.mean.A_mm / seed.mean.B_mm : median_of(aspects);
    r.declared = declared_params(seed, r.aspect);
    r.fit = fit_region(r.series, r.declared, config.fit_bounds, settings.fit);
  }
  set_model_totals(out);
  return out;
}

std::vector<StepAnalysis> analyse_steps(std::span<const Step> steps, const InsoleLayout& layout,
                                        const Config& config, const AnalysisSettings& settings,
                                        const std::function<void(double)>& on_progress) {
  std::vector<StepAnalysis> out(steps.size());
  std::vector<ContactEllipseCache> caches(detail::parallel_workers(steps.size()));
  detail::parallel_for_workers(
      steps.size(),
      [&](std::size_t i, std::size_t worker) {
        out[i] = analyse_step(steps[i], layout, config, settings, &caches[worker]);
      },
      [&](std::size_t done) {
        if (on_progress) {
          on_progress(static_cast<double>(done) / static_cast<double>(steps.size()));
        }
      });
  return out;
}

SharedExponents shared_damping_exponents(std::span<const StepAnalysis> steps, const Config& config,
                                         const AnalysisSettings& settings) {
  SharedExponents out;
  detail::parallel_for(kRegionCount, [&](std::size_t ri) {
    std::vector<RegionSeries> series;
    std::vector<EllipsoidParams> declared;
    for (const StepAnalysis& step : steps) {
      const RegionAnalysis& r = step.regions[ri];
      if (r.fit.status != FitStatus::Ok) continue;
      series.push_back(r.series);
      declared.push_back(r.declared);
    }
    out[ri] = fit_shared_damping_exponent(series, declared, config.fit_bounds, settings.fit);
  });
  return out;
}

void fit_at_shared_exponents(StepAnalysis& step, const SharedExponents& shared,
                             const Config& config, const AnalysisSettings& settings) {
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    RegionAnalysis& r = step.regions[ri];
    if (!shared[ri] || r.fit.status != FitStatus::Ok) continue;
    FitSettings at = settings.fit;
    at.declared_m = shared[ri]->m;
    RegionFit fit = fit_region(r.series, r.declared, config.fit_bounds, at);
    if (fit.status != FitStatus::Ok) continue;
    fit.m.se = shared[ri]->se;
    fit.m.at_bound = shared[ri]->at_bound;
    r.fit = std::move(fit);
  }
  set_model_totals(step);
}

SharedExponents fit_damping_exponent_per_session(std::span<StepAnalysis> steps,
                                                 const Config& config,
                                                 const AnalysisSettings& settings) {
  const SharedExponents shared = shared_damping_exponents(steps, config, settings);
  detail::parallel_for(steps.size(), [&](std::size_t k) {
    fit_at_shared_exponents(steps[k], shared, config, settings);
  });
  return shared;
}

void set_model_totals(StepAnalysis& step) {
  const std::size_t frames = step.t_s.size();
  step.model_total_force_n.assign(frames, 0.0);
  for (const RegionAnalysis& r : step.regions) {
    if (r.fit.status == FitStatus::Ok && r.fit.model_force_n.size() == frames) {
      for (std::size_t f = 0; f < frames; ++f)
        step.model_total_force_n[f] += r.fit.model_force_n[f];
    }
  }
  step.nrmse_total_pct =
      frames == 0 ? 0.0 : nrmse_pct(step.measured_total_force_n, step.model_total_force_n);
}

namespace {

// Positions in a MaterialVector.
constexpr std::size_t kLnKbar = 0;
constexpr std::size_t kLnCbar = 2;

// One parameter's course over the session and its difference between the feet, from the steps
// that have estimates, leaving out those whose fit held it at a bound: a value pinned there says
// nothing of the tissue. With `footprint_only`, also those fitted on the contact ellipse, whose
// area moves in whole cells and does not determine the damping (README, "How the fit works").
std::pair<std::optional<LogTrend>, std::optional<FootAsymmetry>> step_course(
    std::span<const StepAnalysis> steps, const std::vector<std::size_t>& estimated_steps,
    const std::vector<MaterialEstimate>& estimates, std::size_t index,
    const Estimate RegionFit::*parameter, Region region, bool footprint_only, double pair_sd_pct) {
  std::vector<Foot> feet;
  std::vector<double> t, value, variance;
  for (std::size_t k = 0; k < estimates.size(); ++k) {
    const StepAnalysis& step = steps[estimated_steps[k]];
    const RegionAnalysis& ra = step.at(region);
    if ((ra.fit.*parameter).at_bound || (footprint_only && ra.area == AreaSource::Ellipse)) {
      continue;
    }
    feet.push_back(step.foot);
    t.push_back(step.t_heel_strike_s);
    value.push_back(estimates[k].value[index]);
    variance.push_back(estimates[k].covariance[index][index]);
  }
  return {log_trend(t, value, variance, feet),
          foot_asymmetry(feet, t, value, variance, pair_sd_pct / 100.0)};
}

RegionSessionAnalysis analyse_region(std::span<const StepAnalysis> steps, Region region,
                                     const Config& config, InsoleSize size,
                                     const AnalysisSettings& settings) {
  RegionSessionAnalysis r;
  r.region = region;
  std::vector<RegionSeries> stances;
  std::vector<const ForceTransform*> transforms;
  std::vector<double> aspects;
  std::array<std::vector<double>, 9> values;
  std::vector<MaterialEstimate> estimates;
  std::vector<std::size_t> estimated_steps;
  for (std::size_t si = 0; si < steps.size(); ++si) {
    const RegionAnalysis& ra = steps[si].at(region);
    if (ra.frames == 0) continue;
    ++r.steps_with_contact;
    if (settings.area != AreaSource::Ellipse && ra.area == AreaSource::Ellipse) {
      ++r.steps_on_ellipse;
    }
    stances.push_back(ra.series);
    transforms.push_back(ra.effects.get());
    aspects.push_back(ra.aspect);
    if (ra.fit.status != FitStatus::Ok) continue;
    ++r.steps_fitted;
    const RegionFit& f = ra.fit;
    const std::array<double, 9> v{f.A_mm.value,
                                  f.B_mm.value,
                                  f.C_mm.value,
                                  f.d0_mm.value,
                                  f.kbar_n_per_mm3.value,
                                  f.n.value,
                                  f.cbar_ns_per_mm3.value,
                                  f.m.value,
                                  f.nrmse_pct};
    for (std::size_t i = 0; i < v.size(); ++i) values[i].push_back(v[i]);
    if (const auto e = material_estimate(f)) {
      estimates.push_back(*e);
      estimated_steps.push_back(si);
    }
  }
  // At one m per session a step whose fit at that m failed keeps its own m and is no estimate
  // of the shared m's tissue: the pool leaves it out.
  const bool shared_m = std::any_of(estimates.begin(), estimates.end(),
                                    [](const auto& e) { return e.slope_on_shared_m.has_value(); });
  if (shared_m) {
    std::size_t kept = 0;
    for (std::size_t k = 0; k < estimates.size(); ++k) {
      if (!estimates[k].slope_on_shared_m) continue;
      estimates[kept] = estimates[k];
      estimated_steps[kept++] = estimated_steps[k];
    }
    estimates.resize(kept);
    estimated_steps.resize(kept);
  }
  const PoolingSettings& tables = pooling_tables(config, settings.area);
  r.pooling = pool_region_steps(estimates, region, tables, config.fit_bounds);
  const AsymmetrySettings& pairs = asymmetry_tables(config, settings.area);
  const PairSds& pair = shared_m ? pairs.m_per_session : pairs.per_step;
  if (settings.fit.mode != FitMode::Identifiable || settings.fit.free_scale) {
    r.pooling.not_pooled = "pooling needs the default fit (identifiable, P declared)";
  }
  std::tie(r.kbar_trend, r.kbar_asymmetry) =
      step_course(steps, estimated_steps, estimates, kLnKbar, &RegionFit::kbar_n_per_mm3, region,
                  false, pair.kbar_pair_sd_pct[index_of(region)]);
  std::tie(r.cbar_trend, r.cbar_asymmetry) =
      step_course(steps, estimated_steps, estimates, kLnCbar, &RegionFit::cbar_ns_per_mm3, region,
                  true, pair.cbar_pair_sd_pct[index_of(region)]);
  r.chain_sd = chain_sd(tables, region, shared_m);
  r.pooled_per_step.resize(steps.size());
  r.pooled_mean = pooled_mean_with_chain_error(r.pooling, r.chain_sd);
  if (r.pooling.pooled) {
    for (std::size_t k = 0; k < estimated_steps.size(); ++k) {
      r.pooled_per_step[estimated_steps[k]] =
          material_params(with_shared_error(r.pooling.steps[k], r.chain_sd));
    }
  }
  const SeedTissueStats& seed = config.tissue(size, region);
  r.aspect = aspects.empty() ? seed.mean.A_mm / seed.mean.B_mm : median_of(aspects);
  r.declared = declared_params(seed, r.aspect);
  if (!stances.empty()) {
    const bool effects = std::any_of(transforms.begin(), transforms.end(),
                                     [](const ForceTransform* t) { return t != nullptr; });
    r.session_fit = fit_region_session(stances, r.declared, config.fit_bounds, settings.fit,
                                       effects ? std::span<const ForceTransform* const>(transforms)
                                               : std::span<const ForceTransform* const>());
  }
  Spread* targets[] = {
      &r.A_mm, &r.B_mm,     &r.C_mm, &r.d0_mm, &r.kbar_n_per_mm3, &r.n, &r.cbar_ns_per_mm3,
      &r.m,    &r.nrmse_pct};
  for (std::size_t i = 0; i < values.size(); ++i) *targets[i] = spread_of(std::move(values[i]));
  return r;
}

}  // namespace

const PoolingSettings& pooling_tables(const Config& config, AreaSource area) {
  return area == AreaSource::FootprintMean ? config.pooling_footprint_mean : config.pooling;
}

const AsymmetrySettings& asymmetry_tables(const Config& config, AreaSource area) {
  return area == AreaSource::FootprintMean ? config.asymmetry_footprint_mean : config.asymmetry;
}

std::string chain_table_name(std::string_view kind, AreaSource area, bool shared_m) {
  return fmt::format("[{}{}{}]", kind, area == AreaSource::FootprintMean ? ".footprint_mean" : "",
                     shared_m ? ".m_per_session" : "");
}

MaterialVector chain_sd(const PoolingSettings& pooling, Region region, bool shared_m) {
  const ChainSds& chain = shared_m ? pooling.m_per_session : pooling.per_step;
  const std::size_t ri = index_of(region);
  return {chain.kbar_chain_sd_pct[ri] / 100.0, chain.n_chain_sd[ri],
          chain.cbar_chain_sd_pct[ri] / 100.0, chain.m_chain_sd[ri]};
}

MaterialVector step_sd(const PoolingSettings& pooling, Region region, bool shared_m) {
  const ChainSds& chain = shared_m ? pooling.m_per_session : pooling.per_step;
  const std::size_t ri = index_of(region);
  return {chain.kbar_step_sd_pct[ri] / 100.0, chain.n_step_sd[ri],
          chain.cbar_step_sd_pct[ri] / 100.0, chain.m_step_sd[ri]};
}

PooledEstimates pool_region_steps(std::span<const MaterialEstimate> estimates, Region region,
                                  const PoolingSettings& pooling, const FitBounds& fit_bounds) {
  std::vector<MaterialEstimate> own(estimates.begin(), estimates.end());
  const MaterialBounds bounds = material_bounds(fit_bounds);
  for (MaterialEstimate& e : own) {
    e = within_m_range(e, bounds);
    const bool shared_m = e.slope_on_shared_m.has_value();
    const MaterialVector sd = step_sd(pooling, region, shared_m);
    for (std::size_t p = 0; p < (shared_m ? 3 : 4); ++p) e.covariance[p][p] += sd[p] * sd[p];
  }
  return pool_steps(own, bounds);
}

std::optional<MaterialEstimate> pooled_mean_with_chain_error(const PooledEstimates& pooling,
                                                             const MaterialVector& chain_sd) {
  if (!pooling.pooled) return std::nullopt;
  return with_shared_error({pooling.mean, pooling.mean_covariance, pooling.mean_slope_on_shared_m},
                           chain_sd);
}

std::optional<MaterialParams> with_chain_error(const RegionFit& fit, Region region,
                                               const PoolingSettings& pooling,
                                               const FitBounds& bounds) {
  std::optional<MaterialEstimate> estimate = material_estimate(fit);
  if (!estimate) return std::nullopt;
  *estimate = within_m_range(*estimate, material_bounds(bounds));
  const bool shared_m = estimate->slope_on_shared_m.has_value();
  if (shared_m) {
    // The shared m's own variance reaches this step's kbar, n and cbar through their slopes, as
    // pool_steps carries it into a mean (m's own entry already holds it).
    const MaterialVector& g = *estimate->slope_on_shared_m;
    const double m_variance = estimate->covariance[3][3];
    for (std::size_t a = 0; a < 4; ++a) {
      for (std::size_t b = 0; b < 4; ++b) {
        if (a < 3 || b < 3) estimate->covariance[a][b] += g[a] * g[b] * m_variance;
      }
    }
  }
  MaterialEstimate total = with_shared_error(*estimate, chain_sd(pooling, region, shared_m));
  // The step's own error beyond its Jacobian's, independent of the other steps' and parameters'.
  const MaterialVector own = step_sd(pooling, region, shared_m);
  for (std::size_t p = 0; p < 4; ++p) total.covariance[p][p] += own[p] * own[p];
  return material_params(total);
}

SessionAnalysis analyse_session(std::span<const StepAnalysis> steps, const Config& config,
                                InsoleSize size, const AnalysisSettings& settings) {
  SessionAnalysis out;
  std::vector<double> totals;
  for (const StepAnalysis& s : steps) totals.push_back(s.nrmse_total_pct);
  out.nrmse_total_pct = spread_of(std::move(totals));

  // The regions' session fits are independent and each takes seconds on a long session.
  detail::parallel_for(kRegionCount, [&](std::size_t i) {
    out.regions[i] = analyse_region(steps, kRegions[i], config, size, settings);
  });
  return out;
}

}  // namespace gaitmon
