// Test helpers; paths come from compile definitions set by tests/CMakeLists.txt.
#include "test_support.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <vector>

namespace gaitmon::test {

std::filesystem::path source_dir() {
  return GAITMON_SOURCE_DIR;
}

std::filesystem::path shared_dir() {
  return GAITMON_SHARED_DIR;
}

std::filesystem::path demo_session() {
  return source_dir() / "replay" / "demo-simulated-37-38.csv";
}

std::filesystem::path gaitmon_binary() {
#ifdef GAITMON_BINARY
  return GAITMON_BINARY;
#else
  return {};
#endif
}

namespace {
// Scratch folders are removed when the program ends, unless GAITMON_KEEP_SCRATCH is set (to
// look at what a failing test wrote).
struct ScratchFolders {
  std::vector<std::filesystem::path> dirs;
  ~ScratchFolders() {
    const char* keep = std::getenv("GAITMON_KEEP_SCRATCH");
    if (keep != nullptr && *keep != '\0') return;
    std::error_code ignored;
    for (const auto& dir : dirs) std::filesystem::remove_all(dir, ignored);
  }
};
ScratchFolders scratch_folders;
}  // namespace

std::filesystem::path scratch_dir(const std::string& name) {
  auto dir = std::filesystem::temp_directory_path() /
             ("gaitmon-test-" + std::to_string(::getpid()) + "-" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  scratch_folders.dirs.push_back(dir);
  return dir;
}

std::filesystem::path write_text(const std::filesystem::path& path, const std::string& text) {
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + path.string());
  return path;
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path.string());
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::size_t count(std::string_view text, std::string_view what) {
  std::size_t n = 0;
  for (std::size_t at = text.find(what); at != std::string_view::npos;
       at = text.find(what, at + what.size())) {
    ++n;
  }
  return n;
}

std::string session_head(const std::string& rate_hz) {
  std::string text = "# gaitmon-session: 1\n# insole_size: 35-36\n# sample_rate_hz: " + rate_hz +
                     "\n# sensors: 93\nt_s,foot";
  for (int i = 1; i <= 93; ++i) text += ",s" + std::to_string(i);
  return text + "\n";
}

std::string session_row(const std::string& time_and_foot, int cells, int value) {
  std::string row = time_and_foot;
  for (int i = 0; i < cells; ++i) row += "," + std::to_string(value);
  return row + "\n";
}

int run_command(const std::string& command, std::string* output) {
  std::string full = command + " 2>&1";
  FILE* pipe = ::popen(full.c_str(), "r");
  if (pipe == nullptr) throw std::runtime_error("popen failed: " + command);
  std::array<char, 4096> buffer{};
  std::string text;
  std::size_t got = 0;
  while ((got = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0)
    text.append(buffer.data(), got);
  int status = ::pclose(pipe);
  if (output != nullptr) *output = std::move(text);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string run_gaitmon(const std::string& args, int* status) {
  std::string output;
  *status = run_command(gaitmon_binary().string() + " " + args, &output);
  return output;
}

const Config& shipped_config() {
  static const Config config = load_config(source_dir() / "config" / "gaitmon.toml");
  return config;
}

double median(std::vector<double> values) {
  if (values.empty()) return kNaN;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 == 1 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

double sample_sd(const std::vector<double>& values) {
  double mean = 0.0;
  for (double x : values) mean += x / static_cast<double>(values.size());
  double ss = 0.0;
  for (double x : values) ss += (x - mean) * (x - mean);
  return std::sqrt(ss / static_cast<double>(values.size() - 1));
}

std::vector<ActiveCell> cells_of(const std::vector<std::string>& rows) {
  const CellSize size;
  std::vector<ActiveCell> cells;
  const auto n = static_cast<int>(rows.size());
  for (int r = 0; r < n; ++r) {
    std::string row = rows[static_cast<std::size_t>(r)];
    double offset = 0.0;
    if (!row.empty() && row.front() == '>') {
      offset = 0.5;
      row.erase(0, 1);
    }
    for (std::size_t i = 0; i < row.size(); ++i) {
      if (row[i] == '#') {
        cells.push_back({(static_cast<double>(i) + offset) * size.width_mm,
                         (n - 1 - r) * size.height_mm, false});
      }
    }
  }
  return cells;
}

}  // namespace gaitmon::test
