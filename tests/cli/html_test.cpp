// Text put into the HTML reports: markup characters are escaped, everything else is kept.
#include "src/cli/html.hpp"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace gaitmon::cli
