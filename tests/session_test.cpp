// Tests of the session CSV v1 reader and writer (shared/docs/session-format.md).
#include "gaitmon/session.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <nlohmann/json.hpp>
#include <ostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "allocation_count.hpp"
#include "gaitmon/error.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

using ::testing::HasSubstr;
namespace fs = std::filesystem;

// Size 35-36 has 93 sensors: the smallest file the format allows.
constexpr std::size_t kN = 93;

std::string meta(const std::string& size = "35-36", const std::string& sensors = "93") {
  return "# gaitmon-session: 1\n# insole_size: " + size +
         "\n# sample_rate_hz: 100\n# sensors: " + sensors + "\n";
}

std::string columns(std::size_t n = kN) {
  std::string text = "t_s,foot";
  for (std::size_t i = 1; i <= n; ++i) text += ",s" + std::to_string(i);
  return text + "\n";
}

// A frame line whose sensor k (1-based) reads `values[k-1]` as text.
std::string frame_line(const std::string& t, const std::string& foot,
                       const std::vector<std::string>& values) {
  std::string text = t + "," + foot;
  for (const auto& v : values) text += "," + v;
  return text + "\n";
}

std::vector<std::string> zeros(std::size_t n = kN) {
  return std::vector<std::string>(n, "0");
}

const fs::path& scratch() {
  static const fs::path dir = test::scratch_dir("session");
  return dir;
}

// Some files here are megabytes; they go when the test program ends.
class RemoveScratch : public ::testing::Environment {
 public:
  void TearDown() override { fs::remove_all(scratch()); }
};
[[maybe_unused]] ::testing::Environment* const kRemoveScratch =
    ::testing::AddGlobalTestEnvironment(new RemoveScratch);

fs::path write_file(const std::string& name, const std::string& text) {
  return test::write_text(scratch() / name, text);
}

std::string file_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Reads everything and checks the InputError it must raise: its line, its source and reason.
void expect_reader_error(const std::function<SessionReader()>& open, const std::string& source,
                         std::uint64_t line, const std::string& reason) {
  SCOPED_TRACE(source);
  try {
    SessionReader reader = open();
    Frame frame;
    while (reader.next(frame)) {
    }
    ADD_FAILURE() << "no InputError; expected line " << line << ": " << reason;
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), line) << e.what();
    EXPECT_EQ(e.file(), source);
    EXPECT_THAT(e.what(), HasSubstr(source + (line > 0 ? ":" + std::to_string(line) : "") + ": "));
    EXPECT_THAT(e.what(), HasSubstr(reason));
  }
}

// The file by its path, and its bytes through a stream under a label: one parser, one error.
void expect_input_error(const fs::path& path, std::uint64_t line, const std::string& reason) {
  expect_reader_error([&] { return SessionReader(path); }, path.string(), line, reason);
  std::istringstream in(file_text(path));
  expect_reader_error([&] { return SessionReader(in, "stream of " + path.filename().string()); },
                      "stream of " + path.filename().string(), line, reason);
}

// ---------------------------------------------------------------------------------------------
// Good input

std::string hand_written_file(const std::string& eol) {
  auto values = zeros();
  values[0] = "255";
  values[1] = "007";
  values[16] = "42";
  values[92] = "9";
  std::string text =
      "# gaitmon-session: 1\n# sensors: 93\n# subject: P-112\n# insole_size: 35-36\n"
      "# sample_rate_hz: 99.5\n# zeta: last\n#weird.key:  spaced value  \n"
      "# body_mass_kg: 71.25\n# recorded_at: 2024-03-01T10:15:00Z\n"
      "# note: walk: fast\n" +
      columns() + frame_line("0.000", "L", values) + frame_line("1e-3", "R", zeros());
  std::string converted;
  for (char c : text) {
    if (c == '\n') {
      converted += eol;
    } else {
      converted += c;
    }
  }
  return converted;
}

void expect_hand_written_content(SessionReader& reader) {
  const SessionHeader& h = reader.header();
  EXPECT_EQ(h.version, 1);
  EXPECT_EQ(h.insole_size, InsoleSize::S35_36);
  EXPECT_EQ(h.sample_rate_hz, 99.5);
  EXPECT_EQ(h.sensors, 93u);
  EXPECT_EQ(h.subject, "P-112");
  EXPECT_EQ(h.recorded_at, "2024-03-01T10:15:00Z");
  EXPECT_EQ(h.note, "walk: fast");
  EXPECT_EQ(h.body_mass_kg, 71.25);
  const std::vector<std::pair<std::string, std::string>> extra{{"zeta", "last"},
                                                               {"weird.key", "spaced value"}};
  EXPECT_EQ(h.extra, extra);

  Frame frame;
  ASSERT_TRUE(reader.next(frame));
  EXPECT_EQ(reader.line(), 12u);
  EXPECT_EQ(frame.t_s, 0.0);
  EXPECT_EQ(frame.foot, Foot::Left);
  ASSERT_EQ(frame.bits.size(), 93u);
  EXPECT_EQ(frame.bits[0], 255);
  EXPECT_EQ(frame.bits[1], 7);
  EXPECT_EQ(frame.bits[2], 0);
  EXPECT_EQ(frame.bits[16], 42);
  EXPECT_EQ(frame.bits[92], 9);
  ASSERT_TRUE(reader.next(frame));
  EXPECT_EQ(reader.line(), 13u);
  EXPECT_EQ(frame.t_s, 0.001);
  EXPECT_EQ(frame.foot, Foot::Right);
  EXPECT_EQ(frame.bits, std::vector<std::uint8_t>(93, 0));
  EXPECT_FALSE(reader.next(frame));
  EXPECT_FALSE(reader.next(frame));
}

void expect_hand_written_content(const fs::path& path) {
  SessionReader reader(path);
  EXPECT_EQ(reader.path(), path);
  expect_hand_written_content(reader);
}

TEST(SessionReader, ReadsAHandWrittenFile) {
  expect_hand_written_content(write_file("lf.csv", hand_written_file("\n")));
}

TEST(SessionReader, ReadsCrLfLineEnds) {
  expect_hand_written_content(write_file("crlf.csv", hand_written_file("\r\n")));
}

TEST(SessionReader, AcceptsAUtf8ByteOrderMark) {
  expect_hand_written_content(write_file("bom.csv", "\xEF\xBB\xBF" + hand_written_file("\n")));
}

TEST(SessionReader, AcceptsAFileWithoutFinalNewline) {
  std::string text = hand_written_file("\n");
  text.pop_back();
  expect_hand_written_content(write_file("no-final-newline.csv", text));
}

TEST(SessionReader, AcceptsBlankLinesAtTheEnd) {
  expect_hand_written_content(write_file("blank-end.csv", hand_written_file("\n") + "\n\n"));
  expect_hand_written_content(write_file("blank-end-crlf.csv", hand_written_file("\r\n") + "\r\n"));
}

TEST(SessionReader, ReadsAStreamUnderTheNameGiven) {
  for (const char* eol : {"\n", "\r\n"}) {
    std::istringstream in("\xEF\xBB\xBF" + hand_written_file(eol));
    SessionReader reader(in, "walk-7 (upload)");
    EXPECT_EQ(reader.path(), fs::path("walk-7 (upload)"));
    expect_hand_written_content(reader);
  }
}

// Hands out `text`, then fails as a device or network stream would (std::filebuf throws from
// underflow on a read error, and the stream turns that into badbit).
class FailingBuffer : public std::streambuf {
 public:
  explicit FailingBuffer(std::string text) : text_(std::move(text)) {}

 protected:
  int_type underflow() override {
    if (given_) throw std::runtime_error("device gone");
    given_ = true;
    setg(text_.data(), text_.data(), text_.data() + text_.size());
    return traits_type::to_int_type(text_.front());
  }

 private:
  std::string text_;
  bool given_ = false;
};

TEST(SessionReader, AStreamThatFailsIsAnErrorAtTheLineItCutShort) {
  // Longer than the reader's chunks, so frames come through before the failure.
  std::string text = meta() + columns();
  constexpr int kFrames = 1000;
  for (int i = 0; i < kFrames; ++i) text += frame_line(std::to_string(i) + ".5", "L", zeros());
  FailingBuffer buffer(text);
  std::istream in(&buffer);
  SessionReader reader(in, "live upload");
  Frame frame;
  int frames = 0;
  try {
    while (reader.next(frame)) {
      ASSERT_EQ(frame.t_s, frames + 0.5);
      ++frames;
    }
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_GT(frames, 0);
    EXPECT_LT(frames, kFrames);
    EXPECT_EQ(e.file(), "live upload");
    EXPECT_EQ(e.line(), 5u + static_cast<std::uint64_t>(frames) + 1u);
    EXPECT_THAT(e.what(), HasSubstr("live upload:" + std::to_string(e.line()) +
                                    ": cannot read: the stream failed"));
  }
}

TEST(SessionReader, HeaderOnlyFileHasNoFrames) {
  SessionReader reader(write_file("header-only.csv", meta() + columns()));
  Frame frame;
  EXPECT_FALSE(reader.next(frame));
  EXPECT_EQ(reader.line(), 0u);
}

TEST(SessionReader, BytesReadFollowsTheLinesConsumed) {
  const std::string head = meta() + columns();
  const std::string first = frame_line("0.5", "L", zeros());
  const std::string second = frame_line("0.5", "R", zeros());
  SessionReader reader(write_file("bytes.csv", head + first + second));
  EXPECT_EQ(reader.bytes_read(), head.size());
  Frame frame;
  ASSERT_TRUE(reader.next(frame));
  EXPECT_EQ(reader.bytes_read(), head.size() + first.size());
  ASSERT_TRUE(reader.next(frame));
  EXPECT_FALSE(reader.next(frame));
  EXPECT_EQ(reader.bytes_read(), head.size() + first.size() + second.size());
}

TEST(SessionReader, FeetInterleaveInAnyOrder) {
  // Each foot increases on its own; across feet the times go back and forth.
  const std::string text = meta() + columns() + frame_line("0.5", "R", zeros()) +
                           frame_line("0.2", "L", zeros()) + frame_line("0.3", "L", zeros()) +
                           frame_line("0.4", "L", zeros()) + frame_line("0.6", "R", zeros()) +
                           frame_line("0.45", "L", zeros());
  const auto frames = test::file_frames(write_file("interleaved.csv", text));
  ASSERT_EQ(frames.size(), 6u);
  const std::vector<double> t{0.5, 0.2, 0.3, 0.4, 0.6, 0.45};
  const std::vector<Foot> feet{Foot::Right, Foot::Left,  Foot::Left,
                               Foot::Left,  Foot::Right, Foot::Left};
  for (std::size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].t_s, t[i]) << i;
    EXPECT_EQ(frames[i].foot, feet[i]) << i;
  }
}

TEST(SessionReader, NextAllocatesNothingAfterTheFirstFrame) {
  std::string text = meta() + columns();
  for (int i = 0; i < 200; ++i) {
    auto values = zeros();
    values[static_cast<std::size_t>(i) % kN] = std::to_string(i);
    text += frame_line(std::to_string(i) + ".25", i % 2 == 0 ? "L" : "R", values);
  }
  SessionReader reader(write_file("allocations.csv", text));
  Frame frame;
  const std::uint64_t at_start = test::allocations.load();
  ASSERT_TRUE(reader.next(frame));
  // The first frame sizes the buffer, which shows the counter sees the reader's allocations.
  EXPECT_GE(test::allocations.load() - at_start, 1U);
  const std::uint8_t* storage = frame.bits.data();
  const std::uint64_t before = test::allocations.load();
  int frames = 1;
  while (reader.next(frame)) ++frames;
  EXPECT_EQ(test::allocations.load() - before, 0U);
  EXPECT_EQ(frames, 200);
  EXPECT_EQ(frame.bits.data(), storage);
  EXPECT_EQ(frame.bits[199 % kN], 199);
}

// ---------------------------------------------------------------------------------------------
// Bad header

TEST(SessionReaderBadHeader, EmptyFile) {
  expect_input_error(write_file("empty.csv", ""), 0, "empty");
}

TEST(SessionReaderBadHeader, EndsBeforeTheColumnHeader) {
  expect_input_error(write_file("truncated.csv", meta()), 4, "ends before the column header");
}

TEST(SessionReaderBadHeader, MissingVersion) {
  const std::string text =
      "# insole_size: 35-36\n# sample_rate_hz: 100\n# sensors: 93\n" + columns();
  expect_input_error(write_file("no-version.csv", text), 4, "missing version");
}

TEST(SessionReaderBadHeader, NotASessionFileAtAll) {
  expect_input_error(write_file("plain.csv", "a,b,c\n1,2,3\n"), 1, "missing version");
}

TEST(SessionReaderBadHeader, UnknownVersion) {
  const std::string text = "# gaitmon-session: 2\n# insole_size: 35-36\n" + columns();
  expect_input_error(write_file("version-2.csv", text), 1, "unknown version '2'");
}

TEST(SessionReaderBadHeader, UnknownInsoleSize) {
  expect_input_error(write_file("size.csv", meta("47-48") + columns()), 2,
                     "unknown insole_size '47-48'");
}

TEST(SessionReaderBadHeader, SensorsDisagreeWithTheSize) {
  expect_input_error(write_file("sensors-94.csv", meta("35-36", "94") + columns(94)), 4,
                     "sensors is 94 but insole size 35-36 has 93 sensors");
  // The seed's Table 1 count for 41-42 is not the format's.
  expect_input_error(write_file("sensors-130.csv", meta("41-42", "130") + columns(130)), 4,
                     "sensors is 130 but insole size 41-42 has 129 sensors");
}

TEST(SessionReaderBadHeader, SensorsNotAWholeNumber) {
  expect_input_error(write_file("sensors-text.csv", meta("35-36", "93.0") + columns()), 4,
                     "sensors '93.0' is not a whole number");
}

TEST(SessionReaderBadHeader, SampleRateNotAPositiveNumber) {
  for (const std::string rate : {"0", "-100", "fast", "inf", ""}) {
    const std::string text =
        "# gaitmon-session: 1\n# insole_size: 35-36\n# sample_rate_hz: " + rate +
        "\n# sensors: 93\n" + columns();
    expect_input_error(write_file("rate.csv", text), 3, "sample_rate_hz '" + rate + "' is not");
  }
}

TEST(SessionReaderBadHeader, SampleRateOutsideTheRangeTheStepDetectorWorksAt) {
  for (const std::string rate : {"1", "9.99", "10000.5", "1e300"}) {
    const std::string text =
        "# gaitmon-session: 1\n# insole_size: 35-36\n# sample_rate_hz: " + rate +
        "\n# sensors: 93\n" + columns();
    expect_input_error(write_file("rate-range.csv", text), 3,
                       "sample_rate_hz '" + rate + "' is outside [10, 10000] Hz");
  }
  for (const std::string rate : {"10", "10000"}) {
    const std::string text =
        "# gaitmon-session: 1\n# insole_size: 35-36\n# sample_rate_hz: " + rate +
        "\n# sensors: 93\n" + columns();
    SessionReader reader(write_file("rate-edge.csv", text));
    EXPECT_EQ(reader.header().sample_rate_hz, std::stod(rate));
  }
}

TEST(SessionReaderBadHeader, BodyMassNotAPositiveNumber) {
  expect_input_error(write_file("mass.csv", meta() + "# body_mass_kg: -70\n" + columns()), 5,
                     "body_mass_kg '-70' is not a finite number > 0");
}

TEST(SessionReaderBadHeader, MissingInsoleSize) {
  const std::string text =
      "# gaitmon-session: 1\n# sample_rate_hz: 100\n# sensors: 93\n" + columns();
  expect_input_error(write_file("no-size.csv", text), 4, "missing required key 'insole_size'");
}

TEST(SessionReaderBadHeader, MissingSampleRate) {
  const std::string text =
      "# gaitmon-session: 1\n# insole_size: 35-36\n# sensors: 93\n" + columns();
  expect_input_error(write_file("no-rate.csv", text), 4, "missing required key 'sample_rate_hz'");
}

TEST(SessionReaderBadHeader, MissingSensors) {
  const std::string text =
      "# gaitmon-session: 1\n# insole_size: 35-36\n# sample_rate_hz: 100\n" + columns();
  expect_input_error(write_file("no-sensors.csv", text), 4, "missing required key 'sensors'");
}

TEST(SessionReaderBadHeader, DuplicateRequiredKey) {
  expect_input_error(write_file("dup.csv", meta() + "# insole_size: 35-36\n" + columns()), 5,
                     "duplicate key 'insole_size' (first on line 2)");
}

TEST(SessionReaderBadHeader, DuplicateOptionalKey) {
  expect_input_error(
      write_file("dup-subject.csv", meta() + "# subject: a\n# subject: b\n" + columns()), 6,
      "duplicate key 'subject' (first on line 5)");
}

TEST(SessionReaderBadHeader, MetadataLineNotKeyValue) {
  expect_input_error(write_file("comment.csv", meta() + "# just a comment\n" + columns()), 5,
                     "is not '# key: value'");
  expect_input_error(write_file("hash.csv", "#\n" + meta() + columns()), 1,
                     "is not '# key: value'");
}

TEST(SessionReaderBadHeader, ColumnHeaderWrongName) {
  std::string header = columns();
  header.replace(header.find(",s17,"), 5, ",s71,");
  expect_input_error(write_file("col-name.csv", meta() + header), 5,
                     "column header: column 19 is 's71', expected 's17'");
}

TEST(SessionReaderBadHeader, ColumnHeaderWrongCount) {
  expect_input_error(write_file("col-count.csv", meta() + columns(92)), 5,
                     "column header has 94 columns, expected 95");
}

TEST(SessionReaderBadHeader, ColumnHeaderMissing) {
  expect_input_error(write_file("col-missing.csv", meta() + frame_line("0", "L", zeros())), 5,
                     "column header: column 1 is '0', expected 't_s'");
}

TEST(SessionReaderBadHeader, FileCannotBeOpened) {
  const fs::path path = scratch() / "absent.csv";
  try {
    SessionReader reader(path);
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), 0u);
    EXPECT_EQ(e.file(), path.string());
    EXPECT_THAT(e.what(), HasSubstr("cannot open"));
  }
}

TEST(SessionReaderBadHeader, ADirectoryCannotBeRead) {
  const fs::path dir = scratch() / "a-directory.csv";
  fs::create_directories(dir);
  try {
    SessionReader reader(dir);
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), dir.string());
    EXPECT_THAT(e.what(), HasSubstr("cannot"));
  }
}

// ---------------------------------------------------------------------------------------------
// Bad frame lines: lines 6 and 7 are good (L and R at 0.5), line 8 is the bad one.

struct BadLine {
  const char* name;
  std::string line;
  std::string reason;
};

// gtest prints a case it cannot print as its bytes, padding included.
void PrintTo(const BadLine& b, std::ostream* os) {
  *os << b.name;
}

std::string with_value(std::size_t sensor, const std::string& value) {
  auto values = zeros();
  values[sensor - 1] = value;
  return frame_line("0.6", "L", values);
}

std::vector<BadLine> bad_lines() {
  auto fewer = zeros(kN - 1);
  auto more = zeros(kN + 1);
  std::string trailing_comma = frame_line("0.6", "L", zeros());
  trailing_comma.insert(trailing_comma.size() - 1, ",");
  return {
      {"ValueAbove255", with_value(17, "300"), "column s17: value 300 is outside 0..255"},
      {"Value256", with_value(1, "256"), "column s1: value 256 is outside 0..255"},
      {"ValueHuge", with_value(93, "99999999999999999999"),
       "column s93: value 99999999999999999999 is outside 0..255"},
      {"ValueNegative", with_value(3, "-1"), "column s3: '-1' is not an integer 0..255"},
      {"ValuePlusSign", with_value(3, "+1"), "column s3: '+1' is not an integer 0..255"},
      {"ValueDecimal", with_value(4, "1.5"), "column s4: '1.5' is not an integer 0..255"},
      {"ValueDecimalZero", with_value(4, "2.0"), "column s4: '2.0' is not an integer 0..255"},
      {"ValueLeadingSpace", with_value(5, " 1"), "column s5: ' 1' is not an integer 0..255"},
      {"ValueTrailingSpace", with_value(5, "1 "), "column s5: '1 ' is not an integer 0..255"},
      {"ValueLetters", with_value(6, "x"), "column s6: 'x' is not an integer 0..255"},
      {"ValueHex", with_value(6, "0x1"), "column s6: '0x1' is not an integer 0..255"},
      {"ValueWithANul",
       with_value(9, std::string("1\0"
                                 "2",
                                 3)),
       "column s9: '1\\x002' is not an integer 0..255"},
      {"ValueWithACarriageReturn", with_value(9, "1\r2"),
       "column s9: '1\\x0d2' is not an integer 0..255"},
      {"ValueEmpty", with_value(7, ""), "column s7: empty value"},
      {"LastValueEmpty", with_value(93, ""), "column s93: empty value"},
      {"LastValueJunk", with_value(93, "12x"), "column s93: '12x' is not an integer 0..255"},
      {"TooFewColumns", frame_line("0.6", "L", fewer),
       "expected 95 columns (sensors + 2), found 94"},
      {"TooManyColumns", frame_line("0.6", "L", more),
       "expected 95 columns (sensors + 2), found 96"},
      {"TrailingComma", trailing_comma, "expected 95 columns (sensors + 2), found 96"},
      {"OnlyATime", "0.6\n", "expected 95 columns (sensors + 2), found 1"},
      {"Semicolons", "0.6;L;0\n", "expected 95 columns (sensors + 2), found 1"},
      {"FootX", frame_line("0.6", "X", zeros()), "column foot: 'X' is not L or R"},
      {"FootLowercase", frame_line("0.6", "l", zeros()), "column foot: 'l' is not L or R"},
      {"FootWord", frame_line("0.6", "Left", zeros()), "column foot: 'Left' is not L or R"},
      {"FootEmpty", frame_line("0.6", "", zeros()), "column foot: '' is not L or R"},
      {"TimeText", frame_line("abc", "L", zeros()),
       "column t_s: 'abc' is not a finite decimal number"},
      {"TimeEmpty", frame_line("", "L", zeros()), "column t_s: '' is not a finite decimal number"},
      {"TimeNan", frame_line("nan", "L", zeros()),
       "column t_s: 'nan' is not a finite decimal number"},
      {"TimeInfinite", frame_line("inf", "L", zeros()),
       "column t_s: 'inf' is not a finite decimal number"},
      {"TimeTwoPoints", frame_line("0.6.1", "L", zeros()),
       "column t_s: '0.6.1' is not a finite decimal number"},
      {"TimeWithUnit", frame_line("0.6s", "L", zeros()),
       "column t_s: '0.6s' is not a finite decimal number"},
      {"TimeLeadingSpace", frame_line(" 0.6", "L", zeros()),
       "column t_s: ' 0.6' is not a finite decimal number"},
      {"TimeRepeatsForItsFoot", frame_line("0.5", "L", zeros()),
       "t_s 0.5 does not increase for foot L (previous 0.5)"},
      {"TimeGoesBackForItsFoot", frame_line("0.4", "L", zeros()),
       "t_s 0.4 does not increase for foot L (previous 0.5)"},
      {"TimeGoesBackForTheRightFoot", frame_line("0.25", "R", zeros()),
       "t_s 0.25 does not increase for foot R (previous 0.5)"},
      {"TimeHuge", frame_line("1e308", "L", zeros()),
       "t_s 1e+308 is more than a day (86400 s) from the start of the recording"},
      {"TimeJustOverADay", frame_line("86400.01", "L", zeros()),
       "t_s 86400.01 is more than a day (86400 s) from the start of the recording"},
      {"TimeADayBeforeTheStart", frame_line("-1e9", "R", zeros()),
       "t_s -1e+09 is more than a day (86400 s) from the start of the recording"},
  };
}

class SessionReaderBadLine : public ::testing::TestWithParam<BadLine> {};

TEST_P(SessionReaderBadLine, IsRejectedWithItsLineAndReason) {
  const BadLine& bad = GetParam();
  const std::string good_after = frame_line("0.7", "L", zeros());
  const std::string text = meta() + columns() + frame_line("0.5", "L", zeros()) +
                           frame_line("0.5", "R", zeros()) + bad.line + good_after;
  expect_input_error(write_file(std::string(bad.name) + ".csv", text), 8, bad.reason);
}

INSTANTIATE_TEST_SUITE_P(Rules, SessionReaderBadLine, ::testing::ValuesIn(bad_lines()),
                         [](const auto& info) { return std::string(info.param.name); });

// The rate the times show, for warn_on_rate_mismatch: a header's 100 Hz against frames 20 ms
// apart. A gap and the other foot's frames in between do not move it.
TEST(SessionReader, TimestampRateIsOneOverTheMedianSpacingOfAFootsFrames) {
  std::string text = meta() + columns();
  for (int k = 0; k < 12; ++k) {
    const double t = 0.02 * k + (k >= 8 ? 5.0 : 0.0);
    text +=
        frame_line(std::to_string(t), "L", zeros()) + frame_line(std::to_string(t), "R", zeros());
  }
  SessionReader reader(write_file("rate.csv", text));
  Frame frame;
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(reader.next(frame));
  EXPECT_FALSE(reader.timestamp_rate_hz()) << "8 spacings are too few for a rate";
  while (reader.next(frame)) {
  }
  ASSERT_TRUE(reader.timestamp_rate_hz());
  EXPECT_NEAR(*reader.timestamp_rate_hz(), 50.0, 1e-6);
}

TEST(SessionReaderBadFrames, EmptyLineInTheMiddle) {
  const std::string text =
      meta() + columns() + frame_line("0.5", "L", zeros()) + "\n" + frame_line("0.6", "L", zeros());
  expect_input_error(write_file("gap.csv", text), 7,
                     "empty line in the middle of the frames (more data on line 8)");
}

TEST(SessionReaderBadFrames, BlankLinesThenData) {
  const std::string text = meta() + columns() + frame_line("0.5", "L", zeros()) + "\r\n\r\n" +
                           frame_line("0.6", "L", zeros());
  expect_input_error(write_file("gaps.csv", text), 7,
                     "empty line in the middle of the frames (more data on line 9)");
}

TEST(SessionReaderBadFrames, OverlongLine) {
  const std::string text = meta() + columns() + frame_line("0.5", "L", zeros()) +
                           std::string(1200000, '1') + "\n" + frame_line("0.6", "L", zeros());
  expect_input_error(write_file("overlong.csv", text), 7, "line is longer than 1048576 bytes");
}

TEST(SessionReaderBadFrames, OverlongLastLineWithoutNewline) {
  const std::string text = meta() + columns() + std::string(1100000, '0');
  expect_input_error(write_file("overlong-last.csv", text), 6, "line is longer than 1048576 bytes");
}

// ---------------------------------------------------------------------------------------------
// Writer

SessionHeader full_header() {
  SessionHeader h;
  h.insole_size = InsoleSize::S41_42;
  h.sample_rate_hz = 99.87654321;
  h.sensors = 129;
  h.subject = "subject 7";
  h.recorded_at = "2024-05-17T08:30:00+02:00";
  h.note = "treadmill, 4 km/h: second try";
  h.body_mass_kg = 82.4;
  h.extra = {{"source", "lab B"}, {"device", "medilogic"}, {"empty", ""}};
  return h;
}

TEST(SessionWriter, WritesTheExactLayout) {
  const fs::path path = write_file("exact.csv", "");
  SessionHeader h;
  h.insole_size = InsoleSize::S35_36;
  h.sensors = 93;
  h.note = "n";
  h.extra = {{"k", "v"}};
  {
    SessionWriter writer(path, h);
    Frame frame{0.01, Foot::Left, std::vector<std::uint8_t>(93, 0)};
    frame.bits[0] = 5;
    frame.bits[1] = 10;
    frame.bits[2] = 255;
    writer.write(frame);
    frame.foot = Foot::Right;
    frame.t_s = 0.0;
    frame.bits.assign(93, 1);
    writer.write(frame);
  }
  std::string expected =
      "# gaitmon-session: 1\n# insole_size: 35-36\n# sample_rate_hz: 100\n# sensors: 93\n"
      "# note: n\n# k: v\n" +
      columns() + "0.01,L,5,10,255";
  for (int i = 3; i < 93; ++i) expected += ",0";
  expected += "\n0,R";
  for (int i = 0; i < 93; ++i) expected += ",1";
  expected += "\n";
  std::ifstream in(path, std::ios::binary);
  const std::string written((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(written, expected);
}

TEST(SessionWriter, RoundTripsHeaderAndFramesExactly) {
  const SessionHeader h = full_header();
  // Times that need all 17 digits, exponents and a negative start, interleaved feet.
  const std::vector<double> times{
      -0.25, 1e-5, 0.1 + 0.2, 1.0 / 3.0, 2.0 / 3.0, 12345.6789012345, kMaxSessionTimeS - 0.5};
  std::vector<Frame> frames;
  for (std::size_t i = 0; i < times.size(); ++i) {
    for (Foot foot : kFeet) {
      Frame f{times[i] + (foot == Foot::Right ? 0.004 : 0.0), foot, {}};
      for (std::size_t k = 0; k < 129; ++k)
        f.bits.push_back(static_cast<std::uint8_t>((i * 37 + k * 11) % 256));
      frames.push_back(f);
    }
  }
  const fs::path path = write_file("roundtrip.csv", "");
  {
    SessionWriter writer(path, h);
    for (const Frame& f : frames) writer.write(f);
    writer.close();
  }
  SessionReader reader(path);
  const SessionHeader& r = reader.header();
  EXPECT_EQ(r.version, 1);
  EXPECT_EQ(r.insole_size, h.insole_size);
  EXPECT_EQ(std::bit_cast<std::uint64_t>(r.sample_rate_hz),
            std::bit_cast<std::uint64_t>(h.sample_rate_hz));
  EXPECT_EQ(r.sensors, h.sensors);
  EXPECT_EQ(r.subject, h.subject);
  EXPECT_EQ(r.recorded_at, h.recorded_at);
  EXPECT_EQ(r.note, h.note);
  ASSERT_TRUE(r.body_mass_kg.has_value());
  EXPECT_EQ(std::bit_cast<std::uint64_t>(*r.body_mass_kg), std::bit_cast<std::uint64_t>(82.4));
  EXPECT_EQ(r.extra, h.extra);

  Frame f;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    ASSERT_TRUE(reader.next(f)) << i;
    EXPECT_EQ(std::bit_cast<std::uint64_t>(f.t_s), std::bit_cast<std::uint64_t>(frames[i].t_s))
        << i;
    EXPECT_EQ(f.foot, frames[i].foot) << i;
    EXPECT_EQ(f.bits, frames[i].bits) << i;
    // 4 required + 4 optional + 3 extra metadata lines, then the column header.
    EXPECT_EQ(reader.line(), 13 + i);
  }
  EXPECT_FALSE(reader.next(f));
}

TEST(SessionWriter, RoundTripsAFileSpanningManyReadChunks) {
  // About 3 MB at size 45-46, so many lines cross the reader's chunk boundaries.
  SessionHeader h;
  h.insole_size = InsoleSize::S45_46;
  h.sensors = 161;
  const fs::path path = write_file("chunks.csv", "");
  const std::size_t count = 6000;
  auto value = [](std::size_t i, std::size_t k) {
    return static_cast<std::uint8_t>((i * 7 + k * 13 + i / 3) % 256);
  };
  {
    SessionWriter writer(path, h);
    Frame f{0.0, Foot::Left, std::vector<std::uint8_t>(161)};
    for (std::size_t i = 0; i < count; ++i) {
      f.t_s = static_cast<double>(i / 2) / 100.0;
      f.foot = i % 2 == 0 ? Foot::Left : Foot::Right;
      for (std::size_t k = 0; k < 161; ++k) f.bits[k] = value(i, k);
      writer.write(f);
    }
  }
  EXPECT_GT(fs::file_size(path), 2u * 1024 * 1024);
  SessionReader reader(path);
  Frame f;
  std::size_t i = 0;
  std::size_t mismatches = 0;
  while (reader.next(f)) {
    if (f.t_s != static_cast<double>(i / 2) / 100.0) ++mismatches;
    if (f.foot != (i % 2 == 0 ? Foot::Left : Foot::Right)) ++mismatches;
    for (std::size_t k = 0; k < 161; ++k) {
      if (f.bits[k] != value(i, k)) ++mismatches;
    }
    ++i;
  }
  EXPECT_EQ(i, count);
  EXPECT_EQ(mismatches, 0u);
}

TEST(SessionWriter, RejectsAWrongSensorCount) {
  SessionHeader h;  // 37-38, 107 sensors
  SessionWriter writer(write_file("w-count.csv", ""), h);
  EXPECT_THROW(writer.write(Frame{0.0, Foot::Left, std::vector<std::uint8_t>(106)}),
               std::invalid_argument);
  EXPECT_NO_THROW(writer.write(Frame{0.0, Foot::Left, std::vector<std::uint8_t>(107)}));
}

TEST(SessionWriter, RejectsATimeThatDoesNotIncreaseForItsFoot) {
  const fs::path path = write_file("w-time.csv", "");
  SessionWriter writer(path, SessionHeader{});
  const std::vector<std::uint8_t> bits(107);
  writer.write(Frame{1.0, Foot::Left, bits});
  writer.write(Frame{0.5, Foot::Right, bits});
  try {
    writer.write(Frame{1.0, Foot::Left, bits});
    ADD_FAILURE() << "no invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("does not increase for foot L"));
  }
  EXPECT_THROW(writer.write(Frame{0.25, Foot::Right, bits}), std::invalid_argument);
  EXPECT_THROW(writer.write(Frame{std::numeric_limits<double>::quiet_NaN(), Foot::Right, bits}),
               std::invalid_argument);
  EXPECT_THROW(writer.write(Frame{std::numeric_limits<double>::infinity(), Foot::Right, bits}),
               std::invalid_argument);
  writer.close();
  EXPECT_EQ(test::file_frames(path).size(), 2u);
}

TEST(SessionWriter, RejectsATimeBeyondADayWhichTheReaderWouldRefuse) {
  SessionWriter writer(write_file("w-day.csv", ""), SessionHeader{});
  const std::vector<std::uint8_t> bits(107);
  EXPECT_THROW(writer.write(Frame{-kMaxSessionTimeS - 1.0, Foot::Left, bits}),
               std::invalid_argument);
  writer.write(Frame{kMaxSessionTimeS, Foot::Left, bits});
  try {
    writer.write(Frame{1e308, Foot::Left, bits});
    ADD_FAILURE() << "no invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("t_s 1e+308 is more than a day (86400 s) from the start"));
  }
}

TEST(SessionWriter, RejectsAHeaderThatWouldNotReadBack) {
  const fs::path path = write_file("w-header.csv", "");
  auto rejects = [&](const SessionHeader& h) {
    EXPECT_THROW((SessionWriter{path, h}), std::invalid_argument);
  };
  SessionHeader h;
  h.sensors = 108;
  rejects(h);
  h = {};
  h.version = 2;
  rejects(h);
  h = {};
  h.sample_rate_hz = 0.0;
  rejects(h);
  h.sample_rate_hz = 9.0;
  rejects(h);
  h = {};
  h.body_mass_kg = -1.0;
  rejects(h);
  h = {};
  h.note = "two\nlines";
  rejects(h);
  h = {};
  h.subject = " padded";
  rejects(h);
  h = {};
  h.extra = {{"sensors", "5"}};
  rejects(h);
  h = {};
  h.extra = {{"bad key", "v"}};
  rejects(h);
}

TEST(SessionWriter, ReportsAFileThatCannotBeCreated) {
  const fs::path path = scratch() / "missing" / "out.csv";
  try {
    SessionWriter writer(path, SessionHeader{});
    ADD_FAILURE() << "no runtime_error";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr(path.string()));
  }
}

TEST(SessionWriter, ReportsAWriteFailureOnClose) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "/dev/full is not available";
  SessionWriter writer("/dev/full", SessionHeader{});
  writer.write(Frame{0.0, Foot::Left, std::vector<std::uint8_t>(107)});
  try {
    writer.close();
    ADD_FAILURE() << "no runtime_error";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("/dev/full"));
  }
  EXPECT_THROW(writer.write(Frame{1.0, Foot::Left, std::vector<std::uint8_t>(107)}),
               std::runtime_error);
}

// ---------------------------------------------------------------------------------------------
// A real recording

TEST(SessionReader, ReadsARealGaitpdbRecording) {
  const fs::path csv = test::shared_dir() / "real-data/gaitpdb/gaitpdb_JuPt01_01.csv";
  const fs::path sidecar = test::shared_dir() / "real-data/gaitpdb/gaitpdb_JuPt01_01.json";
  if (!fs::exists(csv) || !fs::exists(sidecar)) {
    GTEST_SKIP() << "real recording not found: " << csv;
  }
  std::ifstream in(sidecar);
  const auto meta_json = nlohmann::json::parse(in);
  const auto frames_per_foot = meta_json.at("frames_per_foot").get<std::size_t>();

  SessionReader reader(csv);
  const SessionHeader& h = reader.header();
  EXPECT_EQ(h.insole_size, InsoleSize::S41_42);
  EXPECT_EQ(insole_size_name(h.insole_size), meta_json.at("insole_size").get<std::string>());
  EXPECT_EQ(h.sample_rate_hz, 100.0);
  EXPECT_EQ(h.sensors, 129u);
  EXPECT_EQ(h.subject, "JuPt01_01");
  ASSERT_TRUE(h.note.has_value());
  EXPECT_THAT(*h.note, HasSubstr("PhysioNet gaitpdb"));
  ASSERT_EQ(h.extra.size(), 2u);
  EXPECT_EQ(h.extra[0].first, "source");
  EXPECT_EQ(h.extra[1].first, "converter");
  EXPECT_EQ(h.extra[1].second, "tools/realdata/gaitpdb_to_session.py");

  Frame frame;
  ASSERT_TRUE(reader.next(frame));
  EXPECT_EQ(reader.line(), 10u);
  EXPECT_EQ(frame.t_s, 0.0);
  EXPECT_EQ(frame.foot, Foot::Left);
  // The first values of line 10 of the file: 0.0000,L,0,12,14,13,13,2,...
  EXPECT_EQ(frame.bits[0], 0);
  EXPECT_EQ(frame.bits[1], 12);
  EXPECT_EQ(frame.bits[2], 14);
  EXPECT_EQ(frame.bits[3], 13);
  EXPECT_EQ(frame.bits[4], 13);
  EXPECT_EQ(frame.bits[5], 2);
  std::array<std::size_t, 2> count{1, 0};
  double last_t = 0.0;
  while (reader.next(frame)) {
    ++count[frame.foot == Foot::Left ? 0 : 1];
    last_t = frame.t_s;
  }
  EXPECT_EQ(count[0], frames_per_foot);
  EXPECT_EQ(count[1], frames_per_foot);
  EXPECT_EQ(last_t, 82.2642);
}

}  // namespace
}  // namespace gaitmon
