// gaitmon command line: one subcommand per job; errors at the edges become one clear line.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <exception>
#include <iostream>

#include "commands.hpp"
#include "gaitmon/error.hpp"

int main(int argc, char** argv) {
  using namespace gaitmon::cli;
  // spdlog logs on stdout by default; stdout carries the commands' results (the step lines of the
  // live commands, the tables, fake-insole's pty path), so that a pipe gets results only.
  spdlog::set_default_logger(spdlog::stderr_color_mt("gaitmon"));
  CLI::App app{
      "gaitmon: step segmentation and plantar-tissue models from Medilogic pressure insoles"};
  // At most one, checked after parsing: CLI11 checks a required one before it reports a word it
  // does not know, so `gaitmon frobnicate` would say only that a subcommand is required.
  app.require_subcommand(0, 1);
  // Subcommands inherit it: --config and --log-level work after the command's name too.
  app.fallthrough();
  GlobalOptions global;
  app.add_option("--config", global.config_path,
                 "Main config file (default: $GAITMON_CONFIG or the source tree's "
                 "config/gaitmon.toml)")
      ->check(CLI::ExistingFile);
  app.add_option("--log-level", global.log_level,
                 "trace, debug, info, warn, error or off (default: [log] level of the config)")
      ->check(CLI::IsMember(gaitmon::log_level_names()));
  add_simulate_command(app, global);
  add_segment_command(app, global);
  add_analyze_command(app, global);
  add_discrepancy_command(app, global);
  add_creep_command(app, global);
  add_calibrate_command(app, global);
  add_fake_insole_command(app, global);
  add_spy_command(app, global);
  add_run_command(app, global);
  add_replay_command(app, global);
  add_record_command(app, global);

  try {
    app.parse(argc, argv);
    if (app.get_subcommands().empty()) throw CLI::RequiredError("A subcommand");
  } catch (const CLI::ParseError& e) {
    // CLI11 prints the message (or the help) here. Its own codes (101-1xx) would set a usage
    // error apart from a bad file, which scripts in the lab do not need: both are 2.
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const gaitmon::InputError& e) {
    std::cerr << "gaitmon: bad input: " << e.what() << '\n';
    return 2;
  } catch (const gaitmon::ConfigError& e) {
    std::cerr << "gaitmon: bad config: " << e.what() << '\n';
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "gaitmon: error: " << e.what() << '\n';
    return 1;
  }
  return 0;
}
