// Text put into the HTML reports: markup characters are escaped, everything else is kept; a page's
// head escapes its title; axis ticks fall on 1, 2 or 5 x 10^k.
#include "src/cli/html.hpp"

#include <gtest/gtest.h>

#include <string>

namespace gaitmon::cli {
namespace {

TEST(Html, EscapesWhatWouldEndAnElementOrADoubleQuotedAttribute) {
  EXPECT_EQ(escape(R"(<b title="a&b">x</b>)"), "&lt;b title=&quot;a&amp;b&quot;&gt;x&lt;/b&gt;");
  EXPECT_EQ(escape("&amp;"), "&amp;amp;");
}

TEST(Html, KeepsOtherTextAsItIs) {
  EXPECT_EQ(escape(""), "");
  EXPECT_EQ(escape("GaCo01_01 heel, 37-38: 0.05 N s/mm^3 \xC2\xB1 10 %"),
            "GaCo01_01 heel, 37-38: 0.05 N s/mm^3 \xC2\xB1 10 %");
}

TEST(Html, APageHeadEscapesItsTitleAndOpensTheBody) {
  const std::string head = page_head("a <b> & c");
  EXPECT_EQ(head.rfind("<!DOCTYPE html>", 0), 0u);
  EXPECT_NE(head.find("<title>a &lt;b&gt; &amp; c</title>"), std::string::npos);
  EXPECT_EQ(head.substr(head.size() - 13), "</head><body>");
}

TEST(Html, TickStepsAreOneTwoOrFiveTimesAPowerOfTen) {
  // The range over the count, rounded to the nearest of 1, 2, 5 and 10 on its decade.
  EXPECT_DOUBLE_EQ(nice_step(1.0, 5), 0.2);
  EXPECT_DOUBLE_EQ(nice_step(0.12, 6), 0.02);
  EXPECT_DOUBLE_EQ(nice_step(730.0, 5), 100.0);  // 146
  EXPECT_DOUBLE_EQ(nice_step(2.0, 5), 0.5);      // 0.4
  EXPECT_DOUBLE_EQ(nice_step(1.7, 5), 0.2);      // 0.34
  EXPECT_DOUBLE_EQ(nice_step(8.0, 1), 10.0);
}

}  // namespace
}  // namespace gaitmon::cli
