// `gaitmon spy` run as a program: its option errors, and messages it must survive (malformed
// bytes, strings that are not UTF-8), read back from an LCM log through LCM's file:// provider.
#include <gtest/gtest.h>

#include <gaitmon/raw_t.hpp>
#include <lcm/lcm-cpp.hpp>
#include <string>
#include <vector>

#include "gaitmon/lcm_connection.hpp"
#include "gaitmon/lcm_publisher.hpp"
#include "lcm/sample_reports.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

std::string spy(const std::string& args, int* status) {
  std::string output;
  // `timeout`: an option that makes the spy wait for ever fails the test instead of hanging it.
  *status =
      test::run_command("timeout 30 " + test::gaitmon_binary().string() + " spy " + args, &output);
  return output;
}

TEST(SpyCommand, BadOptionsAreExitCodeTwoAndSayWhy) {
  struct Case {
    std::string args;
    std::string message;
  };
  for (const Case& c : {
           Case{"--count 0", "--count: '0' is less than 1"},
           Case{"--count -1", "--count: '-1' is not a whole number"},
           Case{"--timeout-s nan", "--timeout-s: 'nan' is not in [0.001, 1000000000]"},
           Case{"--timeout-s 0", "--timeout-s: '0' is not in [0.001, 1000000000]"},
           Case{"--lcm-url bogus:// --timeout-s 1", "--lcm-url: LCM cannot open \"bogus://\""},
           Case{"--lcm-url memq --timeout-s 1", "--lcm-url: LCM cannot open \"memq\""},
           // Port 1 on this host: no LCM TCP server; LCM opens it without a socket.
           Case{"--lcm-url tcpq://127.0.0.1:1 --timeout-s 1",
                "--lcm-url: LCM has no connection for \"tcpq://127.0.0.1:1\""},
           Case{"fit bogus --timeout-s 1",
                "channels: \"bogus\" is not a gaitmon channel: frame, step, fit, status, raw, "
                "effects, tissue or the config's names GAITMON_FRAME,"},
       }) {
    SCOPED_TRACE(c.args);
    int status = -1;
    const std::string out = spy(c.args, &status);
    EXPECT_EQ(status, 2) << out;
    EXPECT_NE(out.find(c.message), std::string::npos) << out;
  }
}

// A message the decoder throws on (a negative array length) is skipped, and a string that is not
// UTF-8 is printed with U+FFFD in its place; the spy goes on to the next message.
TEST(SpyCommand, SurvivesAMalformedMessageAndAStringThatIsNotUtf8) {
  const auto dir = test::scratch_dir("spy-malformed");
  const std::string log = (dir / "bus.lcmlog").string();
  LcmSettings settings;
  settings.raw_enabled = true;
  {
    const auto bus = open_lcm("file://" + log + "?mode=w");
    // A raw_t without bits whose num_bits, its last four bytes, is then made -1.
    raw_t message;
    message.num_bits = 0;
    std::vector<std::uint8_t> raw(static_cast<std::size_t>(message.getEncodedSize()));
    ASSERT_EQ(message.encode(raw.data(), 0, static_cast<int>(raw.size())),
              static_cast<int>(raw.size()));
    for (std::size_t i = raw.size() - 4; i < raw.size(); ++i) raw[i] = 0xFF;
    // First, as the log holds back a second failure within a second: bytes that are no message
    // at all, which the decoder refuses without throwing.
    const char junk[] = "junk";
    bus->publish(settings.channels.status, junk, sizeof junk);
    bus->publish(settings.channels.raw, raw.data(), static_cast<unsigned>(raw.size()));
    StatusReport status = test::sample_status();
    status.connection = "bad \xff byte";
    LcmPublisher publisher(bus, settings);
    publisher.publish(status);
    publisher.publish(test::sample_fit());
  }
  int status = -1;
  const std::string out =
      spy("--lcm-url 'file://" + log + "?mode=r' --count 2 --timeout-s 20", &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("\"connection\":\"bad \xEF\xBF\xBD byte\""), std::string::npos) << out;
  EXPECT_NE(out.find("\"channel\":\"GAITMON_FIT\""), std::string::npos) << out;
  // The skipped messages are logged, and counted when the spy ends.
  EXPECT_NE(out.find("LCM: a malformed message on GAITMON_STATUS skipped: another type, cut short "
                     "or an impossible value; 1 so far"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("gaitmon spy: 2 messages printed, 2 malformed ones skipped"),
            std::string::npos)
      << out;
}

}  // namespace
}  // namespace gaitmon
