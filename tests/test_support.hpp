// Paths, scratch folders, small statistics and cell pictures for tests and benchmarks; free of
// any test framework.
#pragma once

#include <filesystem>
#include <limits>
#include <numbers>
#include <string>
#include <string_view>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/contact_ellipse.hpp"
#include "gaitmon/tissue_model.hpp"

namespace gaitmon::test {

/// Built with ASan or TSan: the longest numerical tests skip there, saying which test runs their
/// code under the sanitizers.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
/// The default cell's width and height (config/gaitmon.toml, [sensor]), mm.
inline constexpr double kCellWidthMm = 7.5;
inline constexpr double kCellHeightMm = 15.0;
/// The seed's Appendix I means of the heel of size 37-38.
inline const EllipsoidParams kHeel{80.2, 80.7, 69.9, 16.4, 0.117, 0.294, 0.011, 1.18};

/// The source tree (for config/ and replay/).
std::filesystem::path source_dir();
/// The project's shared/ folder beside the checkout (seed data, real recordings).
std::filesystem::path shared_dir();
/// The bundled demo session, replay/demo-simulated-37-38.csv (simulated, 60 s, two feet).
std::filesystem::path demo_session();
/// The gaitmon executable built with the tests (empty in benchmarks).
std::filesystem::path gaitmon_binary();
/// A fresh, empty scratch folder unique to this process and `name`, removed at exit unless
/// GAITMON_KEEP_SCRATCH is set.
std::filesystem::path scratch_dir(const std::string& name);
/// Writes `text` to `path`, creating folders; returns path.
std::filesystem::path write_text(const std::filesystem::path& path, const std::string& text);
/// The whole of the file at `path`; throws std::runtime_error if it cannot be read.
std::string read_text(const std::filesystem::path& path);
/// How often `what` (not empty) occurs in `text`, without overlaps.
std::size_t count(std::string_view text, std::string_view what);
/// The header and column line of a hand-made 35-36 session (93 sensors) at `rate_hz`.
std::string session_head(const std::string& rate_hz = "100");
/// One row of such a session: `time_and_foot` (e.g. "0.01,L") and `cells` readings of `value`.
std::string session_row(const std::string& time_and_foot, int cells = 93, int value = 0);
/// Runs a shell command, returns its exit status, and captures stdout+stderr into `output`.
int run_command(const std::string& command, std::string* output = nullptr);
/// Runs the gaitmon binary with `args` (a shell command line's rest), sets its exit status and
/// returns its stdout and stderr together.
std::string run_gaitmon(const std::string& args, int* status);
/// The shipped config, config/gaitmon.toml, loaded once.
const Config& shipped_config();
/// The sample standard deviation (n - 1); needs at least two values.
double sample_sd(const std::vector<double>& values);
/// The median (of the middle two for an even count); NaN for none.
double median(std::vector<double> values);
/// Active cells of the default 7.5 x 15 mm size from a picture, most anterior row first: '#'
/// active, '.' inactive. A row starting with '>' is shifted half a cell medially, as centred
/// rows of different length are.
std::vector<ActiveCell> cells_of(const std::vector<std::string>& rows);

}  // namespace gaitmon::test
