#include "core/plot.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/fs.h"
#include "core/test_support.h"

namespace twinforge::core {
namespace {

int Count(const std::string& text, const std::string& what) {
  int n = 0;
  for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// Two panels, one line per series; a NaN is skipped and labels are escaped.
TEST(Plot, WritesOneLinePerSeriesAndSkipsGaps) {
  const auto dir = testing::TestDir("plot_test");
  PlotPanel a{"success <vs> steps", "steps", "success", {}, true};
  a.series.push_back({"train", {0, 1, 2, 3}, {0.0, 0.5, NAN, 1.0}});
  a.series.push_back({"eval & co", {0, 3}, {0.1, 0.9}});
  PlotPanel b{"vs time", "minutes", "success", {{"train", {0, 1}, {0, 1}}}, false};
  WriteSvgPlot(dir / "curve.svg", {a, b});
  const std::string svg = ReadTextFile(dir / "curve.svg");
  EXPECT_EQ(svg.rfind("<svg", 0), 0u);
  EXPECT_EQ(Count(svg, "<path"), 3);
  EXPECT_NE(svg.find("success &lt;vs&gt; steps"), std::string::npos);
  EXPECT_NE(svg.find("eval &amp; co"), std::string::npos);
  // The first series has three finite points: one move and two lines.
  const auto path = svg.find("<path d='");
  const std::string d = svg.substr(path, svg.find('\'', path + 9) - path);
  EXPECT_EQ(Count(d, "M"), 1);
  EXPECT_EQ(Count(d, " L"), 2);
  EXPECT_EQ(svg.find("nan"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(dir / "curve.svg.tmp"));
}

}  // namespace
}  // namespace twinforge::core
