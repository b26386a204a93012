// Session CSV v1 (shared/docs/session-format.md): a streaming reader and a writer.
//
// The reader holds one line at a time, never the whole file. Bad input throws InputError naming
// the file (or the name given for a stream), the 1-based line and the reason; nothing partial is
// returned silently.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "gaitmon/frame.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

struct SessionHeader {
  int version = 1;
  InsoleSize insole_size = InsoleSize::S37_38;
  double sample_rate_hz = 100.0;
  std::size_t sensors = 107;
  std::optional<std::string> subject;
  std::optional<std::string> recorded_at;
  std::optional<std::string> note;
  std::optional<double> body_mass_kg;
  /// Every other `# key: value` line, in file order; kept and otherwise ignored.
  std::vector<std::pair<std::string, std::string>> extra;
};

/// The largest |t_s| the reader accepts: a day, longer than any walking session (simulate's
/// --duration stops there too). A time beyond it is corrupt (1e308 would overflow the wire
/// format's microseconds), not a recording.
inline constexpr double kMaxSessionTimeS = 86400.0;

class SessionReader {
 public:
  /// Opens the file and parses the metadata and column header. Throws InputError.
  explicit SessionReader(const std::filesystem::path& path);
  /// Reads the session from `in` (which must outlive the reader), by the same parser; errors
  /// name `name` where a file's would name its path. Throws InputError.
  SessionReader(std::istream& in, std::string name);
  ~SessionReader();
  SessionReader(const SessionReader&) = delete;
  SessionReader& operator=(const SessionReader&) = delete;

  const SessionHeader& header() const;
  /// The file's path, or the name given with a stream.
  const std::filesystem::path& path() const;

  /// Reads the next frame into `frame` (its bits buffer is reused). Returns false at the end of
  /// the file. Throws InputError for a bad line.
  bool next(Frame& frame);

  /// The 1-based line number of the frame last returned by next().
  std::uint64_t line() const;

  /// Bytes of the file consumed so far, through the end of the last line read (for progress).
  std::uint64_t bytes_read() const;

  /// The frame rate per foot the times show so far: one over the median spacing of a foot's
  /// successive frames, over the first kRateSpacings spacings (a lost frame or a gap does not
  /// move a median); nullopt before 10 spacings.
  std::optional<double> timestamp_rate_hz() const;
  static constexpr std::size_t kRateSpacings = 2000;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Logs a warning naming the file and both rates when the header's sample_rate_hz and the
/// reader's timestamp_rate_hz() are more than 10 % apart: the windows of the step detector are in
/// frames, so a wrong header rate misjudges every one of them.
void warn_on_rate_mismatch(const SessionReader& reader);

/// Reads the whole session once, before anything is played from it: a bad line found while
/// playing would come after the frames before it were sent. Throws InputError at the first bad
/// line, or "no frames" for a header alone; warns as warn_on_rate_mismatch does. Returns the
/// number of frames.
std::uint64_t check_whole_session(const std::filesystem::path& path);

/// Why `value` cannot be a header value that reads back as written (a line break, or a blank at
/// either end, which the reader trims), or an empty string if it can.
std::string header_value_problem(std::string_view value);

class SessionWriter {
 public:
  /// Creates (truncates) the file and writes the metadata and column header.
  /// Throws std::runtime_error naming the file if it cannot be written.
  SessionWriter(const std::filesystem::path& path, const SessionHeader& header);
  ~SessionWriter();
  SessionWriter(const SessionWriter&) = delete;
  SessionWriter& operator=(const SessionWriter&) = delete;

  /// Appends one frame. Throws std::invalid_argument for a wrong sensor count or a time that
  /// does not increase for its foot or is beyond kMaxSessionTimeS, std::runtime_error on an I/O
  /// failure.
  void write(const Frame& frame);

  /// Flushes and closes; throws std::runtime_error on failure. Called by the destructor if
  /// needed (which then swallows errors).
  void close();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gaitmon
