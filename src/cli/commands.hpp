// The subcommands of the gaitmon program; each registers itself on the top-level app.
#pragma once

#include <CLI/CLI.hpp>
#include <filesystem>
#include <string>

#include "gaitmon/config.hpp"

namespace gaitmon::cli {

/// Options every subcommand shares.
struct GlobalOptions {
  std::filesystem::path config_path;
  std::string log_level = "info";
};

/// Applies --log-level and loads the config named by --config, or the default one. Every
/// command calls it first.
Config load_global_config(const GlobalOptions& global);

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
