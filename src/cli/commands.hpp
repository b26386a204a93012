// The subcommands of the gaitmon program; each registers itself on the top-level app.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "gaitmon/config.hpp"

namespace lcm {
class LCM;
}

namespace gaitmon::cli {

/// Options every subcommand shares.
struct GlobalOptions {
  std::filesystem::path config_path;
  std::string log_level;  ///< empty: [log] level of the config
};

/// Loads the config named by --config, or the default one, and sets the log level: --log-level,
/// else the config's [log] level. Every command calls it first.
Config load_global_config(const GlobalOptions& global);

/// A fitted value and its standard error joined by plus_minus ("+-", " &plusmn; "), or the value
/// and "(no SE)" where the data do not determine it (a non-finite se), so that no report prints
/// "nan".
std::string estimate_text(double value, double se, std::string_view plus_minus);

/// Opens the LCM connection of --lcm-url (from_command_line) or of [lcm] url: a URL LCM cannot
/// open is a command-line error (CLI::ValidationError) or a config error (ConfigError), exit 2.
std::shared_ptr<lcm::LCM> open_lcm_url(const GlobalOptions& global, const std::string& url,
                                       bool from_command_line);

/// A check of an option: a finite number from min to max, else "must be a number from MIN to MAX,
/// got TEXT" (NaN and trailing text refused, which CLI::Range lets through or mis-states).
CLI::Validator number_range(double min, double max);
/// A check of an option: a whole number >= min, else "must be a whole number >= MIN, got TEXT".
CLI::Validator whole_number_from(std::uint64_t min);

void add_simulate_command(CLI::App& app, const GlobalOptions& global);
void add_segment_command(CLI::App& app, const GlobalOptions& global);
void add_analyze_command(CLI::App& app, const GlobalOptions& global);
void add_discrepancy_command(CLI::App& app, const GlobalOptions& global);
void add_fake_insole_command(CLI::App& app, const GlobalOptions& global);
void add_spy_command(CLI::App& app, const GlobalOptions& global);
void add_run_command(CLI::App& app, const GlobalOptions& global);
void add_replay_command(CLI::App& app, const GlobalOptions& global);
void add_record_command(CLI::App& app, const GlobalOptions& global);

}  // namespace gaitmon::cli
