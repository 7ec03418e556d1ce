#include "core/plot.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include "core/error.h"

namespace twinforge::core {

std::string EscapeXml(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '<')
      out += "&lt;";
    else if (c == '>')
      out += "&gt;";
    else if (c == '&')
      out += "&amp;";
    else
      out += c;
  }
  return out;
}

namespace {

constexpr double kWidth = 420, kHeight = 300;
constexpr double kLeft = 56, kRight = 12, kTop = 28, kBottom = 44;
const char* const kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b"};

std::string Number(double v) {
  std::ostringstream s;
  s.precision(3);
  s << v;
  return s.str();
}

void Panel(std::ostream& svg, const PlotPanel& panel, double x0) {
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  for (const PlotSeries& s : panel.series)
    for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      xmin = std::min(xmin, s.x[i]);
      xmax = std::max(xmax, s.x[i]);
      ymin = std::min(ymin, s.y[i]);
      ymax = std::max(ymax, s.y[i]);
    }
  if (!std::isfinite(xmin)) xmin = 0, xmax = 1, ymin = 0, ymax = 1;
  if (panel.y_unit_range) ymin = 0, ymax = 1;
  if (xmax <= xmin) xmax = xmin + 1;
  if (ymax <= ymin) ymax = ymin + 1;
  const double w = kWidth - kLeft - kRight, h = kHeight - kTop - kBottom;
  const auto X = [&](double x) { return x0 + kLeft + (x - xmin) / (xmax - xmin) * w; };
  const auto Y = [&](double y) { return kTop + (1 - (y - ymin) / (ymax - ymin)) * h; };
  svg << "<text x='" << x0 + kWidth / 2 << "' y='18' text-anchor='middle' font-weight='bold'>"
      << EscapeXml(panel.title) << "</text>\n";
  svg << "<rect x='" << x0 + kLeft << "' y='" << kTop << "' width='" << w << "' height='" << h
      << "' fill='none' stroke='#888'/>\n";
  for (int k = 0; k <= 4; ++k) {
    const double xv = xmin + (xmax - xmin) * k / 4, yv = ymin + (ymax - ymin) * k / 4;
    svg << "<text x='" << X(xv) << "' y='" << kTop + h + 14 << "' text-anchor='middle'>"
        << Number(xv) << "</text>\n";
    svg << "<text x='" << x0 + kLeft - 4 << "' y='" << Y(yv) + 4 << "' text-anchor='end'>"
        << Number(yv) << "</text>\n";
    svg << "<line x1='" << x0 + kLeft << "' x2='" << x0 + kLeft + w << "' y1='" << Y(yv) << "' y2='"
        << Y(yv) << "' stroke='#eee'/>\n";
  }
  svg << "<text x='" << x0 + kLeft + w / 2 << "' y='" << kHeight - 8 << "' text-anchor='middle'>"
      << EscapeXml(panel.x_label) << "</text>\n";
  svg << "<text transform='translate(" << x0 + 14 << "," << kTop + h / 2
      << ") rotate(-90)' text-anchor='middle'>" << EscapeXml(panel.y_label) << "</text>\n";
  for (std::size_t k = 0; k < panel.series.size(); ++k) {
    const PlotSeries& s = panel.series[k];
    const char* colour = kColours[k % std::size(kColours)];
    std::string path;
    bool pen_down = false;
    for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;  // skip, keep the line
      path += (pen_down ? " L" : "M") + Number(X(s.x[i])) + "," + Number(Y(s.y[i]));
      pen_down = true;
    }
    svg << "<path d='" << path << "' fill='none' stroke='" << colour << "' stroke-width='1.5'/>\n";
    svg << "<text x='" << x0 + kLeft + 6 << "' y='" << kTop + 14 + 14 * k << "' fill='" << colour
        << "'>" << EscapeXml(s.name) << "</text>\n";
  }
}

}  // namespace

void WriteSvgPlot(const std::filesystem::path& path, const std::vector<PlotPanel>& panels) {
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  const auto tmp = path.string() + ".tmp";
  {
    std::ofstream svg(tmp);
    if (!svg) throw IoError("cannot write " + path.string());
    svg << "<svg xmlns='http://www.w3.org/2000/svg' width='" << kWidth * panels.size()
        << "' height='" << kHeight << "' font-family='sans-serif' font-size='11'>\n"
        << "<rect width='100%' height='100%' fill='white'/>\n";
    for (std::size_t p = 0; p < panels.size(); ++p) Panel(svg, panels[p], kWidth * p);
    svg << "</svg>\n";
    if (!svg) throw IoError("cannot write " + path.string());
  }
  std::filesystem::rename(tmp, path);
}

}  // namespace twinforge::core
