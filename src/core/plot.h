// Line plots written as SVG (learning curves, success vs steps): a file any browser opens.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace twinforge::core {

struct PlotSeries {
  std::string name;
  std::vector<double> x, y;  // same length; NaN y values are gaps
};

struct PlotPanel {
  std::string title, x_label, y_label;
  std::vector<PlotSeries> series;
  bool y_unit_range = false;  // y axis fixed to [0, 1] (success rates)
};

// `text` with <, > and & escaped, for SVG and HTML.
std::string EscapeXml(const std::string& text);

// Panels side by side in one SVG, written to a temporary name and renamed.
void WriteSvgPlot(const std::filesystem::path& path, const std::vector<PlotPanel>& panels);

}  // namespace twinforge::core
