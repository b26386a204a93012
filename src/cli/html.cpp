// Helpers shared by the self-contained HTML pages.
#include "html.hpp"

#include <cmath>

namespace gaitmon::cli {

std::string escape(std::string_view text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string page_head(std::string_view title) {
  return R"(<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>)" + escape(title) +
         R"(</title><style>body{font-family:sans-serif;margin:20px;max-width:1000px}
table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #ccc;padding:3px 8px;font-size:13px}
th{background:#f3f3f3}.key span{display:inline-block;width:14px;height:10px;margin:0 4px}
pre{background:#f6f6f6;padding:8px}</style></head><body>)";
}

double nice_step(double range, int count) {
  const double raw = range / count;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / mag;
  return (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0) * mag;
}

}  // namespace gaitmon::cli
