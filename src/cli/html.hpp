// Helpers shared by the self-contained HTML pages (the analyze, discrepancy and creep reports).
#pragma once

#include <string>
#include <string_view>

namespace gaitmon::cli {

/// Text made safe inside HTML elements and double-quoted attributes.
std::string escape(std::string_view text);

/// The start of a page up to and including <body>: its title (escaped here) and the tables' and
/// code blocks' style.
std::string page_head(std::string_view title);

/// A tick spacing of 1, 2 or 5 x 10^k giving about `count` ticks over `range` (> 0).
double nice_step(double range, int count);

}  // namespace gaitmon::cli
