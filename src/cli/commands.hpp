// The subcommands of the gaitmon program; each registers itself on the top-level app.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/byte_source.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/discrepancy.hpp"

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

/// estimate_text of an effect's parameter, then " (sandwich" plus_minus robust_se ")" where the
/// step-clustered sandwich gives an error too.
std::string param_text(const ParamEstimate& p, std::string_view plus_minus);

/// What analyze, discrepancy and creep print after measuring a creep of `gain` and `tau_s` from
/// the zeros of a session (or of several that agree): the [sensor_creep] lines that undo it in
/// every frame of these insoles, or, where the config's creep was undone first, that this one is
/// what remains on top of it.
std::string sensor_creep_advice(const Config& config, double gain, double tau_s);

/// Opens the LCM connection of --lcm-url (from_command_line) or of [lcm] url: a URL LCM cannot
/// open is a command-line error (CLI::ValidationError) or a config error (ConfigError), exit 2.
std::shared_ptr<lcm::LCM> open_lcm_url(const GlobalOptions& global, const std::string& url,
                                       bool from_command_line);

/// The range check of a floating-point option: [min, max], or (min, max] with `open_min`.
/// CLI::Range lets nan through, as nan compares false with both bounds.
CLI::Validator number_in(double min, double max, bool open_min = false);

/// Every insole size's name ("35-36" ...), for the options that take one.
std::vector<std::string> insole_size_names();

/// The check of an unsigned option: digits only, from min to max. CLI11 takes "-1" and a
/// number too large for the type, and wraps or clamps them.
CLI::Validator whole_number_in(std::uint64_t min, std::uint64_t max);

/// The check of a session a command reads twice (its header first, then the whole file): an
/// existing regular file. A pipe (`/dev/stdin`, `<(...)`) would lose what the first read took
/// and fail with a misleading "missing version".
CLI::Validator session_file_read_twice();

void add_simulate_command(CLI::App& app, const GlobalOptions& global);
void add_segment_command(CLI::App& app, const GlobalOptions& global);
void add_analyze_command(CLI::App& app, const GlobalOptions& global);
void add_discrepancy_command(CLI::App& app, const GlobalOptions& global);
void add_creep_command(CLI::App& app, const GlobalOptions& global);
void add_calibrate_command(CLI::App& app, const GlobalOptions& global);
void add_fake_insole_command(CLI::App& app, const GlobalOptions& global);
void add_spy_command(CLI::App& app, const GlobalOptions& global);
void add_run_command(CLI::App& app, const GlobalOptions& global);
void add_replay_command(CLI::App& app, const GlobalOptions& global);

/// Makes the insole link from the config and --usb.
using InsoleSourceFactory =
    std::function<std::unique_ptr<drivers::ByteSource>(const Config& config, bool usb)>;
/// `make_source` defaults to the serial or USB driver (make_insole_source); tests pass a source
/// of their own, as no real driver can be made to fail at will.
void add_record_command(CLI::App& app, const GlobalOptions& global,
                        InsoleSourceFactory make_source = {});

}  // namespace gaitmon::cli
