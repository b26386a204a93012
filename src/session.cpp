// Session CSV v1: a streaming reader (chunked reads, reused buffers) and a buffered writer.
#include "gaitmon/session.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <istream>
#include <limits>
#include <stdexcept>
#include <string_view>

#include "gaitmon/error.hpp"

namespace gaitmon {
namespace {

constexpr std::size_t kChunkBytes = std::size_t{1} << 16;
constexpr std::size_t kMaxLineBytes = std::size_t{1} << 20;
constexpr std::string_view kBom = "\xEF\xBB\xBF";
constexpr double kNoTime = -std::numeric_limits<double>::infinity();

// The keys the format gives a meaning to; a second occurrence of any of them is ambiguous.
enum class Key : std::size_t {
  Version,
  InsoleSize,
  SampleRate,
  Sensors,
  Subject,
  RecordedAt,
  Note,
  BodyMass
};
constexpr std::size_t kKeyCount = 8;
constexpr std::array<std::string_view, kKeyCount> kKeyNames{
    "gaitmon-session", "insole_size", "sample_rate_hz", "sensors",
    "subject",         "recorded_at", "note",           "body_mass_kg"};

std::optional<Key> known_key(std::string_view name) {
  for (std::size_t i = 0; i < kKeyCount; ++i) {
    if (kKeyNames[i] == name) return static_cast<Key>(i);
  }
  return std::nullopt;
}

bool is_key_char(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
         c == '-' || c == '.';
}

bool is_blank(char c) {
  return c == ' ' || c == '\t';
}

std::string format_double(double value) {
  std::array<char, 32> text{};
  const auto result = std::to_chars(text.data(), text.data() + text.size(), value);
  return std::string(text.data(), result.ptr);
}

// Quotes a piece of input for an error message, cut short so a runaway line stays readable.
// Control bytes are shown as \xNN: a NUL would end the message where a C string is printed, and
// a CR would overwrite it on a terminal.
std::string quote(std::string_view text) {
  constexpr std::size_t kShown = 40;
  std::string quoted = "'";
  for (const char c : text.substr(0, kShown)) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte < 0x20 || byte == 0x7f) {
      quoted += fmt::format("\\x{:02x}", byte);
    } else {
      quoted += c;
    }
  }
  return quoted + (text.size() > kShown ? "...'" : "'");
}

bool parse_finite(std::string_view text, double& value) {
  const char* end = text.data() + text.size();
  const auto result = std::from_chars(text.data(), end, value);
  return result.ec == std::errc{} && result.ptr == end && std::isfinite(value);
}

bool parse_positive(std::string_view text, double& value) {
  return parse_finite(text, value) && value > 0.0;
}

std::optional<std::size_t> parse_count(std::string_view text) {
  // Nine digits cannot overflow and far exceed any real sensor count.
  if (text.empty() || text.size() > 9) return std::nullopt;
  std::size_t value = 0;
  for (char c : text) {
    if (c < '0' || c > '9') return std::nullopt;
    value = value * 10 + static_cast<std::size_t>(c - '0');
  }
  return value;
}

// "# key: value" -> {key, value}; the value is trimmed of surrounding blanks.
std::optional<std::pair<std::string_view, std::string_view>> split_metadata(std::string_view line) {
  std::size_t i = 1;
  while (i < line.size() && is_blank(line[i])) ++i;
  const std::size_t key_begin = i;
  while (i < line.size() && is_key_char(line[i])) ++i;
  if (i == key_begin || i == line.size() || line[i] != ':') return std::nullopt;
  const std::string_view key = line.substr(key_begin, i - key_begin);
  ++i;
  while (i < line.size() && is_blank(line[i])) ++i;
  std::string_view value = line.substr(i);
  while (!value.empty() && is_blank(value.back())) value.remove_suffix(1);
  return std::pair{key, value};
}

std::string column_header(std::size_t sensors) {
  std::string text = "t_s,foot";
  for (std::size_t i = 1; i <= sensors; ++i) text += ",s" + std::to_string(i);
  return text;
}

std::vector<std::string_view> split_commas(std::string_view line) {
  std::vector<std::string_view> fields;
  std::size_t begin = 0;
  for (;;) {
    const std::size_t comma = line.find(',', begin);
    if (comma == std::string_view::npos) {
      fields.push_back(line.substr(begin));
      return fields;
    }
    fields.push_back(line.substr(begin, comma - begin));
    begin = comma + 1;
  }
}

struct FileCloser {
  void operator()(std::FILE* file) const { std::fclose(file); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

// Fills `buffer` with up to `size` bytes of the input and returns how many; 0 at its end, or on a
// read error, which it describes in `error`.
using ReadBytes = std::function<std::size_t(char* buffer, std::size_t size, std::string& error)>;

// Hands out one line at a time from large reads, keeping only the current chunk and the tail of a
// line that crosses a chunk boundary. The buffer starts at one chunk and grows only for a line
// longer than that: a reader is cheap to make for a small input (the fuzzer makes one per run).
class LineSource {
 public:
  LineSource(std::string name, ReadBytes read) : name_(std::move(name)), read_(std::move(read)) {}

  // The next line without its "\n" or "\r\n"; false at the end of the input.
  bool next(std::string_view& line) {
    for (;;) {
      const std::size_t pending = end_ - begin_;
      const char* first = buffer_.get() + begin_;
      if (const void* newline = pending > 0 ? std::memchr(first, '\n', pending) : nullptr) {
        const auto length = static_cast<std::size_t>(static_cast<const char*>(newline) - first);
        begin_ += length + 1;
        return take(line, first, length);
      }
      if (eof_) {
        if (pending == 0) return false;
        begin_ = end_;
        return take(line, first, pending);
      }
      if (pending > kMaxLineBytes) too_long();
      make_room(pending);
      std::string error;
      const std::size_t got = read_(buffer_.get() + end_, capacity_ - end_, error);
      if (!error.empty()) throw InputError(name_, line_ + 1, "cannot read: " + error);
      if (got == 0) eof_ = true;
      end_ += got;
      bytes_loaded_ += got;
    }
  }

  const std::string& name() const { return name_; }

  std::uint64_t line_number() const { return line_; }

  std::uint64_t bytes_consumed() const { return bytes_loaded_ - (end_ - begin_); }

 private:
  // Moves the `pending` bytes of an unfinished line to the front, growing the buffer while they
  // would fill more than half of it, so that every read gets at least half a chunk.
  void make_room(std::size_t pending) {
    if (capacity_ == 0 || pending > capacity_ / 2) {
      const std::size_t size = std::max(kChunkBytes, 2 * capacity_);
      auto grown = std::make_unique_for_overwrite<char[]>(size);
      if (pending > 0) std::memcpy(grown.get(), buffer_.get() + begin_, pending);
      buffer_ = std::move(grown);
      capacity_ = size;
    } else if (pending > 0) {
      std::memmove(buffer_.get(), buffer_.get() + begin_, pending);
    }
    begin_ = 0;
    end_ = pending;
  }

  bool take(std::string_view& line, const char* first, std::size_t length) {
    if (length > kMaxLineBytes) too_long();
    ++line_;
    if (length > 0 && first[length - 1] == '\r') --length;
    line = std::string_view(first, length);
    return true;
  }

  [[noreturn]] void too_long() const {
    throw InputError(name_, line_ + 1,
                     "line is longer than " + std::to_string(kMaxLineBytes) + " bytes");
  }

  std::string name_;
  ReadBytes read_;
  std::unique_ptr<char[]> buffer_;
  std::size_t capacity_ = 0;
  std::size_t begin_ = 0;
  std::size_t end_ = 0;
  bool eof_ = false;
  std::uint64_t line_ = 0;
  std::uint64_t bytes_loaded_ = 0;
};

LineSource file_lines(const std::filesystem::path& path) {
  std::string name = path.string();
  FilePtr opened(std::fopen(path.c_str(), "rb"));
  if (!opened) throw InputError(name, 0, std::string("cannot open: ") + std::strerror(errno));
  // Shared: ReadBytes is a std::function, which must be copyable.
  std::shared_ptr<std::FILE> file = std::move(opened);
  auto read = [file](char* buffer, std::size_t size, std::string& error) {
    const std::size_t got = std::fread(buffer, 1, size, file.get());
    if (got == 0 && std::ferror(file.get()) != 0) error = std::strerror(errno);
    return got;
  };
  return LineSource(std::move(name), std::move(read));
}

LineSource stream_lines(std::istream& in, std::string name) {
  auto read = [&in](char* buffer, std::size_t size, std::string& error) {
    in.read(buffer, static_cast<std::streamsize>(size));
    if (in.bad()) error = "the stream failed";
    return static_cast<std::size_t>(in.gcount());
  };
  return LineSource(std::move(name), std::move(read));
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Reader

struct SessionReader::Impl {
  std::filesystem::path path;
  LineSource lines;
  SessionHeader header;
  std::array<double, 2> last_t{kNoTime, kNoTime};
  std::uint64_t frame_line = 0;
  // Between a foot's successive frames, the first ones only; a fixed array, as next() must not
  // allocate.
  std::array<double, kRateSpacings> spacings_s{};
  std::size_t spacing_count = 0;

  explicit Impl(LineSource source) : path(source.name()), lines(std::move(source)) {
    read_header();
  }

  [[noreturn]] void fail(std::uint64_t line, std::string reason) const {
    throw InputError(lines.name(), line, std::move(reason));
  }

  void read_header();
  void apply_metadata(std::string_view key, std::string_view value, std::uint64_t line,
                      std::array<std::uint64_t, kKeyCount>& seen);
  void check_column_header(std::string_view line) const;
  void parse_frame(std::string_view line, Frame& frame);
  [[noreturn]] void fail_field(std::string_view line, std::size_t field) const;
};

void SessionReader::Impl::read_header() {
  std::array<std::uint64_t, kKeyCount> seen{};
  std::string_view line;
  for (;;) {
    if (!lines.next(line)) {
      if (lines.line_number() == 0) fail(0, "file is empty");
      fail(lines.line_number(), "file ends before the column header");
    }
    if (lines.line_number() == 1 && line.starts_with(kBom)) line.remove_prefix(kBom.size());
    if (line.empty() || line.front() != '#') break;
    const auto entry = split_metadata(line);
    if (!entry)
      fail(lines.line_number(), "metadata line " + quote(line) + " is not '# key: value'");
    apply_metadata(entry->first, entry->second, lines.line_number(), seen);
  }

  const std::uint64_t header_line = lines.line_number();
  if (seen[static_cast<std::size_t>(Key::Version)] == 0) {
    fail(header_line, "missing version: no '# gaitmon-session: 1' line before the column header");
  }
  for (Key key : {Key::InsoleSize, Key::SampleRate, Key::Sensors}) {
    if (seen[static_cast<std::size_t>(key)] == 0) {
      fail(header_line, "missing required key '" +
                            std::string(kKeyNames[static_cast<std::size_t>(key)]) +
                            "' before the column header");
    }
  }
  const std::size_t expected = session_sensor_count(header.insole_size);
  if (header.sensors != expected) {
    fail(seen[static_cast<std::size_t>(Key::Sensors)],
         "sensors is " + std::to_string(header.sensors) + " but insole size " +
             std::string(insole_size_name(header.insole_size)) + " has " +
             std::to_string(expected) + " sensors");
  }
  check_column_header(line);
}

void SessionReader::Impl::apply_metadata(std::string_view key, std::string_view value,
                                         std::uint64_t line,
                                         std::array<std::uint64_t, kKeyCount>& seen) {
  const auto known = known_key(key);
  if (!known) {
    header.extra.emplace_back(key, value);
    return;
  }
  std::uint64_t& first = seen[static_cast<std::size_t>(*known)];
  if (first != 0) {
    fail(line,
         "duplicate key '" + std::string(key) + "' (first on line " + std::to_string(first) + ")");
  }
  first = line;
  switch (*known) {
    case Key::Version:
      if (value != "1") {
        fail(line, "unknown version " + quote(value) +
                       " of gaitmon-session (this reader supports version 1)");
      }
      header.version = 1;
      break;
    case Key::InsoleSize: {
      const auto size = parse_insole_size(value);
      if (!size) {
        fail(line, "unknown insole_size " + quote(value) +
                       " (expected 35-36, 37-38, 39-40, 41-42, 43-44 or 45-46)");
      }
      header.insole_size = *size;
      break;
    }
    case Key::SampleRate:
      if (!parse_positive(value, header.sample_rate_hz)) {
        fail(line, "sample_rate_hz " + quote(value) + " is not a finite number > 0");
      }
      if (header.sample_rate_hz < kMinSampleRateHz || header.sample_rate_hz > kMaxSampleRateHz) {
        fail(line, fmt::format("sample_rate_hz {} is outside [{}, {}] Hz", quote(value),
                               kMinSampleRateHz, kMaxSampleRateHz));
      }
      break;
    case Key::Sensors: {
      const auto count = parse_count(value);
      if (!count) fail(line, "sensors " + quote(value) + " is not a whole number");
      header.sensors = *count;
      break;
    }
    case Key::Subject:
      header.subject = std::string(value);
      break;
    case Key::RecordedAt:
      header.recorded_at = std::string(value);
      break;
    case Key::Note:
      header.note = std::string(value);
      break;
    case Key::BodyMass: {
      double mass = 0.0;
      if (!parse_positive(value, mass)) {
        fail(line, "body_mass_kg " + quote(value) + " is not a finite number > 0");
      }
      header.body_mass_kg = mass;
      break;
    }
  }
}

void SessionReader::Impl::check_column_header(std::string_view line) const {
  const std::string expected = column_header(header.sensors);
  if (line == expected) return;
  const auto found = split_commas(line);
  const auto wanted = split_commas(expected);
  if (found.size() != wanted.size()) {
    fail(lines.line_number(), "column header has " + std::to_string(found.size()) +
                                  " columns, expected " + std::to_string(wanted.size()) +
                                  " (t_s,foot,s1,...,s" + std::to_string(header.sensors) + ")");
  }
  std::size_t i = 0;
  while (found[i] == wanted[i]) ++i;
  fail(lines.line_number(), "column header: column " + std::to_string(i + 1) + " is " +
                                quote(found[i]) + ", expected '" + std::string(wanted[i]) + "'");
}

void SessionReader::Impl::parse_frame(std::string_view line, Frame& frame) {
  const std::size_t n = header.sensors;
  const char* p = line.data();
  const char* const end = p + line.size();

  const auto* comma = static_cast<const char*>(std::memchr(p, ',', line.size()));
  if (comma == nullptr) fail_field(line, 0);
  double t = 0.0;
  if (!parse_finite(std::string_view(p, static_cast<std::size_t>(comma - p)), t)) {
    fail_field(line, 0);
  }
  if (std::abs(t) > kMaxSessionTimeS) {
    fail(lines.line_number(),
         fmt::format("t_s {} is more than a day ({} s) from the start of the recording, longer "
                     "than any session: the time is corrupt",
                     format_double(t), kMaxSessionTimeS));
  }
  p = comma + 1;

  if (end - p < 2 || (p[0] != 'L' && p[0] != 'R') || p[1] != ',') fail_field(line, 1);
  const std::size_t foot = p[0] == 'L' ? 0 : 1;
  p += 2;

  if (frame.bits.size() != n) frame.bits.resize(n);
  std::uint8_t* out = frame.bits.data();
  for (std::size_t i = 0;;) {
    if (p == end) fail_field(line, i + 2);
    unsigned digit = static_cast<unsigned char>(*p) - unsigned{'0'};
    if (digit > 9) fail_field(line, i + 2);
    unsigned value = digit;
    ++p;
    while (p != end && (digit = static_cast<unsigned char>(*p) - unsigned{'0'}) <= 9) {
      value = value * 10 + digit;
      if (value > 255) fail_field(line, i + 2);
      ++p;
    }
    out[i] = static_cast<std::uint8_t>(value);
    if (++i == n) break;
    if (p == end || *p != ',') fail_field(line, i + 1);
    ++p;
  }
  if (p != end) fail_field(line, n + 1);

  if (!(t > last_t[foot])) {
    fail(lines.line_number(), "t_s " + format_double(t) + " does not increase for foot " +
                                  (foot == 0 ? "L" : "R") + " (previous " +
                                  format_double(last_t[foot]) + ")");
  }
  if (last_t[foot] != kNoTime && spacing_count < kRateSpacings) {
    spacings_s[spacing_count++] = t - last_t[foot];
  }
  last_t[foot] = t;
  frame.t_s = t;
  frame.foot = foot == 0 ? Foot::Left : Foot::Right;
}

// The slow path of parse_frame: works out what is wrong with a line, checking the column count
// first since a missing or extra comma makes every later field look wrong.
void SessionReader::Impl::fail_field(std::string_view line, std::size_t field) const {
  const std::uint64_t at = lines.line_number();
  const auto fields = split_commas(line);
  if (fields.size() != header.sensors + 2) {
    fail(at, "expected " + std::to_string(header.sensors + 2) + " columns (sensors + 2), found " +
                 std::to_string(fields.size()));
  }
  const std::string_view text = fields[field];
  if (field == 0) fail(at, "column t_s: " + quote(text) + " is not a finite decimal number");
  if (field == 1) fail(at, "column foot: " + quote(text) + " is not L or R");
  const std::string column = "column s" + std::to_string(field - 1) + ": ";
  if (text.empty()) fail(at, column + "empty value (expected an integer 0..255)");
  if (std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    fail(at, column + "value " + std::string(text.substr(0, 40)) + " is outside 0..255");
  }
  fail(at, column + quote(text) + " is not an integer 0..255");
}

SessionReader::SessionReader(const std::filesystem::path& path)
    : impl_(std::make_unique<Impl>(file_lines(path))) {}

SessionReader::SessionReader(std::istream& in, std::string name)
    : impl_(std::make_unique<Impl>(stream_lines(in, std::move(name)))) {}

SessionReader::~SessionReader() = default;

const SessionHeader& SessionReader::header() const {
  return impl_->header;
}

const std::filesystem::path& SessionReader::path() const {
  return impl_->path;
}

bool SessionReader::next(Frame& frame) {
  std::string_view line;
  if (!impl_->lines.next(line)) return false;
  if (line.empty()) {
    // Blank lines may only close the file; one followed by data would hide a gap.
    const std::uint64_t blank = impl_->lines.line_number();
    while (impl_->lines.next(line)) {
      if (!line.empty()) {
        impl_->fail(blank, "empty line in the middle of the frames (more data on line " +
                               std::to_string(impl_->lines.line_number()) + ")");
      }
    }
    return false;
  }
  impl_->parse_frame(line, frame);
  impl_->frame_line = impl_->lines.line_number();
  return true;
}

std::uint64_t SessionReader::line() const {
  return impl_->frame_line;
}

std::uint64_t SessionReader::bytes_read() const {
  return impl_->lines.bytes_consumed();
}

std::optional<double> SessionReader::timestamp_rate_hz() const {
  if (impl_->spacing_count < 10) return std::nullopt;
  std::vector<double> sorted(
      impl_->spacings_s.begin(),
      impl_->spacings_s.begin() + static_cast<std::ptrdiff_t>(impl_->spacing_count));
  const auto middle = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), middle, sorted.end());
  return 1.0 / *middle;
}

void warn_on_rate_mismatch(const SessionReader& reader) {
  const double header_hz = reader.header().sample_rate_hz;
  if (const auto rate = reader.timestamp_rate_hz();
      rate && std::abs(*rate / header_hz - 1.0) > 0.1) {
    spdlog::warn(
        "{}: the header says sample_rate_hz {}, but the times show {:.4g} Hz per foot (the median "
        "spacing of a foot's frames): the step detector's windows are in frames, so correct the "
        "header if the times are right",
        reader.path().string(), header_hz, *rate);
  }
}

std::uint64_t check_whole_session(const std::filesystem::path& path) {
  SessionReader reader(path);
  Frame frame;
  std::uint64_t frames = 0;
  while (reader.next(frame)) ++frames;
  if (frames == 0) throw InputError(path.string(), 0, "no frames");
  warn_on_rate_mismatch(reader);
  return frames;
}

// ---------------------------------------------------------------------------------------------
// Writer

std::string header_value_problem(std::string_view value) {
  // The reader trims blanks around a value and ends it at a line break, so these would not
  // read back as written.
  if (value.find_first_of("\r\n") != std::string_view::npos) return "contains a line break";
  if (!value.empty() && (is_blank(value.front()) || is_blank(value.back()))) {
    return "starts or ends with a blank";
  }
  return {};
}

namespace {

constexpr std::size_t kWriteBufferBytes = std::size_t{1} << 20;

// ",0" ... ",255" with their lengths; four bytes are always copied so each entry is padded.
struct ValueTexts {
  std::array<std::array<char, 4>, 256> text{};
  std::array<std::uint8_t, 256> size{};
};

constexpr ValueTexts make_value_texts() {
  ValueTexts table;
  for (unsigned v = 0; v < 256; ++v) {
    auto& t = table.text[v];
    t[0] = ',';
    if (v >= 100) {
      t[1] = static_cast<char>('0' + v / 100);
      t[2] = static_cast<char>('0' + v / 10 % 10);
      t[3] = static_cast<char>('0' + v % 10);
      table.size[v] = 4;
    } else if (v >= 10) {
      t[1] = static_cast<char>('0' + v / 10);
      t[2] = static_cast<char>('0' + v % 10);
      table.size[v] = 3;
    } else {
      t[1] = static_cast<char>('0' + v);
      table.size[v] = 2;
    }
  }
  return table;
}

constexpr ValueTexts kValueTexts = make_value_texts();

void check_text_value(std::string_view key, std::string_view value) {
  if (const std::string why = header_value_problem(value); !why.empty()) {
    throw std::invalid_argument("session header '" + std::string(key) + "' " + why);
  }
}

void check_header(const SessionHeader& header) {
  if (header.version != 1) {
    throw std::invalid_argument("session header: version " + std::to_string(header.version) +
                                " cannot be written (only version 1)");
  }
  const std::size_t expected = session_sensor_count(header.insole_size);
  if (header.sensors != expected) {
    throw std::invalid_argument(
        "session header: sensors is " + std::to_string(header.sensors) + " but insole size " +
        std::string(insole_size_name(header.insole_size)) + " has " + std::to_string(expected));
  }
  if (!(header.sample_rate_hz >= kMinSampleRateHz && header.sample_rate_hz <= kMaxSampleRateHz)) {
    throw std::invalid_argument(fmt::format("session header: sample_rate_hz must be in [{}, {}]",
                                            kMinSampleRateHz, kMaxSampleRateHz));
  }
  if (header.body_mass_kg &&
      (!std::isfinite(*header.body_mass_kg) || *header.body_mass_kg <= 0.0)) {
    throw std::invalid_argument("session header: body_mass_kg must be finite and > 0");
  }
  if (header.subject) check_text_value("subject", *header.subject);
  if (header.recorded_at) check_text_value("recorded_at", *header.recorded_at);
  if (header.note) check_text_value("note", *header.note);
  for (const auto& [key, value] : header.extra) {
    if (key.empty() || !std::all_of(key.begin(), key.end(), is_key_char)) {
      throw std::invalid_argument("session header: extra key '" + key +
                                  "' is not made of letters, digits, '_', '-' or '.'");
    }
    if (known_key(key)) {
      throw std::invalid_argument("session header: extra key '" + key +
                                  "' is a key of the format itself");
    }
    check_text_value(key, value);
  }
}

std::string header_text(const SessionHeader& header) {
  std::string text = "# gaitmon-session: 1\n# insole_size: ";
  text += insole_size_name(header.insole_size);
  text += "\n# sample_rate_hz: " + format_double(header.sample_rate_hz);
  text += "\n# sensors: " + std::to_string(header.sensors) + "\n";
  if (header.subject) text += "# subject: " + *header.subject + "\n";
  if (header.recorded_at) text += "# recorded_at: " + *header.recorded_at + "\n";
  if (header.note) text += "# note: " + *header.note + "\n";
  if (header.body_mass_kg) text += "# body_mass_kg: " + format_double(*header.body_mass_kg) + "\n";
  for (const auto& [key, value] : header.extra) text += "# " + key + ": " + value + "\n";
  text += column_header(header.sensors) + "\n";
  return text;
}

}  // namespace

struct SessionWriter::Impl {
  std::string name;
  FilePtr file;
  std::vector<char> buffer;
  std::size_t used = 0;
  std::size_t sensors = 0;
  std::size_t max_line = 0;
  std::array<double, 2> last_t{kNoTime, kNoTime};

  [[noreturn]] void fail_io(int error) const {
    throw std::runtime_error("cannot write " + name + ": " + std::strerror(error));
  }

  // The error of the last failed stdio call; some C libraries leave errno unset.
  static int last_error() { return errno != 0 ? errno : EIO; }

  void flush() {
    const bool complete = std::fwrite(buffer.data(), 1, used, file.get()) == used;
    used = 0;
    if (!complete) fail_io(last_error());
  }
};

SessionWriter::SessionWriter(const std::filesystem::path& path, const SessionHeader& header)
    : impl_(std::make_unique<Impl>()) {
  check_header(header);
  Impl& w = *impl_;
  w.name = path.string();
  w.sensors = header.sensors;
  // Time (at most 24 characters), foot, up to ",255" per sensor, the newline and the padding of
  // the last four-byte copy.
  w.max_line = 32 + 2 + 4 * w.sensors + 1 + 4;
  w.file.reset(std::fopen(path.c_str(), "wb"));
  if (!w.file) {
    throw std::runtime_error("cannot create " + w.name + ": " + std::strerror(errno));
  }
  const std::string text = header_text(header);
  w.buffer.resize(std::max(kWriteBufferBytes, text.size()) + w.max_line);
  std::memcpy(w.buffer.data(), text.data(), text.size());
  w.used = text.size();
}

SessionWriter::~SessionWriter() {
  try {
    close();
  } catch (const std::exception&) {
    // A destructor must not throw; callers who need the outcome call close() themselves.
  }
}

void SessionWriter::write(const Frame& frame) {
  Impl& w = *impl_;
  if (!w.file) throw std::runtime_error("cannot write " + w.name + ": the writer is closed");
  if (frame.bits.size() != w.sensors) {
    throw std::invalid_argument("session " + w.name + ": frame has " +
                                std::to_string(frame.bits.size()) + " sensor values, expected " +
                                std::to_string(w.sensors));
  }
  const std::size_t foot = frame.foot == Foot::Left ? 0 : 1;
  if (std::abs(frame.t_s) > kMaxSessionTimeS) {
    throw std::invalid_argument(fmt::format(
        "session {}: t_s {} is more than a day ({} s) from the start, which the reader refuses",
        w.name, format_double(frame.t_s), kMaxSessionTimeS));
  }
  if (!std::isfinite(frame.t_s) || !(frame.t_s > w.last_t[foot])) {
    throw std::invalid_argument(
        "session " + w.name + ": t_s " + format_double(frame.t_s) + " does not increase for foot " +
        std::string(foot_name(frame.foot)) + " (previous " + format_double(w.last_t[foot]) + ")");
  }
  if (w.used + w.max_line > w.buffer.size()) w.flush();

  char* out = w.buffer.data() + w.used;
  out = std::to_chars(out, out + 32, frame.t_s).ptr;
  *out++ = ',';
  *out++ = foot == 0 ? 'L' : 'R';
  for (std::uint8_t value : frame.bits) {
    std::memcpy(out, kValueTexts.text[value].data(), 4);
    out += kValueTexts.size[value];
  }
  *out++ = '\n';
  w.used = static_cast<std::size_t>(out - w.buffer.data());
  w.last_t[foot] = frame.t_s;
}

void SessionWriter::close() {
  Impl& w = *impl_;
  if (!w.file) return;
  int error = 0;
  if (std::fwrite(w.buffer.data(), 1, w.used, w.file.get()) != w.used) error = Impl::last_error();
  w.used = 0;
  if (std::fclose(w.file.release()) != 0 && error == 0) error = Impl::last_error();
  if (error != 0) w.fail_io(error);
}

}  // namespace gaitmon
