// `gaitmon analyze`: per step and region tissue fits, a session-level fit, and a report.
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <iterator>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "commands.hpp"
#include "gaitmon/analysis.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/error.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/json.hpp"
#include "gaitmon/pooling.hpp"
#include "gaitmon/session.hpp"
#include "gaitmon/stance.hpp"
#include "output_file.hpp"
#include "progress.hpp"
#include "report_html.hpp"

namespace gaitmon::cli {
namespace {

struct AnalyzeArgs {
  std::filesystem::path session;
  std::filesystem::path out_dir;
  bool report = false;
  std::string model = "correct";
  std::string fit = "identifiable";
  // Empty: the default, which for --fit seed8 is the seed's own input (see settings_from).
  std::string smoothing;
  std::string area;  ///< empty: [model] area, or the seed's ellipse with --fit seed8
  std::string end_rate = "two-frame";
  bool free_scale = false;
  bool m_per_session = false;
  bool m_per_session_given = false;  ///< else [model] m_per_session of the config
  std::vector<std::string> effects;
  bool effects_given = false;

  /// Whether the area is taken from how the session's cells read (resolved in run_analyze).
  bool area_auto() const { return area == "auto" || (area.empty() && fit != "seed8"); }
};

std::string declared_note(const FitSettings& fit) {
  if (fit.mode == FitMode::Seed8) {
    return "--fit seed8: all eight parameters are free, as in the seed, started at the middle of "
           "the bounds. Force and contact area cannot determine C_mm and d0_mm (model-notes "
           "section 2; see each fit's undetermined list): their values are wherever the "
           "optimiser stopped.";
  }
  return std::string(
             "C_mm and d0_mm are declared, not fitted: force and contact area cannot determine "
             "them (model-notes section 2). They are the seed's Appendix I means for the insole "
             "size and region; A_mm/B_mm is the median measured contact-ellipse aspect, ") +
         (fit.free_scale ? "pi A B fitted (--free-scale). " : "pi A B from Appendix I. ") +
         "kbar and cbar are derived from the identifiable combinations K = kbar C^(1+n) "
         "d0^(-n) and D = cbar C^(1+m) d0^(-m) under those declared values.";
}

AnalysisSettings settings_from(const AnalyzeArgs& args) {
  AnalysisSettings s;
  // CLI11 has checked membership, so the parses cannot fail.
  s.fit.model = *parse_model_variant(args.model);
  s.fit.mode = *parse_fit_mode(args.fit);
  // --fit seed8 reproduces the seed's fit, so by default it also gets the seed's inputs: the
  // contact ellipse's area and the seed's smoothing.
  const bool seed8 = s.fit.mode == FitMode::Seed8;
  if (!args.smoothing.empty()) {
    s.fit.smoothing = *parse_smoothing(args.smoothing);
  } else if (seed8) {
    s.fit.smoothing = Smoothing::Seed;
  }
  // `auto` is resolved once the steps are in (run_analyze), from how the cells read.
  if (!args.area.empty() && !args.area_auto()) {
    s.area = *parse_area_source(args.area);
  } else if (!args.area_auto()) {
    s.area = AreaSource::Ellipse;
  }
  s.fit.end_rate = *parse_end_rate(args.end_rate);
  if (s.fit.end_rate != EndRate::TwoFrame && s.fit.smoothing != Smoothing::None) {
    throw CLI::ValidationError("--end-rate",
                               "applies to --smoothing none only (the seed's "
                               "smoothing takes the rate from its polynomial)");
  }
  s.fit.free_scale = args.free_scale;
  if (s.fit.free_scale && s.fit.mode != FitMode::Identifiable) {
    throw CLI::ValidationError("--free-scale", "applies to --fit identifiable only");
  }
  if (args.m_per_session && (s.fit.mode != FitMode::Identifiable || s.fit.free_scale)) {
    throw CLI::ValidationError(
        "--m-per-session",
        "applies to the default fit only (not --fit seed8 or --free-scale); with [model] "
        "m_per_session in the config, give --m-per-session=false");
  }
  return s;
}

/// Keeps a free-text reason inside one CSV field.
std::string csv_safe(std::string text) {
  std::replace_if(
      text.begin(), text.end(), [](char c) { return c == ',' || c == '\n'; }, ';');
  return text;
}

std::string status_text(const RegionFit& fit) {
  if (fit.status != FitStatus::Failed) return std::string(fit_status_name(fit.status));
  return std::string(fit_status_name(fit.status)) + ":" + csv_safe(fit.reason);
}

struct NamedEstimate {
  const char* name;
  const Estimate* estimate;
};

std::array<NamedEstimate, 8> estimates(const RegionFit& f) {
  return {{{"A_mm", &f.A_mm},
           {"B_mm", &f.B_mm},
           {"C_mm", &f.C_mm},
           {"d0_mm", &f.d0_mm},
           {"kbar_n_per_mm3", &f.kbar_n_per_mm3},
           {"n", &f.n},
           {"cbar_ns_per_mm3", &f.cbar_ns_per_mm3},
           {"m", &f.m}}};
}

std::string at_bound_list(const RegionFit& fit) {
  std::string out;
  for (const auto& [name, e] : estimates(fit)) {
    if (!e->at_bound) continue;
    if (!out.empty()) out += ';';
    out += name;
  }
  return out;
}

std::string steps_csv(const std::vector<StepRow>& steps) {
  std::string out =
      "foot,step,t_heel_strike_s,t_toe_off_s,stance_s,peak_force_n,status,"
      "nrmse_total_pct\n";
  for (const auto& s : steps) {
    fmt::format_to(std::back_inserter(out), "{},{},{},{},{:.4f},{:.2f},{},{}\n", foot_name(s.foot),
                   s.index, s.t_heel_strike_s, s.t_toe_off_s, s.t_toe_off_s - s.t_heel_strike_s,
                   s.peak_force_n, step_status_name(s.status),
                   s.nrmse_total_pct ? fmt::format("{:.3f}", *s.nrmse_total_pct) : "");
  }
  return out;
}

// The pooled columns of one region-step (pooling.hpp), empty where it was not pooled.
std::string pooled_columns(const std::optional<MaterialParams>& p) {
  if (!p) return ",,,,,,,";
  return fmt::format("{:.6g},{:.6g},{:.6g},{:.6g},{:.3g},{:.3g},{:.3g},{:.3g}",
                     p->kbar_n_per_mm3.value, p->n.value, p->cbar_ns_per_mm3.value, p->m.value,
                     p->kbar_n_per_mm3.se, p->n.se, p->cbar_ns_per_mm3.se, p->m.se);
}

// The step's own standard errors with the chain's shared error (with_chain_error), empty where
// the fit has no material estimate.
std::string total_se_columns(const RegionFit& fit, Region region, const Config& config,
                             AreaSource area) {
  const std::optional<MaterialParams> p =
      with_chain_error(fit, region, pooling_tables(config, area), config.fit_bounds);
  if (!p) return ",,,";
  return fmt::format("{:.3g},{:.3g},{:.3g},{:.3g}", p->kbar_n_per_mm3.se, p->n.se,
                     p->cbar_ns_per_mm3.se, p->m.se);
}

// `analyses` in the order analyse_session was given them.
std::string regions_csv(const std::vector<StepAnalysis>& analyses, const SessionAnalysis& session,
                        const Config& config, AreaSource area) {
  std::string out =
      "foot,step,region,status,frames,peak_force_n,peak_area_mm2,A_mm,B_mm,C_mm,d0_mm,"
      "kbar_n_per_mm3,n,cbar_ns_per_mm3,m,se_kbar,se_n,se_cbar,se_m,nrmse_pct,aspect_a_over_b,"
      "at_bound,iterations,final_cost,area,frames_fitted,kbar_pooled,n_pooled,cbar_pooled,"
      "m_pooled,se_kbar_pooled,se_n_pooled,se_cbar_pooled,se_m_pooled,se_kbar_total,se_n_total,"
      "se_cbar_total,se_m_total\n";
  for (std::size_t si = 0; si < analyses.size(); ++si) {
    const StepAnalysis& s = analyses[si];
    for (const RegionAnalysis& r : s.regions) {
      const RegionFit& f = r.fit;
      const std::string pooled_and_total =
          pooled_columns(session.regions[index_of(r.region)].pooled_per_step[si]) + "," +
          total_se_columns(f, r.region, config, area);
      fmt::format_to(std::back_inserter(out), "{},{},{},{},{},{:.3f},{:.2f},", foot_name(s.foot),
                     s.step, region_name(r.region), status_text(f), r.frames, r.peak_force_n,
                     r.peak_area_mm2);
      if (f.status == FitStatus::Ok) {
        fmt::format_to(std::back_inserter(out),
                       "{:.4g},{:.4g},{:.4g},{:.4g},{:.6g},{:.6g},{:.6g},{:.6g},{:.3g},{:.3g},"
                       "{:.3g},{:.3g},{:.3f},{:.4f},{},{},{:.6g},{},{},{}\n",
                       f.A_mm.value, f.B_mm.value, f.C_mm.value, f.d0_mm.value,
                       f.kbar_n_per_mm3.value, f.n.value, f.cbar_ns_per_mm3.value, f.m.value,
                       f.kbar_n_per_mm3.se, f.n.se, f.cbar_ns_per_mm3.se, f.m.se, f.nrmse_pct,
                       r.aspect, at_bound_list(f), f.iterations, f.final_cost,
                       area_source_name(r.area), f.frames, pooled_and_total);
      } else {
        fmt::format_to(std::back_inserter(out), ",,,,,,,,,,,,,{:.4f},,{},,{},{},{}\n", r.aspect,
                       f.iterations, area_source_name(r.area), f.frames, pooled_and_total);
      }
    }
  }
  return out;
}

/// How many standard errors a trend or a difference between the feet must reach for the summary
/// to name it: with about ten of each per session outside the toes, 3 keeps a chance one from
/// showing in most sessions.
constexpr double kNamedZ = 3.0;

/// How many of the region's steps were fitted Ok with the parameter at a bound of its range.
int steps_at_bound(const std::vector<StepAnalysis>& analyses, Region region,
                   const Estimate RegionFit::*estimate) {
  return static_cast<int>(std::count_if(analyses.begin(), analyses.end(), [&](const auto& s) {
    const RegionFit& fit = s.at(region).fit;
    return fit.status == FitStatus::Ok && (fit.*estimate).at_bound;
  }));
}

nlohmann::json spread_json(const Spread& s) {
  return {{"count", s.count}, {"median", s.median}, {"q1", s.q1}, {"q3", s.q3}, {"iqr", s.iqr()}};
}

nlohmann::json fit_json(const RegionFit& f) {
  nlohmann::json params = nlohmann::json::object();
  for (const auto& [name, e] : estimates(f)) {
    params[name] = {
        {"value", e->value}, {"se", e->se}, {"at_bound", e->at_bound}, {"free", e->free}};
  }
  return {{"status", fit_status_name(f.status)},
          {"reason", f.reason},
          {"frames", f.frames},
          {"parameters", params},
          {"nrmse_pct", f.nrmse_pct},
          {"iterations", f.iterations},
          {"final_cost", f.final_cost},
          {"solver_message", f.solver_message},
          {"undetermined", f.undetermined}};
}

// kbar, n, cbar and m's values or standard errors.
nlohmann::json material_json(const MaterialParams& p, double Estimate::*field) {
  return {{"kbar_n_per_mm3", p.kbar_n_per_mm3.*field},
          {"n", p.n.*field},
          {"cbar_ns_per_mm3", p.cbar_ns_per_mm3.*field},
          {"m", p.m.*field}};
}

nlohmann::json pooling_json(const RegionSessionAnalysis& r) {
  const PooledEstimates& p = r.pooling;
  if (!p.pooled || !r.pooled_mean) {
    return {{"pooled", false}, {"steps", p.steps.size()}, {"note", p.not_pooled}};
  }
  const MaterialParams steps = material_params({p.mean, p.mean_covariance, std::nullopt});
  const MaterialParams mean = material_params(*r.pooled_mean);
  const auto sd = [&](std::size_t i) { return std::sqrt(p.between_step[i][i]); };
  return {
      {"pooled", p.pooled},
      {"steps", p.steps.size()},
      {"iterations", p.iterations},
      {"mean", material_json(mean, &Estimate::value)},
      {"se", material_json(mean, &Estimate::se)},
      {"se_steps", material_json(steps, &Estimate::se)},
      {"chain_sd",
       {{"ln_kbar", r.chain_sd[0]},
        {"n", r.chain_sd[1]},
        {"ln_cbar", r.chain_sd[2]},
        {"m", r.chain_sd[3]}}},
      {"between_step_sd", {{"ln_kbar", sd(0)}, {"n", sd(1)}, {"ln_cbar", sd(2)}, {"m", sd(3)}}},
      {"note",
       "per-step fits pooled across steps by a normal random-effects model on (ln kbar, n, ln "
       "cbar, m): regions.csv's *_pooled columns (include/gaitmon/pooling.hpp). se is the "
       "mean's standard error with the measurement chain's shared error, chain_sd from "
       "the config's table that settings.pooling_table names ([pooling], [pooling.m_per_session] "
       "at one m per session, [pooling.footprint_mean] and its m_per_session on the area "
       "footprint-mean; ln kbar and ln cbar: relative); se_steps is the steps' scatter alone. At "
       "one m per session the steps were pooled at that m, and its error (its se and its "
       "chain_sd) enters the others' se through how they move with it. For the region's tissue "
       "over the session "
       "read this mean: session_fit's standard errors are its Jacobian's, and up to fifteen times "
       "too small against the truth (README, \"Per-step estimates pooled across steps\")"}};
}

nlohmann::json trend_json(const std::optional<LogTrend>& t) {
  if (!t) return nullptr;
  return {{"steps", t->steps},
          {"span_min", t->span_min},
          {"ln_slope_per_min", t->ln_slope_per_min},
          {"se_ln_slope_per_min", t->se_ln_slope_per_min},
          {"pct_per_min", t->pct_per_min},
          {"se_pct_per_min", t->se_pct_per_min},
          {"z", t->z()}};
}

nlohmann::json asymmetry_json(const std::optional<FootAsymmetry>& a) {
  if (!a) return nullptr;
  return {{"left_steps", a->left_steps},
          {"right_steps", a->right_steps},
          {"ln_right_over_left", a->ln_ratio},
          {"se_ln_right_over_left", a->se_ln_ratio},
          {"se_steps_ln_right_over_left", a->se_steps_ln_ratio},
          {"insole_pair_sd_ln_right_over_left", a->pair_sd_ln_ratio},
          {"right_over_left_pct", a->pct},
          {"se_right_over_left_pct", a->se_pct},
          {"z", a->z()}};
}

nlohmann::json bounds_json(const FitBounds& b) {
  const auto one = [](const Bounds& x) {
    return nlohmann::json{{"lower", x.lower}, {"upper", x.upper}};
  };
  return {{"A_mm", one(b.A_mm)},
          {"B_mm", one(b.B_mm)},
          {"C_mm", one(b.C_mm)},
          {"d0_mm", one(b.d0_mm)},
          {"kbar_n_per_mm3", one(b.kbar_n_per_mm3)},
          {"n", one(b.n)},
          {"cbar_ns_per_mm3", one(b.cbar_ns_per_mm3)},
          {"m", one(b.m)}};
}

nlohmann::json effects_json(const std::optional<ExtendedModelFit>& fit) {
  if (!fit) return nullptr;
  nlohmann::json effects = nlohmann::json::array();
  for (const EffectEstimate& e : fit->effects) {
    nlohmann::json params = nlohmann::json::object();
    for (const ParamEstimate& p : e.params) params[p.name] = p;
    effects.push_back({{"name", e.name},
                       {"inside_tissue_fit", effect_inside_tissue_fit(e.name)},
                       {"undone_in_readings", effect_undone_in_readings(*fit, e)},
                       {"params", params}});
  }
  nlohmann::json regions = nlohmann::json::object();
  for (const RegionComparison& c : fit->regions) {
    regions[std::string(region_name(c.region))] = c;
  }
  return {{"effects", effects},
          {"note",
           "effect parameters are shared by all steps; each step and region keeps its own "
           "tissue amplitudes and stiffness exponent (include/gaitmon/discrepancy.hpp); NRMSE "
           "pooled over step-regions, of the readings as read; an effect undone_in_readings was "
           "undone in every cell's readings before the steps were measured and fitted again, and "
           "then the other effects' parameters and the extended NRMSEs are of those readings"},
          {"baseline_nrmse_pct", fit->baseline_nrmse_pct},
          {"extended_nrmse_pct", fit->extended_nrmse_pct},
          {"baseline_heldout_nrmse_pct", fit->baseline_heldout_nrmse_pct},
          {"extended_heldout_nrmse_pct", fit->extended_heldout_nrmse_pct},
          {"zero_channel",
           {{"changes", fit->zero_changes},
            {"baseline_heldout_nrmse_pct", fit->zero_baseline_heldout_nrmse_pct},
            {"extended_heldout_nrmse_pct", fit->zero_extended_heldout_nrmse_pct}}},
          {"regions", regions}};
}

// With --m-per-session, the one m every step of the region was fitted at; null otherwise.
nlohmann::json m_per_session_json(const RegionSessionAnalysis& r, bool asked) {
  if (!asked) return nullptr;
  if (!r.m_per_session) {
    return {
        {"m", nullptr},
        {"note", "no step of the region was fitted at every m tried; its steps keep their own"}};
  }
  const SharedExponent& m = *r.m_per_session;
  return {{"m", m.m},
          {"se", std::isfinite(m.se) ? nlohmann::json(m.se) : nlohmann::json(nullptr)},
          {"at_bound", m.at_bound},
          {"steps", m.stances},
          {"note",
           "the m at which the region's steps, each with its own kbar, n and cbar, fit best "
           "together; every step is fitted at it (regions.csv's m and se_m). Its standard error "
           "is that of the steps' residuals and does not hold the measurement chain's shared "
           "error, which pooling's se does"}};
}

std::string session_json(const AnalyzeArgs& args, const SessionHeader& header, const Config& config,
                         const AnalysisSettings& settings, const std::vector<StepRow>& steps,
                         const std::vector<StepAnalysis>& analyses, const SessionAnalysis& session,
                         const std::optional<ExtendedModelFit>& extended,
                         const CellReadingEvidence& cells) {
  nlohmann::json j;
  j["session"] = args.session.string();
  j["insole_size"] = insole_size_name(header.insole_size);
  j["sample_rate_hz"] = header.sample_rate_hz;
  j["steps"] = {{"total", steps.size()}, {"analysed", analyses.size()}};
  j["settings"] = {
      {"model", model_variant_name(settings.fit.model)},
      {"fit", fit_mode_name(settings.fit.mode)},
      {"smoothing", smoothing_name(settings.fit.smoothing)},
      {"area", area_source_name(settings.area)},
      {"area_auto", args.area_auto()},
      {"pooling_table", chain_table_name("pooling", settings.area, args.m_per_session)},
      {"asymmetry_table", chain_table_name("asymmetry", settings.area, args.m_per_session)},
      {"end_rate", end_rate_name(settings.fit.end_rate)},
      {"free_scale", settings.fit.free_scale},
      {"m_per_session", args.m_per_session},
      {"starts", settings.fit.starts},
      {"max_iterations", settings.fit.max_iterations},
      {"bounds", bounds_json(config.fit_bounds)},
      {"sensor_creep_of_config",
       {{"gain", config.sensor_creep.gain}, {"tau_s", config.sensor_creep.tau_s}}}};
  j["note"] = declared_note(settings.fit);
  j["cell_reading"] = cell_reading_json(cells);
  j["nrmse_total_pct_across_steps"] = spread_json(session.nrmse_total_pct);
  nlohmann::json regions = nlohmann::json::object();
  for (const RegionSessionAnalysis& r : session.regions) {
    const SeedTissueStats& seed = config.tissue(header.insole_size, r.region);
    regions[std::string(region_name(r.region))] = {
        {"steps_with_contact", r.steps_with_contact},
        {"steps_fitted", r.steps_fitted},
        {"steps_on_contact_ellipse", r.steps_on_ellipse},
        {"aspect_a_over_b", r.aspect},
        {"declared", nlohmann::json(r.declared)},
        {"session_fit", fit_json(r.session_fit)},
        {"pooling", pooling_json(r)},
        {"m_per_session", m_per_session_json(r, args.m_per_session)},
        {"across_steps",
         {{"A_mm", spread_json(r.A_mm)},
          {"B_mm", spread_json(r.B_mm)},
          {"C_mm", spread_json(r.C_mm)},
          {"d0_mm", spread_json(r.d0_mm)},
          {"kbar_n_per_mm3", spread_json(r.kbar_n_per_mm3)},
          {"n", spread_json(r.n)},
          {"cbar_ns_per_mm3", spread_json(r.cbar_ns_per_mm3)},
          {"m", spread_json(r.m)},
          {"nrmse_pct", spread_json(r.nrmse_pct)}}},
        {"steps_at_bound",
         {{"kbar_n_per_mm3", steps_at_bound(analyses, r.region, &RegionFit::kbar_n_per_mm3)},
          {"n", steps_at_bound(analyses, r.region, &RegionFit::n)},
          {"cbar_ns_per_mm3", steps_at_bound(analyses, r.region, &RegionFit::cbar_ns_per_mm3)},
          {"m", steps_at_bound(analyses, r.region, &RegionFit::m)}}},
        {"drift",
         {{"kbar", trend_json(r.kbar_trend)},
          {"cbar", trend_json(r.cbar_trend)},
          {"note",
           fmt::format("change per minute over the session, compounded, from a weighted "
                       "regression of each step's ln kbar and ln cbar on its heel strike, each "
                       "foot at its own level (null: "
                       "fewer than {} steps off the bounds, or spanning less than {:.0f} s); z is "
                       "the slope of the log over its standard error, and beyond about 3 a drift "
                       "(include/gaitmon/drift.hpp)",
                       kMinTrendSteps, kMinTrendSpan_s)}}},
        {"asymmetry",
         {{"kbar", asymmetry_json(r.kbar_asymmetry)},
          {"cbar", asymmetry_json(r.cbar_asymmetry)},
          {"note",
           fmt::format(
               "how much higher the right foot's value is than the left's, in per cent, "
               "from a weighted regression of each step's ln kbar and ln cbar on its foot "
               "and its heel strike (null: fewer than {} steps of either foot off the "
               "bounds). Its standard error is that of the steps' scatter and the pair of "
               "insoles' own SD (the config's table that settings.asymmetry_table names: "
               "[asymmetry], [asymmetry.m_per_session] at one m per session, "
               "[asymmetry.footprint_mean] and its m_per_session on the area footprint-mean) "
               "together; z is the log ratio "
               "over it, and beyond about 3 the feet differ (include/gaitmon/asymmetry.hpp)",
               kMinAsymmetryStepsPerFoot)}}},
        {"appendix_i",
         {{"mean", nlohmann::json(seed.mean)},
          {"sd", nlohmann::json(seed.sd)},
          {"nrmse_pct_mean", seed.nrmse_pct_mean},
          {"nrmse_pct_sd", seed.nrmse_pct_sd}}}};
  }
  j["regions"] = regions;
  j["extended_model"] = effects_json(extended);
  return json_file_text(j);
}

/// One summary line for the regions' kbar and cbar trends, or their differences between the feet:
/// those beyond kNamedZ standard errors with `value_se` of each, else why there are none. The toes
/// are left to session.json: on one to three active cells their estimates scatter with tails
/// beyond what the standard error says (README, "Left against right").
template <class Course, class ValueSe>
void print_named(const SessionAnalysis& session,
                 const std::optional<Course> RegionSessionAnalysis::*kbar,
                 const std::optional<Course> RegionSessionAnalysis::*cbar, ValueSe value_se,
                 const std::string& not_estimated, std::string_view none, std::string_view named) {
  std::vector<std::string> clear;
  bool any = false;
  for (const RegionSessionAnalysis& r : session.regions) {
    if (is_toe(r.region)) continue;
    for (const auto& [name, member] : {std::pair{"kbar", kbar}, {"cbar", cbar}}) {
      const std::optional<Course>& course = r.*member;
      any = any || course.has_value();
      if (course && std::abs(course->z()) >= kNamedZ) {
        const auto [value, se] = value_se(*course);
        clear.push_back(
            fmt::format("{} {} {:+.1f} +- {:.1f}", region_name(r.region), name, value, se));
      }
    }
  }
  if (!any) {
    fmt::print("{}\n", not_estimated);
  } else if (clear.empty()) {
    fmt::print("{} by {} standard errors or more (the toes' are in session.json only)\n", none,
               kNamedZ);
  } else {
    fmt::print("{}: {}\n", named, fmt::join(clear, "; "));
  }
}

// The pooled means with the standard errors that hold the chain's shared error: what a region's
// tissue was over the session, where the medians above are what one step gives.
void print_pooled(const SessionAnalysis& session, AreaSource area, bool m_per_session) {
  fmt::print(
      "pooled over the session, +- one standard error with the measurement chain's error "
      "({} of the config):\n{:<19}{:>18}{:>17}{:>21}{:>17}\n",
      chain_table_name("pooling", area, m_per_session), "region", "kbar N/mm3", "n", "cbar Ns/mm3",
      "m");
  for (const RegionSessionAnalysis& r : session.regions) {
    if (!r.pooled_mean) {
      fmt::print("{:<19}not pooled: {}\n", region_name(r.region), r.pooling.not_pooled);
      continue;
    }
    const MaterialParams p = material_params(*r.pooled_mean);
    fmt::print("{:<19}{:>18}{:>17}{:>21}{:>17}\n", region_name(r.region),
               fmt::format("{:.4f} +- {:.4f}", p.kbar_n_per_mm3.value, p.kbar_n_per_mm3.se),
               fmt::format("{:.3f} +- {:.3f}", p.n.value, p.n.se),
               fmt::format("{:.5f} +- {:.5f}", p.cbar_ns_per_mm3.value, p.cbar_ns_per_mm3.se),
               fmt::format("{:.3f} +- {:.3f}", p.m.value, p.m.se));
  }
}

void print_summary(const AnalyzeArgs& args, const SessionHeader& header,
                   const AnalysisSettings& settings, const std::vector<StepRow>& steps,
                   const std::vector<StepAnalysis>& analyses, const SessionAnalysis& session,
                   const CellReadingEvidence& cells,
                   const std::vector<std::filesystem::path>& written) {
  fmt::print(
      "{}: insole {}, {} steps, {} analysed (model {}, fit {}, smoothing {}, area {}{}{}{}{})\n",
      args.session.string(), insole_size_name(header.insole_size), steps.size(), analyses.size(),
      model_variant_name(settings.fit.model), fit_mode_name(settings.fit.mode),
      smoothing_name(settings.fit.smoothing), area_source_name(settings.area),
      args.area_auto() ? " (auto)" : "",
      settings.fit.end_rate == EndRate::TwoFrame ? "" : ", end rate second-order",
      settings.fit.free_scale ? ", free scale" : "", args.m_per_session ? ", m per session" : "");
  fmt::print("{:<19}{:>8}{:>10}{:>12}{:>10}{:>13}{:>10}{:>12}{:>12}\n", "region", "fitted",
             "contact", "kbar N/mm3", "n", "cbar Ns/mm3", "m", "NRMSE %", "session %");
  bool marked = false;
  for (const RegionSessionAnalysis& r : session.regions) {
    // A median the fits left at a bound of its range in most steps is where the optimiser
    // stopped, not what the data say; such a number must not read like the others.
    const auto median = [&](const Spread& spread, const Estimate RegionFit::*estimate,
                            int decimals) {
      const int at_bound = steps_at_bound(analyses, r.region, estimate);
      const bool mark = r.steps_fitted > 0 && 2 * at_bound >= r.steps_fitted;
      marked = marked || mark;
      return fmt::format("{:.{}f}{}", spread.median, decimals, mark ? "*" : " ");
    };
    fmt::print(
        "{:<19}{:>8}{:>10}{:>13}{:>11}{:>14}{:>11}{:>11.1f}{:>12}\n", region_name(r.region),
        r.steps_fitted, r.steps_with_contact,
        median(r.kbar_n_per_mm3, &RegionFit::kbar_n_per_mm3, 4), median(r.n, &RegionFit::n, 3),
        median(r.cbar_ns_per_mm3, &RegionFit::cbar_ns_per_mm3, 5), median(r.m, &RegionFit::m, 3),
        r.nrmse_pct.median,
        r.session_fit.status == FitStatus::Ok ? fmt::format("{:.1f}", r.session_fit.nrmse_pct)
                                              : std::string(fit_status_name(r.session_fit.status)));
  }
  fmt::print("medians across steps; total-force NRMSE median {:.1f} % (IQR {:.1f} %)\n",
             session.nrmse_total_pct.median, session.nrmse_total_pct.iqr());
  if (marked) {
    fmt::print(
        "* at a bound of its fit range in at least half of the region's steps: the data do not "
        "determine it there (regions.csv: at_bound)\n");
  }
  if (args.m_per_session) {
    std::vector<std::string> shared;
    for (const RegionSessionAnalysis& r : session.regions) {
      shared.push_back(
          r.m_per_session
              ? fmt::format("{} {}{}", region_name(r.region),
                            estimate_text(r.m_per_session->m, r.m_per_session->se, " +- "),
                            r.m_per_session->at_bound ? " (at a bound)" : "")
              : fmt::format("{} none", region_name(r.region)));
    }
    fmt::print("m per session, every step fitted at it: {}\n", fmt::join(shared, ", "));
  }
  print_pooled(session, settings.area, args.m_per_session);
  print_named(
      session, &RegionSessionAnalysis::kbar_trend, &RegionSessionAnalysis::cbar_trend,
      [](const LogTrend& t) {
        return std::pair{t.pct_per_min, t.se_pct_per_min};
      },
      fmt::format("drift: not estimated; no region but the toes has {} steps spanning {:.0f} s "
                  "or more with kbar or cbar off its bounds",
                  kMinTrendSteps, kMinTrendSpan_s),
      "no region's kbar or cbar drifts over the session",
      "drift over the session, % per minute (session.json: drift)");
  print_named(
      session, &RegionSessionAnalysis::kbar_asymmetry, &RegionSessionAnalysis::cbar_asymmetry,
      [](const FootAsymmetry& a) {
        return std::pair{a.pct, a.se_pct};
      },
      fmt::format("left against right: not compared; no region but the toes has {} steps of "
                  "each foot with kbar or cbar off its bounds",
                  kMinAsymmetryStepsPerFoot),
      "no region's kbar or cbar differs between the feet",
      "right foot against left, % (session.json: asymmetry)");
  std::vector<std::string> on_ellipse;
  for (const RegionSessionAnalysis& r : session.regions) {
    if (r.steps_on_ellipse > 0) {
      on_ellipse.push_back(fmt::format("{} ({} of {} steps)", region_name(r.region),
                                       r.steps_on_ellipse, r.steps_with_contact));
    }
  }
  if (!on_ellipse.empty()) {
    fmt::print(
        "note: fitted on the contact ellipse: {}; their active cells determine no footprint, so "
        "the area moves in whole cells and does not determine n, cbar and m there\n",
        fmt::join(on_ellipse, ", "));
  }
  fmt::print("cells: {}\n", cell_reading_sentence(cells));
  if (const std::string advice = cell_reading_advice(cells, settings.area); !advice.empty()) {
    fmt::print("note: {}\n", advice);
  }
  if (settings.fit.mode == FitMode::Identifiable) {
    fmt::print("note: C and d0 are declared (Appendix I means), kbar and cbar derived from them\n");
  } else {
    std::set<std::string> undetermined;
    for (const StepAnalysis& s : analyses) {
      for (const RegionAnalysis& r : s.regions) {
        undetermined.insert(r.fit.undetermined.begin(), r.fit.undetermined.end());
      }
    }
    if (!undetermined.empty()) {
      spdlog::warn(
          "--fit seed8 frees parameters the data cannot determine: {}; their values are "
          "wherever the optimiser stopped (model-notes section 2)",
          fmt::join(undetermined, ", "));
    }
  }
  for (const auto& path : written) fmt::print("wrote {}\n", path.string());
}

void run_analyze(const GlobalOptions& global, AnalyzeArgs args) {
  const Config config = load_global_config(global);
  if (!args.m_per_session_given) args.m_per_session = config.model.m_per_session;
  // --fit seed8 takes the seed's ellipse unless --area says otherwise (settings_from).
  if (args.area.empty() && args.fit != "seed8") args.area = config.model.area;
  AnalysisSettings settings = settings_from(args);
  const std::vector<std::string>& names = args.effects_given ? args.effects : config.model.effects;
  if (settings.fit.mode == FitMode::Seed8 || settings.fit.free_scale) {
    for (const std::string& name : names) {
      if (effect_inside_tissue_fit(name)) {
        throw std::invalid_argument(fmt::format(
            "--effects {}: each step's tissue is fitted with it inside, which needs the default "
            "fit; drop --fit seed8 and --free-scale",
            name));
      }
    }
  }
  if (args.m_per_session && !names.empty()) {
    throw std::invalid_argument(
        fmt::format("--m-per-session with effects in the model ({}) is not supported: each step's "
                    "tissue is then fitted again with them inside; give --effects none or "
                    "--m-per-session=false",
                    fmt::join(names, ", ")));
  }
  check_output_dir(args.out_dir, "--out");
  OutputSet outputs(args.out_dir, {"steps.csv", "regions.csv", "session.json", "report.html"},
                    std::span(&args.session, 1));
  const SessionHeader header = SessionReader(args.session).header();
  const InsoleLayout layout(config.insole(header.insole_size), config.sensor);

  std::vector<StepRow> steps;
  std::vector<Step> ok_steps;
  std::vector<StepAnalysis> analyses;
  std::optional<ExtendedModelFit> extended;
  SharedExponents m_per_session;
  SessionAnalysis session;
  CellReadingEvidence cells;
  // The steps' median NRMSE of the total force before an effect was undone in the readings.
  double total_nrmse_as_read_pct = 0.0;
  {
    ProgressBar progress("analyze");
    const auto share = [&](double from, double to) {
      return [&progress, from, to](double fraction) {
        progress.update(from + (to - from) * fraction);
      };
    };
    auto on_step = [&](Step&& step) {
      steps.push_back({step.foot, step.index, step.t_heel_strike_s, step.t_toe_off_s,
                       step.peak_force_n, step.status, std::nullopt});
      if (step.status == StepStatus::Ok) ok_steps.push_back(std::move(step));
    };
    const auto segment = [&](const std::function<void(double)>& on_progress,
                             const std::function<void(Frame&)>& correct_frame) {
      steps.clear();
      ok_steps.clear();
      const SegmentedSessionInfo info =
          segment_session(args.session, config, on_step, on_progress, correct_frame);
      // Outputs of nothing would read as a perfect fit: medians of 0 and an NRMSE of 0 %.
      if (ok_steps.empty()) {
        throw InputError(
            args.session.string(), 0,
            fmt::format("no complete step to fit in {} and {} frames of the left and right foot "
                        "({} steps found, all cut by the recording's ends or a gap, or longer "
                        "than 60 s{})",
                        info.frames_per_foot[0], info.frames_per_foot[1], steps.size(),
                        correct_frame ? ", with the sensor creep undone" : ""));
      }
    };
    segment(share(0.0, 0.1), {});
    const auto cells_start = std::chrono::steady_clock::now();
    cells = cell_reading_evidence(ok_steps, layout);
    spdlog::debug(
        "weighed how the cells read in {:.2f} s",
        std::chrono::duration<double>(std::chrono::steady_clock::now() - cells_start).count());
    if (args.area_auto()) settings.area = footprint_for(cells);
    // The shares of the time measured on a 60-s session: one effect's fit takes about seven
    // times as long as all the steps' fits, and the session-level fits a twentieth of those.
    // A creep the zeros show is undone and the steps measured and fitted again (a third of the
    // time).
    const bool may_undo_creep = std::ranges::find(names, "sensor_creep") != names.end();
    const double steps_end = names.empty() ? 0.95 : 0.25;
    const double effects_end = may_undo_creep ? 0.6 : 0.95;
    const auto start = std::chrono::steady_clock::now();
    analyses = analyse_steps(ok_steps, layout, config, settings, share(0.1, steps_end));
    if (args.m_per_session)
      m_per_session = fit_damping_exponent_per_session(analyses, config, settings);
    spdlog::debug("analysed {} steps in {:.2f} s", analyses.size(),
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    if (!names.empty()) {
      const auto effects_start = std::chrono::steady_clock::now();
      const DiscrepancyInput input =
          extended_model_input(ok_steps, analyses, layout, config, names, settings.area);
      extended = fit_extended_model(input, names, {}, {}, share(steps_end, effects_end));
      if (auto creep = creep_to_undo(*extended)) {
        spdlog::debug(
            "fitted the extended model to the readings as read in {:.2f} s",
            std::chrono::duration<double>(std::chrono::steady_clock::now() - effects_start)
                .count());
        std::vector<double> totals;
        for (const StepAnalysis& a : analyses) totals.push_back(a.nrmse_total_pct);
        total_nrmse_as_read_pct = spread_of(std::move(totals)).median;
        segment(share(effects_end, 0.65), [&](Frame& frame) { creep->undo(frame); });
        analyses = analyse_steps(ok_steps, layout, config, settings, share(0.65, 0.72));
        const DiscrepancyInput undone =
            extended_model_input(ok_steps, analyses, layout, config, names, settings.area);
        // The effects on top of the creep are those of the readings without it.
        std::vector<std::string> others = names;
        std::erase(others, "sensor_creep");
        extended = with_creep_undone(*extended,
                                     fit_extended_model(undone, others, {}, {}, share(0.72, 0.95)));
        analyses = fit_steps_with_effects(undone, extended->effects, config, settings);
      } else {
        analyses = fit_steps_with_effects(input, extended->effects, config, settings);
      }
      spdlog::debug(
          "fitted the extended model in {:.2f} s",
          std::chrono::duration<double>(std::chrono::steady_clock::now() - effects_start).count());
    }
    const auto key = [](const StepAnalysis& a) { return std::pair(a.foot, a.step); };
    std::sort(analyses.begin(), analyses.end(),
              [&](const StepAnalysis& a, const StepAnalysis& b) { return key(a) < key(b); });
    for (StepRow& row : steps) {
      const auto it = std::lower_bound(
          analyses.begin(), analyses.end(), std::pair(row.foot, row.index),
          [&](const StepAnalysis& a, const std::pair<Foot, int>& k) { return key(a) < k; });
      if (it != analyses.end() && key(*it) == std::pair(row.foot, row.index)) {
        row.nrmse_total_pct = it->nrmse_total_pct;
      }
    }
    std::sort(steps.begin(), steps.end(), [](const StepRow& a, const StepRow& b) {
      return std::pair(a.foot, a.index) < std::pair(b.foot, b.index);
    });
    const auto session_start = std::chrono::steady_clock::now();
    session = analyse_session(analyses, config, header.insole_size, settings);
    for (std::size_t i = 0; i < kRegionCount; ++i)
      session.regions[i].m_per_session = m_per_session[i];
    spdlog::debug(
        "session-level fits in {:.2f} s",
        std::chrono::duration<double>(std::chrono::steady_clock::now() - session_start).count());
    progress.update(1.0);
  }

  std::filesystem::create_directories(args.out_dir);
  outputs.add("steps.csv", steps_csv(steps));
  outputs.add("regions.csv", regions_csv(analyses, session, config, settings.area));
  outputs.add("session.json", session_json(args, header, config, settings, steps, analyses, session,
                                           extended, cells));
  if (args.report) {
    ReportInput input;
    input.session_name = args.session.filename().string();
    input.size = header.insole_size;
    input.sample_rate_hz = header.sample_rate_hz;
    input.config = &config;
    input.settings = &settings;
    input.area_auto = args.area_auto();
    input.steps = steps;
    input.analyses = analyses;
    input.session = &session;
    input.extended = extended ? &*extended : nullptr;
    input.cells = &cells;
    outputs.add("report.html", render_report_html(input));
  }
  const std::vector<std::filesystem::path> written = outputs.commit();
  print_summary(args, header, settings, steps, analyses, session, cells, written);
  if (crosstalk_left_out(cells, names)) {
    fmt::print(
        "note: the cells' readings fit their caps best with a crosstalk of {:.3f} undone: "
        "neighbouring cells read part of each other's load, which the fits take up as tissue; "
        "--effects crosstalk fits it (gaitmon discrepancy weighs it against the other effects)\n",
        cells.coupling());
  }
  if (extended) {
    for (const EffectEstimate& e : extended->effects) {
      std::string params;
      for (const ParamEstimate& p : e.params) {
        params += fmt::format(" {} = {};", p.name, param_text(p, " +- "));
      }
      fmt::print("effect {}:{}\n", e.name, params);
    }
    fmt::print(
        "extended model: pooled NRMSE {:.2f} % -> {:.2f} % (held-out {:.2f} % -> {:.2f} %)\n",
        extended->baseline_nrmse_pct, extended->extended_nrmse_pct,
        extended->baseline_heldout_nrmse_pct, extended->extended_heldout_nrmse_pct);
    // Without this the table above could be read as the tissue under every effect.
    const auto [inside, undone, on_top] = place_effects(*extended);
    if (!inside.empty()) {
      fmt::print(
          "note: each step's tissue parameters above and in regions.csv are fitted with {} "
          "inside its model\n",
          fmt::join(inside, " and "));
    }
    if (const auto creep = creep_to_undo(*extended)) {
      std::vector<std::string> others;
      for (const EffectEstimate& e : extended->effects) {
        if (e.name != "sensor_creep") others.push_back(e.name);
      }
      fmt::print(
          "note: each step above and in regions.csv is measured and fitted from readings with "
          "the sensor creep undone (gain {:.4g}, tau {:.4g} s){}, as are the extended model's "
          "NRMSEs after the arrows; the total force's median NRMSE over the steps as read was "
          "{:.1f} %\n",
          creep->gain(), creep->tau_s(),
          others.empty()
              ? ""
              : fmt::format(", and {} fitted on those readings", fmt::join(others, " and ")),
          total_nrmse_as_read_pct);
      fmt::print("{}\n", sensor_creep_advice(config, creep->gain(), creep->tau_s()));
    }
    for (const EffectEstimate& e : extended->effects) {
      if (e.name == "sensor_creep" && !effect_undone_in_readings(*extended, e)) {
        fmt::print(
            "note: sensor_creep is not undone in the readings: the zero channel does not show it "
            "(its held-out NRMSE falls by less than {:.0f} %) or the data do not determine it "
            "(its gain or tau has no standard error)\n",
            DiscrepancySettings{}.min_zero_shrink_pct);
      }
    }
    if (!on_top.empty()) {
      fmt::print(
          "note: {} {} fitted on top of the baseline's tissue parameters, not inside each "
          "step's fit\n",
          fmt::join(on_top, " and "), on_top.size() == 1 ? "is" : "are");
    }
    if (extended->zero_changes > 0) {
      fmt::print(
          "zero channel ({} changes of the step-regions' zeros): held-out NRMSE {:.3f} % -> "
          "{:.3f} %\n",
          extended->zero_changes, extended->zero_baseline_heldout_nrmse_pct,
          extended->zero_extended_heldout_nrmse_pct);
    }
  }
}

// `none` overrides the config's [model] effects.
std::vector<std::string> effect_names_or_none() {
  std::vector<std::string> names{"none"};
  for (std::string_view n : discrepancy_effect_names()) names.emplace_back(n);
  return names;
}

}  // namespace

void add_analyze_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<AnalyzeArgs>();
  CLI::App* sub = app.add_subcommand(
      "analyze",
      "Fit the ellipsoid tissue model per step and region (seed 5.2) and once per region over "
      "the session: writes DIR/steps.csv, DIR/regions.csv, DIR/session.json and, with "
      "--report, DIR/report.html");
  sub->add_option("session", args->session, "Session CSV v1")
      ->required()
      ->check(session_file_read_twice());
  sub->add_option("--out,-o", args->out_dir, "Output folder")->required();
  sub->add_flag("--report", args->report, "Also write a self-contained HTML report");
  sub->add_option("--model", args->model,
                  "Damping term: correct (default: eq 15's rate, the integral's plus sign), "
                  "seed_eq25 (the seed's minus) or material_rate (the rate of a fixed tissue "
                  "column, d-dot)")
      ->check(CLI::IsMember({"correct", "seed_eq25", "material_rate"}));
  sub->add_option("--fit", args->fit,
                  "identifiable (default: kbar, n, cbar, m free; C, d0 declared) or seed8 (all "
                  "eight free, as the seed)")
      ->check(CLI::IsMember({"identifiable", "seed8"}));
  sub->add_option("--smoothing", args->smoothing,
                  "none (default: the raw series) or seed (the seed's moving average and "
                  "polynomials; the default with --fit seed8)")
      ->check(CLI::IsMember({"none", "seed"}));
  sub->add_option("--area", args->area,
                  "Contact area given to the fit (default: [model] area of the config, auto as "
                  "shipped): auto (footprint-mean where the session's readings fit cells that "
                  "average the pressure better, else footprint; see the summary's cells line), "
                  "footprint (a paraboloid fitted to "
                  "the active cells' loads where they determine it, else the contact ellipse), "
                  "footprint-mean (the same for cells that read the mean pressure over their "
                  "area, as simulate --rasterisation coverage does, where the footprint "
                  "over-reads and n comes out about twice the truth; slower) or ellipse (the "
                  "seed's contact ellipse of the active cells; the default with --fit seed8)")
      ->check(CLI::IsMember({"footprint", "footprint-mean", "ellipse", "auto"}));
  sub->add_option("--end-rate", args->end_rate,
                  "Area rate at each contact's first and last frame: two-frame (default: the "
                  "difference to its neighbour, best for single steps) or second-order (three "
                  "frames, less biased; better pooled values on sessions of a minute or more)")
      ->check(CLI::IsMember({"two-frame", "second-order"}));
  sub->add_flag("--free-scale", args->free_scale,
                "Also fit P = pi A B (keeping A/B); identifiable mode only. The steps are then "
                "not pooled (pooling needs P declared): the *_pooled columns stay empty");
  sub->add_flag("--m-per-session", args->m_per_session,
                "Fit one damping exponent m per region over the whole session, each step's kbar, n "
                "and cbar at it: one step mostly leaves m at a bound of its range (README, \"What "
                "one step can determine\"). Default fit only, without effects; regions.csv's m "
                "and se_m are then the session's, and session.json's m_per_session says so. "
                "Default: [model] m_per_session of the config; --m-per-session=false turns it "
                "off");
  sub->add_option("--effects", args->effects,
                  fmt::format("Effects added to the model, comma-separated ({}), or none; "
                              "default: [model] effects of the config",
                              fmt::join(discrepancy_effect_names(), ", ")))
      ->delimiter(',')
      ->check(CLI::Validator(
          [](const std::string& name) {
            return name.empty() ? std::string("an empty effect name (none for no effect)")
                                : std::string();
          },
          ""))
      ->check(CLI::IsMember(effect_names_or_none()));
  sub->callback([&global, args, sub] {
    args->effects_given = sub->count("--effects") > 0;
    args->m_per_session_given = sub->count("--m-per-session") > 0;
    if (std::find(args->effects.begin(), args->effects.end(), "none") != args->effects.end()) {
      if (args->effects.size() > 1) {
        throw CLI::ValidationError("--effects", "none cannot be combined with an effect");
      }
      args->effects.clear();
    }
    for (auto it = args->effects.begin(); it != args->effects.end(); ++it) {
      if (std::find(std::next(it), args->effects.end(), *it) != args->effects.end()) {
        throw CLI::ValidationError("--effects", "'" + *it + "' is given twice");
      }
    }
    run_analyze(global, *args);
  });
}

}  // namespace gaitmon::cli
