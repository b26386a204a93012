// The Java artefact: the generated jar holds every gaitmon type, lcm-spy's type discovery finds
// them through CLASSPATH, and a Java program decodes a logged message with them.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>
#include <string>

#include "gaitmon/lcm_publisher.hpp"
#include "lcm/sample_reports.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const char* const kTypes[] = {"frame_t",        "region_frame_t", "step_t",         "fit_t",
                              "region_fit_t",   "status_t",       "raw_t",          "effects_t",
                              "effect_param_t", "tissue_t",       "region_tissue_t"};

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

TEST(LcmJava, JarHoldsEveryType) {
  ASSERT_TRUE(fs::exists(GAITMON_LCM_JAR)) << GAITMON_LCM_JAR;
  std::string listing;
  ASSERT_EQ(test::run_command(std::string("jar tf ") + GAITMON_LCM_JAR, &listing), 0) << listing;
  for (const char* type : kTypes) {
    EXPECT_THAT(listing, HasSubstr(std::string("gaitmon/") + type + ".class")) << type;
  }
}

// lcm-spy (lcm.spy.Spy) finds message classes with lcm.util.ClassDiscoverer, which reads
// CLASSPATH. Without a display it stops at the window after reporting what it found.
TEST(LcmJava, LcmSpyFindsTheTypesOnClasspath) {
  std::string output;
  test::run_command(std::string("CLASSPATH=") + GAITMON_LCM_JAR +
                        " timeout 60 java -Djava.awt.headless=true -cp " +
                        GAITMON_LCM_JAVA_LIB_JAR + " lcm.spy.Spy --lcm-url=memq:// 2>&1",
                    &output);
  EXPECT_THAT(output, HasSubstr("Found 11 LCM types")) << output;
}

// Decodes the way lcm-spy does (fingerprint -> class through lcm.spy.LCMTypeDatabase), and once
// with the generated class named in the code.
constexpr const char* kDecodeJava = R"(
import lcm.logging.Log;
import lcm.spy.LCMTypeDatabase;

public class Decode {
  public static void main(String[] args) throws Exception {
    LCMTypeDatabase types = new LCMTypeDatabase();
    Log log = new Log(args[0], "r");
    while (true) {
      Log.Event e;
      try {
        e = log.readNext();
      } catch (java.io.EOFException end) {
        break;
      }
      long fingerprint = new java.io.DataInputStream(new java.io.ByteArrayInputStream(e.data)).readLong();
      Class<?> c = types.getClassByFingerprint(fingerprint);
      Object m = c.getConstructor(byte[].class).newInstance((Object) e.data);
      long utime = c.getField("utime").getLong(m);
      System.out.println("event " + e.channel + " " + c.getName() + " " + utime);
      if (e.channel.equals("GAITMON_FIT")) {
        gaitmon.fit_t fit = new gaitmon.fit_t(e.data);
        System.out.println("fit " + fit.foot + " " + fit.step + " " + fit.latency_ms + " "
            + fit.regions[3].region_name + " " + fit.regions[3].kbar_n_per_mm3 + " "
            + fit.regions[6].status.replace(' ', '_') + " " + fit.effects_inside + " "
            + fit.effects_utime);
      }
      if (e.channel.equals("GAITMON_TISSUE")) {
        gaitmon.tissue_t tissue = new gaitmon.tissue_t(e.data);
        System.out.println("tissue " + tissue.foot + " " + tissue.step + " "
            + tissue.regions[0].region_name + " " + tissue.regions[0].steps + " "
            + tissue.regions[0].kbar_n_per_mm3 + " " + tissue.regions[0].se_kbar);
      }
    }
  }
}
)";

TEST(LcmJava, JavaProgramDecodesALoggedMessage) {
  const fs::path dir = test::scratch_dir("lcm-java");
  const fs::path log = dir / "samples.log";
  {
    LcmSettings settings;
    settings.url = "file://" + log.string() + "?mode=w";
    settings.raw_enabled = true;
    LcmPublisher publisher(settings);
    test::publish_samples(publisher);
    ASSERT_EQ(publisher.published(), 7U);
  }
  test::write_text(dir / "Decode.java", kDecodeJava);
  const std::string classpath =
      std::string(GAITMON_LCM_JAVA_LIB_JAR) + ":" + GAITMON_LCM_JAR + ":" + dir.string();
  std::string output;
  ASSERT_EQ(test::run_command("javac -cp " + classpath + " -d " + dir.string() + " " +
                                  (dir / "Decode.java").string(),
                              &output),
            0)
      << output;
  output.clear();
  ASSERT_EQ(test::run_command("java -cp " + classpath + " Decode " + log.string(), &output), 0)
      << output;
  // lcm.spy's class discovery also prints what it could not load; only our lines count.
  std::vector<std::string> events;
  std::string fit_line, tissue_line;
  for (const std::string& line : lines_of(output)) {
    if (line.rfind("event ", 0) == 0) events.push_back(line);
    if (line.rfind("fit ", 0) == 0) fit_line = line;
    if (line.rfind("tissue ", 0) == 0) tissue_line = line;
  }
  const std::vector<std::string> expected{
      "event GAITMON_FRAME gaitmon.frame_t 1763737200123456",
      "event GAITMON_STEP gaitmon.step_t 1763737200223456",
      "event GAITMON_FIT gaitmon.fit_t 1763737200323456",
      "event GAITMON_STATUS gaitmon.status_t 1763737200423456",
      "event GAITMON_RAW gaitmon.raw_t 1763737200523456",
      "event GAITMON_EFFECTS gaitmon.effects_t 1763737200623456",
      "event GAITMON_TISSUE gaitmon.tissue_t 1763737200723456"};
  EXPECT_EQ(events, expected) << output;
  std::istringstream fit(fit_line);
  std::string word, foot, step, latency, region, kbar, status, inside, effects_utime;
  fit >> word >> foot >> step >> latency >> region >> kbar >> status >> inside >> effects_utime;
  EXPECT_EQ(word, "fit") << output;
  EXPECT_EQ(foot, "1");
  EXPECT_EQ(step, "23");
  EXPECT_EQ(latency, "1.875");
  EXPECT_EQ(region, "met1_2");
  EXPECT_EQ(std::stod(kbar), 0.117 + 0.001 * 3);  // as sample_fit() computes it
  EXPECT_EQ(status, "fit_failed:no_convergence");
  EXPECT_EQ(inside, "stress_relaxation,hysteresis");
  EXPECT_EQ(effects_utime, "1763737199000000");
  // As sample_tissue() gives them; Java prints the shortest decimal that reads back.
  EXPECT_EQ(tissue_line, "tissue 0 41 heel 80 0.125 0.0046") << output;
}

}  // namespace
}  // namespace gaitmon
