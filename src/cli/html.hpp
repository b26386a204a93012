// Helpers shared by the self-contained HTML pages (the analyze and discrepancy reports).
#pragma once

#include <string>
#include <string_view>

namespace gaitmon::cli {

/// Text made safe inside HTML elements and double-quoted attributes.
std::string escape(std::string_view text);

}  // namespace gaitmon::cli
