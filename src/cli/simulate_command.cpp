// `gaitmon simulate`: a session CSV v1 and its ground truth from the forward model.
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "commands.hpp"
#include "gaitmon/session.hpp"
#include "gaitmon/simulator.hpp"
#include "output_file.hpp"

namespace gaitmon::cli {
namespace {

struct SimulateArgs {
  SimulationOptions options;
  std::string size = "37-38";
  std::string model = "correct";
  std::string rasterisation = "centre";
  std::vector<std::string> params;
  std::string effect_params;
  bool effect_params_given = false;
  std::filesystem::path out;
  std::filesystem::path truth;
};

/// Applies one `REGION.FIELD=VALUE` override on top of the region's default parameters.
void apply_param(const std::string& text, const Config& config, SimulationOptions& options) {
  const auto dot = text.find('.');
  const auto eq = text.find('=');
  if (dot == std::string::npos || eq == std::string::npos || eq < dot) {
    throw CLI::ValidationError("--param", "'" + text + "': expected REGION.FIELD=VALUE");
  }
  const auto region = parse_region(text.substr(0, dot));
  if (!region) {
    std::string known;
    for (Region r : kRegions) known += (known.empty() ? "" : ", ") + std::string(region_name(r));
    throw CLI::ValidationError("--param", "'" + text + "': unknown region (" + known + ")");
  }
  const std::string field = text.substr(dot + 1, eq - dot - 1);
  double value = 0.0;
  try {
    std::size_t used = 0;
    value = std::stod(text.substr(eq + 1), &used);
    if (used != text.size() - eq - 1) throw std::invalid_argument("trailing text");
  } catch (const std::exception&) {
    throw CLI::ValidationError("--param", "'" + text + "': the value is not a number");
  }
  if (!(value > 0.0)) throw CLI::ValidationError("--param", "'" + text + "': must be > 0");
  if (!std::isfinite(value)) {
    throw CLI::ValidationError("--param", "'" + text + "': must be finite");
  }
  auto& slot = options.region_params[index_of(*region)];
  if (!slot) slot = config.tissue(options.size, *region).mean;
  const std::map<std::string, double EllipsoidParams::*> fields{
      {"A_mm", &EllipsoidParams::A_mm},
      {"B_mm", &EllipsoidParams::B_mm},
      {"C_mm", &EllipsoidParams::C_mm},
      {"d0_mm", &EllipsoidParams::d0_mm},
      {"kbar_n_per_mm3", &EllipsoidParams::kbar_n_per_mm3},
      {"n", &EllipsoidParams::n},
      {"cbar_ns_per_mm3", &EllipsoidParams::cbar_ns_per_mm3},
      {"m", &EllipsoidParams::m}};
  const auto it = fields.find(field);
  if (it == fields.end()) {
    throw CLI::ValidationError("--param", "'" + text + "': unknown field '" + field +
                                              "' (A_mm, B_mm, C_mm, d0_mm, kbar_n_per_mm3, n, "
                                              "cbar_ns_per_mm3, m)");
  }
  (*slot).*(it->second) = value;
}

/// Parses --effect-params: a JSON object of numbers for the one --effect given, or an object of
/// such objects keyed by effect name when there are several. Names and ranges are checked by
/// the simulator (resolve_effect_params).
void apply_effect_params(const std::string& text, SimulationOptions& options) {
  const auto bad = [](const std::string& why) {
    return CLI::ValidationError("--effect-params", why);
  };
  if (text.empty()) {
    throw bad("is empty: give a JSON object, or leave the option out for the defaults");
  }
  // nlohmann::json keeps the last of two equal keys without a word, so that the value meant
  // may be the one dropped. The keys of each object open at the moment, outermost first.
  std::vector<std::set<std::string>> open_objects;
  const auto refuse_duplicates = [&](int, nlohmann::json::parse_event_t event,
                                     nlohmann::json& parsed) {
    using Event = nlohmann::json::parse_event_t;
    if (event == Event::object_start) open_objects.emplace_back();
    if (event == Event::object_end) open_objects.pop_back();
    if (event == Event::key && !open_objects.back().insert(parsed.get<std::string>()).second) {
      throw bad("key '" + parsed.get<std::string>() + "' is given twice");
    }
    return true;
  };
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text, refuse_duplicates);
  } catch (const nlohmann::json::exception& e) {
    // A syntax error, or a number beyond a double's range (1e999).
    throw bad("not valid JSON (" + std::string(e.what()) + ")");
  }
  if (!j.is_object()) throw bad("expected a JSON object");
  const auto numbers = [&bad](const nlohmann::json& obj, const std::string& effect) {
    EffectParams params;
    if (!obj.is_object()) throw bad("the parameters of '" + effect + "' must be a JSON object");
    for (const auto& [key, value] : obj.items()) {
      if (!value.is_number()) throw bad("'" + key + "' of '" + effect + "' must be a number");
      params[key] = value.get<double>();
    }
    try {
      resolve_effect_params(effect, params);
    } catch (const std::invalid_argument& e) {
      throw bad(e.what());
    }
    return params;
  };
  const bool nested = !j.empty() && j.begin()->is_object();
  if (!nested) {
    if (options.effects.size() != 1) {
      throw bad(
          "with a flat object give exactly one --effect; with several, key the parameters by "
          "effect name");
    }
    options.effect_params[options.effects.front()] = numbers(j, options.effects.front());
    return;
  }
  for (const auto& [effect, obj] : j.items()) {
    if (std::find(options.effects.begin(), options.effects.end(), effect) ==
        options.effects.end()) {
      throw bad("'" + effect + "' is not one of the --effect");
    }
    options.effect_params[effect] = numbers(obj, effect);
  }
}

void run_simulate(const GlobalOptions& global, SimulateArgs& args) {
  const Config config = load_global_config(global);
  SimulationOptions& options = args.options;
  options.size = *parse_insole_size(args.size);
  options.model = *parse_model_variant(args.model);
  options.rasterisation = *parse_rasterisation(args.rasterisation);
  for (const auto& p : args.params) apply_param(p, config, options);
  if (const std::string why = header_value_problem(options.subject); !why.empty()) {
    // Not quoted: a line break would split the message.
    throw CLI::ValidationError("--subject", why + ", which the session header cannot hold");
  }
  for (auto it = options.effects.begin(); it != options.effects.end(); ++it) {
    try {
      simulation_effect_params(*it);  // known names only
    } catch (const std::invalid_argument& e) {
      throw CLI::ValidationError("--effect", e.what());
    }
    // Applied twice, an effect would double silently; analyze refuses the same.
    if (std::find(options.effects.begin(), it, *it) != it) {
      throw CLI::ValidationError("--effect", "'" + *it + "' is given twice");
    }
  }
  if (args.effect_params_given) apply_effect_params(args.effect_params, options);
  if (options.min_bias_bits > options.max_bias_bits) {
    throw CLI::ValidationError("--min-bias",
                               fmt::format("{} is more than --max-bias ({})", options.min_bias_bits,
                                           options.max_bias_bits));
  }
  if (args.truth.empty()) {
    args.truth = args.out;
    args.truth.replace_extension(".truth.json");
  }
  check_output_path(args.out, "--out");
  check_output_path(args.truth, "--truth");
  if (std::filesystem::absolute(args.truth).lexically_normal() ==
      std::filesystem::absolute(args.out).lexically_normal()) {
    throw CLI::ValidationError("--truth", "is the same file as --out");
  }
  if (args.out.has_parent_path()) std::filesystem::create_directories(args.out.parent_path());
  OutputFile csv(args.out);
  OutputFile truth_json(args.truth);
  const SimulationTruth truth =
      simulate_session(config, options, csv.hand_over(), truth_json.hand_over());
  OutputFile* const outputs[] = {&csv, &truth_json};
  OutputFile::commit_all(outputs);

  int partial = 0;
  for (const auto& step : truth.steps) partial += step.partial ? 1 : 0;
  fmt::print("simulated {:.1f} s, insole {}, {} frames per foot at {} Hz, seed {}, model {}\n",
             options.duration_s, insole_size_name(options.size), truth.frames_per_foot,
             truth.sample_rate_hz, options.seed, model_variant_name(options.model));
  if (truth.options.effects != options.effects) {
    fmt::print("the cells creep as the config's [sensor_creep] says: gain {:.4g}, tau {:.4g} s\n",
               config.sensor_creep.gain, config.sensor_creep.tau_s);
  }
  fmt::print("{} steps ({} cut by the recording's ends); {} readings clipped at 255\n",
             truth.steps.size(), partial, truth.clipped_high_samples);
  fmt::print("wrote {} and {}\n", args.out.string(), args.truth.string());
}

}  // namespace

void add_simulate_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<SimulateArgs>();
  CLI::App* sub = app.add_subcommand(
      "simulate",
      "Simulate a two-foot walking session from the ellipsoid model: writes a session CSV v1 "
      "and a ground-truth JSON, at the config's sample_rate_hz");
  sub->add_option("--out,-o", args->out, "Session CSV to write")->required();
  sub->add_option("--truth", args->truth, "Ground-truth JSON (default: OUT with .truth.json)");
  sub->add_option("--size", args->size, "Insole size")
      ->check(CLI::IsMember(insole_size_names()))
      ->capture_default_str();
  sub->add_option("--duration", args->options.duration_s, "Length of the recording, s")
      ->check(number_in(0.1, 86400.0))
      ->capture_default_str();
  sub->add_option("--seed", args->options.seed, "Random seed (same seed, same file)")
      ->check(whole_number_in(0, std::numeric_limits<std::uint64_t>::max()))
      ->capture_default_str();
  sub->add_option("--body-mass", args->options.body_mass_kg, "Body mass, kg")
      ->check(number_in(1.0, 300.0))
      ->capture_default_str();
  sub->add_option("--stride", args->options.timing.stride_s,
                  "Stride time (heel strike to the same foot's next), s")
      ->check(number_in(0.5, 3.0, true))
      ->capture_default_str();
  sub->add_option("--stance-fraction", args->options.timing.stance_fraction,
                  "Loaded time / stride time (the 40 N events cover about 85 % of it)")
      ->check(number_in(0.3, 0.8))
      ->capture_default_str();
  sub->add_option("--jitter", args->options.timing.jitter_pct,
                  "Step-to-step SD of stride and stance time, % of nominal")
      ->check(number_in(0.0, 10.0))
      ->capture_default_str();
  sub->add_option("--model", args->model,
                  "Damping term: correct (the integral of eq 22: eq 15's rate, plus sign), "
                  "seed_eq25 (the seed's minus) or material_rate (the rate of a fixed tissue "
                  "column, d-dot)")
      ->check(CLI::IsMember({"correct", "seed_eq25", "material_rate"}))
      ->capture_default_str();
  sub->add_option("--rasterisation", args->rasterisation,
                  "centre: a cell reads when its centre is in contact; coverage: cells average "
                  "over partial contact")
      ->check(CLI::IsMember({"centre", "coverage"}))
      ->capture_default_str();
  sub->add_option("--noise", args->options.noise_sd_bits, "Sensor noise SD, bits")
      ->check(number_in(0.0, 50.0))
      ->capture_default_str();
  sub->add_option("--tissue-step-sd", args->options.tissue_step_sd_pct,
                  "Step-to-step SD of kbar and cbar (log-normal, % of the value); 0 keeps every "
                  "step at the region's parameters")
      ->check(number_in(0.0, 100.0))
      ->capture_default_str();
  sub->add_option("--tissue-drift", args->options.tissue_drift_pct_per_min,
                  "Steady change of kbar and cbar over the session, % per minute (compounded); "
                  "0 keeps the tissue")
      ->check(number_in(-20.0, 20.0))
      ->capture_default_str();
  sub->add_option("--tissue-asymmetry", args->options.tissue_asymmetry_pct,
                  "How much higher the right foot's kbar and cbar are than the left's, %; 0 "
                  "keeps the feet alike")
      ->check(number_in(-50.0, 50.0))
      ->capture_default_str();
  sub->add_option("--placement-sd", args->options.placement_sd_mm,
                  "Step-to-step SD of where the foot lands on the insole, mm along each axis; 0 "
                  "puts every footprint on its region's centre")
      ->check(number_in(0.0, 10.0))
      ->capture_default_str();
  sub->add_option(
         "--min-bias", args->options.min_bias_bits,
         "Per-sensor dc bias, uniform integer MIN..MAX bits: the least (at most --max-bias; "
         "over twice --noise, no cell's swing reading is clipped at 0)")
      ->check(CLI::Range(0, 50))
      ->capture_default_str();
  sub->add_option("--max-bias", args->options.max_bias_bits,
                  "Per-sensor dc bias, uniform integer MIN..MAX bits: the most")
      ->check(CLI::Range(0, 50))
      ->capture_default_str();
  sub->add_option("--param", args->params,
                  "Override one tissue parameter, REGION.FIELD=VALUE (e.g. "
                  "heel.kbar_n_per_mm3=0.15); the rest are the seed's Appendix I means");
  sub->add_option("--effect", args->options.effects,
                  fmt::format("Physical effect to apply on top of the model, repeatable: {} "
                              "(none is the default)",
                              fmt::join(simulation_effect_names(), ", ")));
  sub->add_option("--effect-params", args->effect_params,
                  R"(Effect parameters as JSON, e.g. '{"strength":0.3,"tau_s":0.1}' for one )"
                  R"(--effect, or '{"NAME":{...},...}' for several (defaults otherwise; the )"
                  R"(README's table of effects lists each one's parameters, defaults and ranges))");
  sub->add_option("--subject", args->options.subject, "Subject label in the session metadata")
      ->capture_default_str();
  sub->callback([&global, args, sub] {
    args->effect_params_given = sub->count("--effect-params") > 0;
    run_simulate(global, *args);
  });
}

}  // namespace gaitmon::cli
