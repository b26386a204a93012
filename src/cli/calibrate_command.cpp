// `gaitmon calibrate`: the chain's SDs of [pooling] and [asymmetry] measured on simulated sessions,
// as tables on stdout and, with --out, as JSON and as TOML to paste into the config.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
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
  std::filesystem::path designs_file;
  bool settle = false;
  std::size_t max_rounds = 10;
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

// Which of the config's sets of tables: those of the footprint or of footprint-mean (measured on
// the coverage raster), for steps fitted each at its own m or at one m per session.
struct TableSet {
  bool footprint_mean = false;
  bool shared_m = false;
};

constexpr TableSet kTableSets[] = {{false, false}, {false, true}, {true, false}, {true, true}};

AreaSource area_of(TableSet set) {
  return set.footprint_mean ? AreaSource::FootprintMean : AreaSource::Footprint;
}

// "[pooling]", "[asymmetry.footprint_mean.m_per_session]", ...
std::string table_name(Table table, TableSet set) {
  return chain_table_name(table == Table::Pair ? "asymmetry" : "pooling", area_of(set),
                          set.shared_m);
}

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

// One entry of the config's tables, on the config's scale (100 ln for kbar and cbar).
template <typename C>
auto& config_entry(C& config, TableSet set, Table table, std::size_t parameter,
                   std::size_t region) {
  if (table == Table::Pair) {
    auto& pairs = set.footprint_mean ? config.asymmetry_footprint_mean : config.asymmetry;
    auto& sds = set.shared_m ? pairs.m_per_session : pairs.per_step;
    return (parameter == 0 ? sds.kbar_pair_sd_pct : sds.cbar_pair_sd_pct)[region];
  }
  auto& pooling = set.footprint_mean ? config.pooling_footprint_mean : config.pooling;
  auto& sds = set.shared_m ? pooling.m_per_session : pooling.per_step;
  const std::array chain = {&sds.kbar_chain_sd_pct, &sds.n_chain_sd, &sds.cbar_chain_sd_pct,
                            &sds.m_chain_sd};
  const std::array step = {&sds.kbar_step_sd_pct, &sds.n_step_sd, &sds.cbar_step_sd_pct,
                           &sds.m_step_sd};
  return (*(table == Table::Step ? step : chain)[parameter])[region];
}

double config_value(const Config& config, TableSet set, Table table, std::size_t parameter,
                    std::size_t region) {
  return config_entry(config, set, table, parameter, region);
}

// What one mode (each step at its own m, or one m per session) measured, beside the config's.
struct ModeReport {
  TableSet set;
  const ChainSamples* samples = nullptr;
  MeasuredChainSds measured;
};

// One design's latest round: its sessions' samples and what they measure in each mode (whose
// `samples` point into this run's, so a run stays where it is once measured).
struct DesignRun {
  CalibrationDesignEntry entry;
  CalibrationSamples samples;
  std::array<ModeReport, 2> modes;

  bool measures(Table table) const {
    return table == Table::Pair ? entry.asymmetry : entry.pooling;
  }
  // A design measures the tables of the cells it simulates, in both ways of fitting m.
  bool measures(TableSet set) const {
    return set.footprint_mean == (entry.design.rasterisation == Rasterisation::Coverage);
  }
  // The entry as this design measured it, if it measures that table and had samples for it.
  std::optional<double> measured(TableSet set, Table table, std::size_t parameter,
                                 std::size_t region) const;
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

template <typename M>
auto& measured_entry(M& measured, Table table, std::size_t parameter, std::size_t region) {
  switch (table) {
    case Table::Chain:
      return measured.chain[parameter][region];
    case Table::Step:
      return measured.step[parameter][region];
    case Table::Pair:
      break;
  }
  return measured.pair[parameter][region];
}

Cell cell_of(const Config& config, const ModeReport& mode, Table table, const TableKey& k,
             std::size_t region) {
  const std::size_t p = k.parameter;
  const bool pair = table == Table::Pair;
  Cell c;
  c.samples = pair                   ? &mode.samples->feet[region][p]
              : table == Table::Step ? &mode.samples->steps[region][p]
                                     : &mode.samples->pooled[region][p];
  c.measured = measured_entry(mode.measured, table, p, region);
  c.config = config_value(config, mode.set, table, p, region);
  // m's SD reaches the others through their slopes on a shared m (0 where m is each step's own).
  const double m_sd = pair ? 0.0 : mode.measured.chain[3][region].value_or(0.0);
  const double config_m_sd = pair ? 0.0 : config_value(config, mode.set, Table::Chain, 3, region);
  // A step errs by the chain's SD and its own.
  const double chain = table == Table::Step ? mode.measured.chain[p][region].value_or(0.0) : 0.0;
  const double config_chain =
      table == Table::Step ? config_value(config, mode.set, Table::Chain, p, region) : 0.0;
  const double scale = k.percent ? 0.01 : 1.0;
  if (c.measured) c.rms_measured = rms_z(*c.samples, std::hypot(chain, *c.measured) * scale, m_sd);
  c.rms_config = rms_z(*c.samples, std::hypot(config_chain, c.config) * scale, config_m_sd);
  c.rms_without = rms_z(*c.samples, 0.0);
  return c;
}

std::optional<double> DesignRun::measured(TableSet set, Table table, std::size_t parameter,
                                          std::size_t region) const {
  if (!measures(table) || !measures(set)) return std::nullopt;
  return measured_entry(modes[set.shared_m].measured, table, parameter, region);
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
  fmt::print("\n{} ({}): {}\n", table_name(table, mode.set),
             mode.set.shared_m ? "one m per region over the session" : "each step at its own m",
             what);
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

// One config table as TOML from `written`, saying above it where no design measured a region of
// the cells they `simulated`.
std::string toml_line(const Config& config, const Config& written, std::span<const DesignRun> runs,
                      TableSet set, Table table, const TableKey& k, bool simulated) {
  std::vector<std::string> entries, kept;
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    const bool measured = std::any_of(runs.begin(), runs.end(), [&](const DesignRun& run) {
      return run.measured(set, table, k.parameter, ri).has_value();
    });
    if (!measured) kept.emplace_back(region_name(kRegions[ri]));
    entries.push_back(
        fmt::format("{} = {}", region_name(kRegions[ri]),
                    sd_text(config_value(written, set, table, k.parameter, ri), k.percent)));
  }
  std::string text;
  if (simulated && !kept.empty()) {
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
      "bias 0-{} bits, placement SD {} mm{})",
      d.session_count(), d.session_count() == 1 ? "" : "s", d.duration_s, fmt::join(sizes, ", "),
      range_text(d.first_seed, d.last_seed), range_text(d.min_body_mass_kg, d.max_body_mass_kg),
      d.noise_sd_bits, d.max_bias_bits, d.placement_sd_mm,
      d.rasterisation == Rasterisation::Coverage ? "; coverage raster, area footprint-mean" : "");
}

// Calls `f(set, table, key, region)` for every entry of the config's tables.
template <typename F>
void for_each_entry(F f) {
  for (const TableSet set : kTableSets) {
    for (const Table table : {Table::Chain, Table::Step, Table::Pair}) {
      for (const TableKey& k : keys_of(table)) {
        for (std::size_t ri = 0; ri < kRegionCount; ++ri) f(set, table, k, ri);
      }
    }
  }
}

// The entries whose value differs from `from` to `to`, as "[table] region key FROM -> TO".
std::vector<std::string> entries_moved(const Config& from, const Config& to,
                                       std::optional<Table> only = std::nullopt) {
  std::vector<std::string> moved;
  for_each_entry([&](TableSet set, Table table, const TableKey& k, std::size_t ri) {
    if (only && table != *only) return;
    const double a = config_value(from, set, table, k.parameter, ri);
    const double b = config_value(to, set, table, k.parameter, ri);
    if (std::abs(a - b) <= 1e-9) return;
    moved.push_back(fmt::format("{} {} {} {} -> {}", table_name(table, set),
                                region_name(kRegions[ri]), k.key, sd_text(a, k.percent),
                                sd_text(b, k.percent)));
  });
  return moved;
}

int entries_apart(const Config& a, const Config& b, std::optional<Table> only = std::nullopt) {
  return static_cast<int>(entries_moved(a, b, only).size());
}

// `config` with, per entry, the largest the designs that measure its table measured (its own
// where none did).
Config with_measured(Config config, std::span<const DesignRun> runs) {
  for_each_entry([&](TableSet set, Table table, const TableKey& k, std::size_t ri) {
    std::optional<double> largest;
    for (const DesignRun& run : runs) {
      if (const auto m = run.measured(set, table, k.parameter, ri)) {
        largest = std::max(largest.value_or(*m), *m);
      }
    }
    if (largest) config_entry(config, set, table, k.parameter, ri) = *largest;
  });
  return config;
}

std::string step_sd_note(int otherwise) {
  if (otherwise == 0) {
    return "the pools weighed each step with the config's step SDs (*_step_sd), which are what "
           "these sessions measure";
  }
  return fmt::format(
      "the pools weighed each step with the config's step SDs (*_step_sd), and {} of them "
      "measure otherwise here. The chain's SDs here hold for the config's; a config that takes "
      "other step SDs needs its chain's SDs measured again with them, until nothing moves "
      "(--settle does so)",
      otherwise);
}

// How --settle ended: the rounds measured the tables again with what the round before measured.
enum class Settled { NotAsked, NothingMoved, Cycle, MaxRounds };

struct Settling {
  Settled outcome = Settled::NotAsked;
  std::vector<int> moved;      ///< per round: entries it measured otherwise than it pooled with
  std::size_t cycle_from = 0;  ///< Cycle: the round whose tables the last one measured again
  int trading = 0;             ///< Cycle: entries that differ between the cycle's rounds
};

std::string note_of(const Settling& settling, int step_sds_otherwise) {
  const std::size_t rounds = settling.moved.size();
  switch (settling.outcome) {
    case Settled::NotAsked:
      return step_sd_note(step_sds_otherwise);
    case Settled::NothingMoved:
      return fmt::format(
          "round {} measured the tables it pooled with: its pools weighed each step with the "
          "step SDs (*_step_sd) written here, so the chain's SDs hold for them",
          rounds);
    case Settled::Cycle:
      return fmt::format(
          "measured again with its own tables, round {} came back to the tables that round {} "
          "pooled with, {} entries trading a rounding step back and forth; written is the larger "
          "of each entry over those rounds",
          rounds, settling.cycle_from, settling.trading);
    case Settled::MaxRounds:
      break;
  }
  return fmt::format(
      "measured again with its own tables for {} rounds (--max-rounds), and the last still moved "
      "{} entries: put these tables in the config's place and measure again",
      rounds, settling.moved.back());
}

std::string tables_of(const DesignRun& run) {
  const TableSet set{run.entry.design.rasterisation == Rasterisation::Coverage, false};
  std::vector<std::string> tables;
  if (run.entry.pooling) tables.push_back(table_name(Table::Chain, set));
  if (run.entry.asymmetry) tables.push_back(table_name(Table::Pair, set));
  return fmt::format("{}", fmt::join(tables, " and "));
}

// The config's tables of the cells the designs simulated as written, under a header that names
// the designs and the note.
std::string toml_text(const Config& config, const Config& written, std::span<const DesignRun> runs,
                      const std::string& note) {
  std::string text = "# Measured by gaitmon calibrate on\n";
  if (runs.size() == 1) {
    text += fmt::format("# {}:\n", design_text(runs[0].entry.design));
  } else {
    for (std::size_t i = 0; i < runs.size(); ++i) {
      text += fmt::format("# design {} ({}): {}\n", i + 1, tables_of(runs[i]),
                          design_text(runs[i].entry.design));
    }
    text += "# each entry the largest of the designs that measure its table;\n";
  }
  text += fmt::format(
      "# the SD per region that brings the z of the pooled means against the truth, of each "
      "step's\n# own estimate and of the feet's difference to an RMS of 1, rounded up. To use "
      "them, replace\n# the keys of the same tables in the config.\n# Note: {}.\n",
      note);
  // Every table, so that the text takes the place of the config's; those of cells no design
  // simulated are the config's, said once above each.
  for (const Table kind : {Table::Pair, Table::Chain}) {
    for (const TableSet set : kTableSets) {
      const bool simulated = std::any_of(runs.begin(), runs.end(),
                                         [&](const DesignRun& run) { return run.measures(set); });
      text += fmt::format("\n{}\n", table_name(kind, set));
      if (!simulated) {
        text += fmt::format("# no design here simulated {}: the values of {}\n",
                            set.footprint_mean ? "cells that average the pressure (coverage raster)"
                                               : "cells that read at their centres (centre raster)",
                            config.source.string());
      }
      for (const Table table : kind == Table::Pair ? std::vector{Table::Pair}
                                                   : std::vector{Table::Chain, Table::Step}) {
        for (const TableKey& k : keys_of(table)) {
          text += toml_line(config, written, runs, set, table, k, simulated);
        }
      }
    }
  }
  return text;
}

nlohmann::json mode_json(const Config& config, const DesignRun& run, const ModeReport& mode) {
  const auto number = [](double v) { return std::isnan(v) ? nlohmann::json() : nlohmann::json(v); };
  nlohmann::json out = nlohmann::json::object();
  for (const Table kind : {Table::Chain, Table::Step, Table::Pair}) {
    if (!run.measures(kind)) continue;
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

nlohmann::json design_json(const Config& config, const DesignRun& run) {
  const CalibrationDesign& design = run.entry.design;
  nlohmann::json out = {{"sessions", design.session_count()},
                        {"duration_s", design.duration_s},
                        {"first_seed", design.first_seed},
                        {"last_seed", design.last_seed},
                        {"min_body_mass_kg", design.min_body_mass_kg},
                        {"max_body_mass_kg", design.max_body_mass_kg},
                        {"noise_sd_bits", design.noise_sd_bits},
                        {"max_bias_bits", design.max_bias_bits},
                        {"placement_sd_mm", design.placement_sd_mm},
                        {"rasterisation", rasterisation_name(design.rasterisation)},
                        {"sizes", nlohmann::json::array()},
                        {"tables", nlohmann::json::array()},
                        {"per_step", mode_json(config, run, run.modes[0])},
                        {"m_per_session", mode_json(config, run, run.modes[1])}};
  for (InsoleSize s : design.sizes) out["sizes"].push_back(insole_size_name(s));
  if (run.entry.pooling) out["tables"].push_back("pooling");
  if (run.entry.asymmetry) out["tables"].push_back("asymmetry");
  return out;
}

nlohmann::json written_json(const Config& written) {
  nlohmann::json out;
  for_each_entry([&](TableSet set, Table table, const TableKey& k, std::size_t ri) {
    nlohmann::json& tables = set.footprint_mean ? out["footprint_mean"] : out;
    tables[set.shared_m ? "m_per_session" : "per_step"]
          [table == Table::Pair ? "asymmetry" : "pooling"][std::string(region_name(kRegions[ri]))]
          [k.key] = config_value(written, set, table, k.parameter, ri);
  });
  return out;
}

// Simulates and analyses the design's sessions with `config`'s tables in the pools; a stop signal
// removes the scratch folder and ends the process as the signal would.
CalibrationSamples collect_or_stop(const Config& config, const CalibrationDesign& design,
                                   const std::filesystem::path& scratch, const std::string& label) {
  try {
    const StopSignals stop_signals;
    ProgressBar progress(label);
    return collect_chain_samples(config, design, scratch, [&](double fraction) {
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
}

// The designs of --designs, or the one the design options give.
std::vector<CalibrationDesignEntry> designs_of(CalibrateArgs& args) {
  if (!args.designs_file.empty()) return load_calibration_designs(args.designs_file);
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
  return {CalibrationDesignEntry{design}};
}

void run_calibrate(const GlobalOptions& global, CalibrateArgs& args) {
  const Config config = load_global_config(global);
  std::vector<DesignRun> runs;
  for (CalibrationDesignEntry& entry : designs_of(args)) runs.push_back({std::move(entry), {}, {}});
  if (!args.out_dir.empty()) check_output_dir(args.out_dir, "--out");
  std::optional<OutputSet> outputs;
  if (!args.out_dir.empty()) {
    outputs.emplace(args.out_dir,
                    std::initializer_list<std::string_view>{"calibration.json", "calibration.toml"},
                    std::span<const std::filesystem::path>());
  }

  // The sessions are written, segmented from their files and removed one by one.
  std::string pattern =
      (std::filesystem::temp_directory_path() / "gaitmon-calibrate-XXXXXX").string();
  if (mkdtemp(pattern.data()) == nullptr) {
    throw std::runtime_error(
        fmt::format("cannot make a scratch folder {}: {}", pattern, std::strerror(errno)));
  }
  const std::filesystem::path scratch(pattern);
  for (std::size_t i = 0; i < runs.size(); ++i) {
    if (runs.size() == 1) {
      fmt::print("calibrate: {}\n", design_text(runs[i].entry.design));
    } else {
      fmt::print("calibrate: design {} of {} ({}): {}\n", i + 1, runs.size(), tables_of(runs[i]),
                 design_text(runs[i].entry.design));
    }
  }
  std::fflush(stdout);

  // Each round pools with the tables the round before measured (the first with the config's),
  // until they measure themselves again, come back to an earlier round's or --max-rounds ends.
  Settling settling;
  if (args.settle) settling.outcome = Settled::MaxRounds;
  const std::size_t max_rounds = args.settle ? args.max_rounds : 1;
  std::vector<Config> pooled_with = {config};
  Config written;
  for (std::size_t round = 1; round <= max_rounds; ++round) {
    const auto start = std::chrono::steady_clock::now();
    for (std::size_t i = 0; i < runs.size(); ++i) {
      std::string label = args.settle ? fmt::format("calibrate round {}", round) : "calibrate";
      if (runs.size() > 1) label += fmt::format(", design {}/{}", i + 1, runs.size());
      DesignRun& run = runs[i];
      run.samples = collect_or_stop(pooled_with.back(), run.entry.design, scratch, label);
      const bool footprint_mean = run.measures(TableSet{true, false});
      run.modes = {ModeReport{{footprint_mean, false},
                              &run.samples.per_step,
                              measure_chain_sds(run.samples.per_step)},
                   ModeReport{{footprint_mean, true},
                              &run.samples.m_per_session,
                              measure_chain_sds(run.samples.m_per_session)}};
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    written = with_measured(pooled_with.back(), runs);
    const std::vector<std::string> moved_entries = entries_moved(pooled_with.back(), written);
    const int moved = static_cast<int>(moved_entries.size());
    if (!args.settle) {
      fmt::print(
          "simulated and analysed in {:.1f} s (each at its own m and at one m per session)\n",
          seconds);
      break;
    }
    settling.moved.push_back(moved);
    // A few entries are named: they are the ones that may trade a rounding step back and forth.
    fmt::print("round {}: simulated and analysed in {:.1f} s; {} of the tables' entries moved{}\n",
               round, seconds, moved,
               moved > 0 && moved <= 6 ? fmt::format(": {}", fmt::join(moved_entries, "; ")) : "");
    std::fflush(stdout);
    if (moved == 0) {
      settling.outcome = Settled::NothingMoved;
      break;
    }
    const auto again = std::find_if(pooled_with.begin(), pooled_with.end(), [&](const Config& c) {
      return entries_apart(c, written) == 0;
    });
    if (again != pooled_with.end()) {
      settling.outcome = Settled::Cycle;
      settling.cycle_from = static_cast<std::size_t>(again - pooled_with.begin()) + 1;
      Config smaller = written;
      for (auto c = again; c != pooled_with.end(); ++c) {
        for_each_entry([&](TableSet set, Table table, const TableKey& k, std::size_t ri) {
          const double other = config_value(*c, set, table, k.parameter, ri);
          double& larger = config_entry(written, set, table, k.parameter, ri);
          double& least = config_entry(smaller, set, table, k.parameter, ri);
          larger = std::max(larger, other);
          least = std::min(least, other);
        });
      }
      settling.trading = entries_apart(written, smaller);
      break;
    }
    pooled_with.push_back(written);
  }
  std::filesystem::remove_all(scratch);

  for (std::size_t i = 0; i < runs.size(); ++i) {
    if (runs.size() > 1) {
      fmt::print("\ndesign {} of {} ({}):\n", i + 1, runs.size(), tables_of(runs[i]));
    }
    for (const Table table : {Table::Chain, Table::Step, Table::Pair}) {
      if (!runs[i].measures(table)) continue;
      for (const ModeReport& mode : runs[i].modes) print_table(config, mode, table);
    }
  }
  // The pools of the last round weighed each step with these step SDs.
  const int otherwise = entries_apart(written, pooled_with.back(), Table::Step);
  const std::string note = note_of(settling, otherwise);
  const std::string toml = toml_text(config, written, runs, note);
  if (runs.size() > 1 || settling.outcome == Settled::Cycle) {
    fmt::print("\nThe tables written (the larger of each entry {}):\n{}",
               runs.size() > 1 ? "over the designs that measure it" : "over the cycle's rounds",
               toml.substr(toml.find("\n[")));
  }
  fmt::print("\ncalibrate: {}\n", note);
  if (!outputs) return;
  std::filesystem::create_directories(args.out_dir);
  nlohmann::json json = {{"designs", nlohmann::json::array()},
                         {"config", config.source.string()},
                         {"step_sds_measured_otherwise", otherwise},
                         {"written", written_json(written)}};
  for (const DesignRun& run : runs) json["designs"].push_back(design_json(config, run));
  if (args.settle) {
    static constexpr const char* kOutcomes[] = {"", "nothing_moved", "cycle", "max_rounds"};
    json["settle"] = {{"rounds", settling.moved.size()},
                      {"moved", settling.moved},
                      {"outcome", kOutcomes[static_cast<int>(settling.outcome)]},
                      {"note", note}};
    if (settling.outcome == Settled::Cycle)
      json["settle"]["cycle_from_round"] = settling.cycle_from;
  }
  json["note"] =
      "per design, table and region: the SD that brings the RMS of z to 1, rounded up "
      "(measured; null where there were no samples), the config's, and the RMS of z with each "
      "and with none; kbar and cbar in 100 ln, n and m as they are; a design has the tables it "
      "measures. The *_step_sd are each step's own error beyond its Jacobian's, whose z takes "
      "the chain's SD of the same kind (measured or the config's) with it. At one m per session "
      "m's measured SD also enters the others' z through their slopes on it. `written` is what "
      "calibration.toml holds: per entry the largest the designs measured (over a cycle's "
      "rounds with --settle), the config's where none did. With --settle the samples are the "
      "last round's, and `config` is the config's as given";
  outputs->add("calibration.json", json_file_text(json));
  outputs->add("calibration.toml", toml);
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
      "writes DIR/calibration.json and DIR/calibration.toml. --designs runs several designs, "
      "--settle measures again until the tables measure themselves");
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
  sub->add_option_function<std::string>(
         "--rasterisation",
         [args](const std::string& raster) {
           args->design.rasterisation = *parse_rasterisation(raster);
         },
         "How the simulated cells read: centre (default) or coverage (cells that average the "
         "pressure over their area, analysed with footprint-mean as analyze's auto takes it)")
      ->check(CLI::IsMember({"centre", "coverage"}));
  auto* designs = sub->add_option(
      "--designs", args->designs_file,
      "A designs file (config/calibration_designs.toml: the shipped tables' eight) in place of "
      "the options above: each table's entries the largest of the designs that measure it");
  designs->check(CLI::ExistingFile);
  for (const char* option : {"--sizes", "--seeds", "--duration", "--body-mass", "--noise",
                             "--max-bias", "--placement-sd", "--rasterisation"}) {
    designs->excludes(sub->get_option(option));
  }
  auto* settle = sub->add_flag(
      "--settle", args->settle,
      "Measure again with the tables just measured in the pools, round after round, until they "
      "measure themselves (or come back to an earlier round's: then the larger of each entry)");
  sub->add_option("--max-rounds", args->max_rounds, "The most rounds --settle runs")
      ->check(CLI::Range(2, 50))
      ->needs(settle)
      ->capture_default_str();
  sub->add_option("--out,-o", args->out_dir,
                  "Folder for calibration.json and calibration.toml (nothing written without it)");
  sub->callback([&global, args] { run_calibrate(global, *args); });
}

}  // namespace gaitmon::cli
