// `gaitmon calibrate`: the chain's SDs of [pooling] and [asymmetry] measured on simulated sessions,
// as tables on stdout and, with --out, as JSON and as TOML to paste into the config.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "commands.hpp"
#include "gaitmon/calibration.hpp"
#include "gaitmon/json.hpp"
#include "output_file.hpp"
#include "progress.hpp"

namespace gaitmon::cli {
namespace {

// The signal (SIGINT or SIGTERM) that asked the sessions to stop, 0 if none: the default action
// would leave the scratch folder's sessions behind. A second one takes the default action at once.
volatile std::sig_atomic_t g_stop_signal = 0;

extern "C" void stop_calibrating(int signal) {
  if (g_stop_signal != 0) {
    std::signal(signal, SIG_DFL);
    std::raise(signal);
    return;
  }
  g_stop_signal = signal;
}

// SIGINT and SIGTERM stop the sessions at the next one the calling thread finishes while it lives.
class StopSignals {
 public:
  StopSignals() {
    struct sigaction action {};
    action.sa_handler = stop_calibrating;
    sigaction(SIGINT, &action, &previous_int_);
    sigaction(SIGTERM, &action, &previous_term_);
  }
  ~StopSignals() {
    sigaction(SIGINT, &previous_int_, nullptr);
    sigaction(SIGTERM, &previous_term_, nullptr);
  }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

 private:
  struct sigaction previous_int_ {};
  struct sigaction previous_term_ {};
};

struct Stopped {};

struct CalibrateArgs {
  CalibrationDesign design;
  std::vector<std::string> sizes;
  std::string seeds = "1-20";
  std::string body_mass = "50-90";
  std::filesystem::path out_dir;
};

// One table of the config: its key, the parameter's index in the samples, and its unit.
struct TableKey {
  const char* key;
  const char* label;
  std::size_t parameter;
  bool percent;  ///< 100 ln (kbar, cbar), else as it is (n, m)
};

// The three kinds of table: the chain's shared SD and each step's own in [pooling], the pair's in
// [asymmetry].
enum class Table { Chain, Step, Pair };

constexpr TableKey kChainKeys[] = {{"kbar_chain_sd_pct", "ln kbar %", 0, true},
                                   {"n_chain_sd", "n", 1, false},
                                   {"cbar_chain_sd_pct", "ln cbar %", 2, true},
                                   {"m_chain_sd", "m", 3, false}};
constexpr TableKey kStepKeys[] = {{"kbar_step_sd_pct", "ln kbar %", 0, true},
                                  {"n_step_sd", "n", 1, false},
                                  {"cbar_step_sd_pct", "ln cbar %", 2, true},
                                  {"m_step_sd", "m", 3, false}};
constexpr TableKey kPairKeys[] = {{"kbar_pair_sd_pct", "ln kbar %", 0, true},
                                  {"cbar_pair_sd_pct", "ln cbar %", 1, true}};

// "A-B" or "A" as two numbers; `parse` turns one part into a number or throws.
template <typename T, typename Parse>
std::pair<T, T> parse_range(const std::string& text, const std::string& option, Parse parse) {
  const auto dash = text.find('-', 1);
  try {
    if (dash == std::string::npos) {
      const T one = parse(text);
      return {one, one};
    }
    return {parse(text.substr(0, dash)), parse(text.substr(dash + 1))};
  } catch (const std::exception&) {
    throw CLI::ValidationError(option, "'" + text + "': expected a number or FIRST-LAST");
  }
}

std::uint64_t whole(const std::string& text) {
  std::uint64_t value = 0;
  const char* end = text.data() + text.size();
  const auto [stop, error] = std::from_chars(text.data(), end, value);
  if (text.empty() || error != std::errc() || stop != end) throw std::invalid_argument(text);
  return value;
}

double real(const std::string& text) {
  std::size_t used = 0;
  const double value = std::stod(text, &used);
  if (used != text.size() || !std::isfinite(value)) throw std::invalid_argument(text);
  return value;
}

double config_value(const Config& config, bool shared_m, Table table, std::size_t parameter,
                    std::size_t region) {
  if (table == Table::Pair) {
    const PairSds& sds = shared_m ? config.asymmetry.m_per_session : config.asymmetry.per_step;
    return (parameter == 0 ? sds.kbar_pair_sd_pct : sds.cbar_pair_sd_pct)[region];
  }
  const ChainSds& sds = shared_m ? config.pooling.m_per_session : config.pooling.per_step;
  const std::array<const std::array<double, kRegionCount>*, 4> chain = {
      &sds.kbar_chain_sd_pct, &sds.n_chain_sd, &sds.cbar_chain_sd_pct, &sds.m_chain_sd};
  const std::array<const std::array<double, kRegionCount>*, 4> step = {
      &sds.kbar_step_sd_pct, &sds.n_step_sd, &sds.cbar_step_sd_pct, &sds.m_step_sd};
  return (*(table == Table::Step ? step : chain)[parameter])[region];
}

// What one mode (each step at its own m, or one m per session) measured, beside the config's.
struct ModeReport {
  bool shared_m = false;
  const ChainSamples* samples = nullptr;
  MeasuredChainSds measured;
};

// One entry of a table: a region's samples of one parameter, its SD as measured and as the
// config has it (on the config's scale: 100 ln for kbar and cbar), and the RMS of z with each and
// with none.
struct Cell {
  const std::vector<ChainSample>* samples = nullptr;
  std::optional<double> measured;
  double config = 0.0;
  double rms_measured = std::nan("");
  double rms_config = std::nan("");
  double rms_without = std::nan("");
};

std::span<const TableKey> keys_of(Table table) {
  switch (table) {
    case Table::Chain:
      return kChainKeys;
    case Table::Step:
      return kStepKeys;
    case Table::Pair:
      break;
  }
  return kPairKeys;
}

Cell cell_of(const Config& config, const ModeReport& mode, Table table, const TableKey& k,
             std::size_t region) {
  const std::size_t p = k.parameter;
  const bool pair = table == Table::Pair;
  Cell c;
  c.samples = pair                   ? &mode.samples->feet[region][p]
              : table == Table::Step ? &mode.samples->steps[region][p]
                                     : &mode.samples->pooled[region][p];
  c.measured = pair                   ? mode.measured.pair[p][region]
               : table == Table::Step ? mode.measured.step[p][region]
                                      : mode.measured.chain[p][region];
  c.config = config_value(config, mode.shared_m, table, p, region);
  // m's SD reaches the others through their slopes on a shared m (0 where m is each step's own).
  const double m_sd = pair ? 0.0 : mode.measured.chain[3][region].value_or(0.0);
  const double config_m_sd =
      pair ? 0.0 : config_value(config, mode.shared_m, Table::Chain, 3, region);
  // A step errs by the chain's SD and its own.
  const double chain = table == Table::Step ? mode.measured.chain[p][region].value_or(0.0) : 0.0;
  const double config_chain =
      table == Table::Step ? config_value(config, mode.shared_m, Table::Chain, p, region) : 0.0;
  const double scale = k.percent ? 0.01 : 1.0;
  if (c.measured) c.rms_measured = rms_z(*c.samples, std::hypot(chain, *c.measured) * scale, m_sd);
  c.rms_config = rms_z(*c.samples, std::hypot(config_chain, c.config) * scale, config_m_sd);
  c.rms_without = rms_z(*c.samples, 0.0);
  return c;
}

std::string sd_text(std::optional<double> sd, bool percent) {
  if (!sd) return "-";
  return percent ? fmt::format("{:.1f}", *sd) : fmt::format("{:.3f}", *sd);
}

std::string rms_text(double rms) {
  return std::isnan(rms) ? "-" : fmt::format("{:.2f}", rms);
}

void print_table(const Config& config, const ModeReport& mode, Table table) {
  const char* what = "";
  switch (table) {
    case Table::Chain:
      what =
          "the SD of the pooled means' error against the truth; after it the config's in "
          "brackets, then the RMS of z with the SD measured / the config's / none";
      break;
    case Table::Step:
      what =
          "the SD of each step's own error beyond its Jacobian's and the chain's; after it the "
          "config's in brackets, then the RMS of the steps' z with it and the chain's SD measured "
          "/ the config's / neither";
      break;
    case Table::Pair:
      what =
          "the SD of the feet's difference, whose truth is none; after it the config's in "
          "brackets, then the RMS of z with the SD measured / the config's / none";
      break;
  }
  fmt::print("\n[{}{}] ({}): {}\n", table == Table::Pair ? "asymmetry" : "pooling",
             mode.shared_m ? ".m_per_session" : "",
             mode.shared_m ? "one m per region over the session" : "each step at its own m", what);
  fmt::print("{:<18} {:>5}", "region",
             table == Table::Pair ? "pairs" : (table == Table::Step ? "steps" : "pools"));
  for (const TableKey& k : keys_of(table)) fmt::print("  {:<28}", k.label);
  fmt::print("\n");
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    fmt::print("{:<18} {:>5}", region_name(kRegions[ri]),
               cell_of(config, mode, table, keys_of(table)[0], ri).samples->size());
    for (const TableKey& k : keys_of(table)) {
      const Cell c = cell_of(config, mode, table, k, ri);
      fmt::print("  {:<28}", fmt::format("{} ({}) {}/{}/{}", sd_text(c.measured, k.percent),
                                         sd_text(c.config, k.percent), rms_text(c.rms_measured),
                                         rms_text(c.rms_config), rms_text(c.rms_without)));
    }
    fmt::print("\n");
  }
}

// One config table as TOML, the config's value where nothing was measured (said above it).
std::string toml_line(const Config& config, const ModeReport& mode, Table table,
                      const TableKey& k) {
  std::vector<std::string> entries, kept;
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    const Cell c = cell_of(config, mode, table, k, ri);
    if (!c.measured) kept.emplace_back(region_name(kRegions[ri]));
    entries.push_back(fmt::format("{} = {}", region_name(kRegions[ri]),
                                  sd_text(c.measured.value_or(c.config), k.percent)));
  }
  std::string text;
  if (!kept.empty()) {
    text = fmt::format("# {}: nothing to measure in these sessions, the value of {}\n",
                       fmt::join(kept, ", "), config.source.string());
  }
  return text + fmt::format("{} = {{ {} }}\n", k.key, fmt::join(entries, ", "));
}

template <typename T>
std::string range_text(T first, T last) {
  return first == last ? fmt::format("{}", first) : fmt::format("{}-{}", first, last);
}

std::string design_text(const CalibrationDesign& d) {
  std::vector<std::string> sizes;
  for (InsoleSize s : d.sizes) sizes.emplace_back(insole_size_name(s));
  return fmt::format(
      "{} simulated session{} of {} s (sizes {}; seeds {}; body mass {} kg; noise {} bits, dc "
      "bias 0-{} bits, placement SD {} mm)",
      d.session_count(), d.session_count() == 1 ? "" : "s", d.duration_s, fmt::join(sizes, ", "),
      range_text(d.first_seed, d.last_seed), range_text(d.min_body_mass_kg, d.max_body_mass_kg),
      d.noise_sd_bits, d.max_bias_bits, d.placement_sd_mm);
}

// The step SDs whose measured value is not the config's. The pools weighed each step with the
// config's (pool_region_steps), and the chain's SDs are measured on those pools, so the tables
// hold together only where the two agree.
int step_sds_measured_otherwise(const Config& config, std::span<const ModeReport> modes) {
  int otherwise = 0;
  for (const ModeReport& mode : modes) {
    for (const TableKey& k : keys_of(Table::Step)) {
      for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
        const Cell c = cell_of(config, mode, Table::Step, k, ri);
        if (c.measured && std::abs(*c.measured - c.config) > 1e-9) ++otherwise;
      }
    }
  }
  return otherwise;
}

std::string step_sd_note(int otherwise) {
  if (otherwise == 0) {
    return "the pools weighed each step with the config's step SDs (*_step_sd), which are what "
           "these sessions measure";
  }
  return fmt::format(
      "the pools weighed each step with the config's step SDs (*_step_sd), and {} of them "
      "measure otherwise here. The chain's SDs here hold for the config's; a config that takes "
      "other step SDs needs its chain's SDs measured again with them, until nothing moves but "
      "a pair of entries that trade a rounding step back and forth (take the larger of each)",
      otherwise);
}

std::string toml_text(const Config& config, const CalibrationDesign& design,
                      std::span<const ModeReport> modes) {
  std::string text = fmt::format(
      "# Measured by gaitmon calibrate on\n# {}:\n# the SD per region that brings the z of the "
      "pooled means against the truth, of each step's\n# own estimate and of the feet's "
      "difference to an RMS of 1, rounded up. To use them, replace\n# the keys of the same "
      "tables in the config.\n# Note: {}.\n",
      design_text(design), step_sd_note(step_sds_measured_otherwise(config, modes)));
  for (const bool pair : {true, false}) {
    for (const ModeReport& mode : modes) {
      text += fmt::format("\n[{}{}]\n", pair ? "asymmetry" : "pooling",
                          mode.shared_m ? ".m_per_session" : "");
      for (const Table table :
           pair ? std::vector{Table::Pair} : std::vector{Table::Chain, Table::Step}) {
        for (const TableKey& k : keys_of(table)) text += toml_line(config, mode, table, k);
      }
    }
  }
  return text;
}

nlohmann::json mode_json(const Config& config, const ModeReport& mode) {
  const auto number = [](double v) { return std::isnan(v) ? nlohmann::json() : nlohmann::json(v); };
  nlohmann::json out;
  for (const Table kind : {Table::Chain, Table::Step, Table::Pair}) {
    nlohmann::json& table = out[kind == Table::Pair ? "asymmetry" : "pooling"];
    for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
      nlohmann::json& region = table[std::string(region_name(kRegions[ri]))];
      for (const TableKey& k : keys_of(kind)) {
        const Cell c = cell_of(config, mode, kind, k, ri);
        region[k.key] = {{"samples", c.samples->size()},
                         {"measured", c.measured ? nlohmann::json(*c.measured) : nlohmann::json()},
                         {"config", c.config},
                         {"rms_z_measured", number(c.rms_measured)},
                         {"rms_z_config", number(c.rms_config)},
                         {"rms_z_without", number(c.rms_without)}};
      }
    }
  }
  return out;
}

void run_calibrate(const GlobalOptions& global, CalibrateArgs& args) {
  const Config config = load_global_config(global);
  CalibrationDesign& design = args.design;
  design.sizes.clear();
  for (const std::string& s : args.sizes) design.sizes.push_back(*parse_insole_size(s));
  std::tie(design.first_seed, design.last_seed) =
      parse_range<std::uint64_t>(args.seeds, "--seeds", whole);
  std::tie(design.min_body_mass_kg, design.max_body_mass_kg) =
      parse_range<double>(args.body_mass, "--body-mass", real);
  try {
    design.check();
  } catch (const std::invalid_argument& e) {
    throw CLI::ValidationError(e.what());
  }
  if (!args.out_dir.empty()) check_output_dir(args.out_dir, "--out");
  std::optional<OutputSet> outputs;
  if (!args.out_dir.empty()) {
    outputs.emplace(args.out_dir,
                    std::initializer_list<std::string_view>{"calibration.json", "calibration.toml"},
                    std::filesystem::path());
  }

  // The sessions are written, segmented from their files and removed one by one.
  std::string pattern =
      (std::filesystem::temp_directory_path() / "gaitmon-calibrate-XXXXXX").string();
  if (mkdtemp(pattern.data()) == nullptr) {
    throw std::runtime_error(
        fmt::format("cannot make a scratch folder {}: {}", pattern, std::strerror(errno)));
  }
  const std::filesystem::path scratch(pattern);
  fmt::print("calibrate: {}\n", design_text(design));
  std::fflush(stdout);
  const auto start = std::chrono::steady_clock::now();
  CalibrationSamples samples;
  try {
    const StopSignals stop_signals;
    ProgressBar progress("calibrate");
    samples = collect_chain_samples(config, design, scratch, [&](double fraction) {
      if (g_stop_signal != 0) throw Stopped{};
      progress.update(fraction);
    });
  } catch (const Stopped&) {
    std::filesystem::remove_all(scratch);
    const int signal = g_stop_signal;
    fmt::print(stderr, "calibrate: stopped by {}; nothing written\n",
               signal == SIGINT ? "SIGINT" : "SIGTERM");
    // Ends as the signal would have, for the shell and the caller to see; raise returns only
    // where the caller blocked the signal, and the run then fails as any other would.
    std::signal(signal, SIG_DFL);
    std::raise(signal);
    throw std::runtime_error("calibrate: stopped");
  } catch (...) {
    std::filesystem::remove_all(scratch);
    throw;
  }
  std::filesystem::remove_all(scratch);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  fmt::print("simulated and analysed in {:.1f} s (each at its own m and at one m per session)\n",
             seconds);

  const std::array<ModeReport, 2> modes = {
      ModeReport{false, &samples.per_step, measure_chain_sds(samples.per_step)},
      ModeReport{true, &samples.m_per_session, measure_chain_sds(samples.m_per_session)}};
  for (const Table table : {Table::Chain, Table::Step, Table::Pair})
    for (const ModeReport& mode : modes) print_table(config, mode, table);
  const int otherwise = step_sds_measured_otherwise(config, modes);
  fmt::print("\ncalibrate: {}\n", step_sd_note(otherwise));
  if (!outputs) return;
  std::filesystem::create_directories(args.out_dir);
  nlohmann::json json = {{"design",
                          {{"sessions", design.session_count()},
                           {"duration_s", design.duration_s},
                           {"first_seed", design.first_seed},
                           {"last_seed", design.last_seed},
                           {"min_body_mass_kg", design.min_body_mass_kg},
                           {"max_body_mass_kg", design.max_body_mass_kg},
                           {"noise_sd_bits", design.noise_sd_bits},
                           {"max_bias_bits", design.max_bias_bits},
                           {"placement_sd_mm", design.placement_sd_mm}}},
                         {"config", config.source.string()},
                         {"step_sds_measured_otherwise", otherwise},
                         {"per_step", mode_json(config, modes[0])},
                         {"m_per_session", mode_json(config, modes[1])}};
  for (InsoleSize s : design.sizes) json["design"]["sizes"].push_back(insole_size_name(s));
  json["note"] =
      "per table and region: the SD that brings the RMS of z to 1, rounded up (measured; null "
      "where there were no samples), the config's, and the RMS of z with each and with none; "
      "kbar and cbar in 100 ln, n and m as they are. The *_step_sd are each step's own error "
      "beyond its Jacobian's, whose z takes the chain's SD of the same kind (measured or the "
      "config's) with it. At one m per session m's measured SD also enters the others' z "
      "through their slopes on it";
  outputs->add("calibration.json", json_file_text(json));
  outputs->add("calibration.toml", toml_text(config, design, modes));
  for (const auto& path : outputs->commit()) fmt::print("wrote {}\n", path.string());
}

}  // namespace

void add_calibrate_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<CalibrateArgs>();
  args->sizes = insole_size_names();
  CLI::App* sub = app.add_subcommand(
      "calibrate",
      "Measure the measurement chain's shared error on simulated sessions: the SDs of [pooling] "
      "and [asymmetry] of the config that bring the z of the pooled means against the truth, and "
      "of the feet's difference, to an RMS of 1; prints them beside the config's and, with --out, "
      "writes DIR/calibration.json and DIR/calibration.toml");
  sub->add_option("--sizes", args->sizes, "Insole sizes, comma-separated (each with every seed)")
      ->delimiter(',')
      ->check(CLI::IsMember(insole_size_names()))
      ->capture_default_str();
  sub->add_option("--seeds", args->seeds, "Seeds FIRST-LAST (or one), for every size")
      ->capture_default_str();
  sub->add_option("--duration", args->design.duration_s, "Length of each session, s")
      ->check(number_in(5.0, 3600.0))
      ->capture_default_str();
  sub->add_option("--body-mass", args->body_mass,
                  "Body mass MIN-MAX (or one), kg, spread evenly over the seeds")
      ->capture_default_str();
  sub->add_option("--noise", args->design.noise_sd_bits, "Sensor noise SD, bits")
      ->check(number_in(0.0, 50.0))
      ->capture_default_str();
  sub->add_option("--max-bias", args->design.max_bias_bits,
                  "Per-sensor dc bias, uniform integer 0..MAX bits")
      ->check(CLI::Range(0, 50))
      ->capture_default_str();
  sub->add_option("--placement-sd", args->design.placement_sd_mm,
                  "Step-to-step SD of where the foot lands on the insole, mm")
      ->check(number_in(0.0, 10.0))
      ->capture_default_str();
  sub->add_option("--out,-o", args->out_dir,
                  "Folder for calibration.json and calibration.toml (nothing written without it)");
  sub->callback([&global, args] { run_calibrate(global, *args); });
}

}  // namespace gaitmon::cli
