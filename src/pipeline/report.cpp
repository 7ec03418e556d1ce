// eval/report.html: one page a person opens in a browser, with every image beside it.
#include <algorithm>
#include <fstream>
#include <iomanip>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/log.h"
#include "core/plot.h"
#include "core/scan.h"
#include "pipeline/main_job.h"
#include "pipeline/run_directory.h"
#include "sim/camera.h"
#include "sim/env.h"

namespace twinforge::pipeline {

namespace {

nlohmann::json ReadJson(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) return nullptr;
  nlohmann::json j = nlohmann::json::parse(core::ReadTextFile(path), nullptr, false);
  return j.is_discarded() ? nlohmann::json(nullptr) : j;
}

std::vector<std::vector<std::string>> ReadCsv(const std::filesystem::path& path) {
  std::vector<std::vector<std::string>> rows;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    rows.emplace_back();
    std::stringstream s(line);
    for (std::string cell; std::getline(s, cell, ',');) rows.back().push_back(cell);
  }
  return rows;
}

std::string Percent(double v) { return std::to_string(int(std::lround(100 * v))) + "%"; }

// The twin rendered from the first scan frame's camera, written next to the report.
bool RenderTwinView(const std::filesystem::path& root, const std::filesystem::path& png) {
  if (!std::filesystem::exists(root / "twin/task.yaml") ||
      !std::filesystem::exists(root / "scan/frames.json"))
    return false;
  const core::Scan scan = core::ReadScan(root / "scan");
  if (scan.frames.empty()) return false;
  auto task =
      std::make_shared<const sim::Task>(sim::LoadTaskSpec((root / "twin/task.yaml").string()));
  sim::Env env(task);
  env.Reset(0, 0);
  const core::ScanFrameInfo& frame = scan.frames.front();
  sim::RayCaster caster({frame.intrinsics, frame.camera_to_base}, env.model());
  const int n = frame.intrinsics.width * frame.intrinsics.height;
  std::vector<float> depth(n);
  core::Image image{frame.intrinsics.width, frame.intrinsics.height, 3, 8,
                    std::vector<uint8_t>(3 * std::size_t(n))};
  caster.Render(env.model(), env.data(), env.base(), depth.data(), image.bytes.data(), true);
  core::WritePng(png, image);
  return true;
}

}  // namespace

std::filesystem::path WriteReport(const std::filesystem::path& root) {
  const std::filesystem::path dir = root / "eval";
  std::filesystem::create_directories(dir);
  std::ostringstream h;
  const nlohmann::json config = ReadJson(root / "config.json");
  const nlohmann::json manifest = ReadJson(root / "manifest.json");
  const std::string task = config.is_object() ? config.value("task", "?") : "?";
  h << "<!doctype html><html><head><meta charset='utf-8'><title>twinforge: "
    << core::EscapeXml(task)
    << "</title><style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
       "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:4px 10px;"
       "text-align:right}img{max-width:48%;margin:2px}</style></head><body>\n";
  h << "<h1>twinforge run: " << core::EscapeXml(task) << "</h1>\n<p>Reality: "
    << core::EscapeXml(config.is_object() ? config.value("reality", "?") : "?")
    << ". Run directory: " << core::EscapeXml(std::filesystem::absolute(root).string())
    << ".</p>\n";

  // Results first: what a user came for.
  h << "<h2>Success on reality (95% bootstrap intervals)</h2>\n<table><tr><th>policy</th>";
  std::vector<std::pair<std::string, nlohmann::json>> evals;
  for (const char* p : {"student", "bc_real"}) {
    const nlohmann::json e = ReadJson(dir / (std::string(p) + ".json"));
    if (e.is_object()) evals.emplace_back(p, e);
  }
  if (!evals.empty())
    for (const auto& l : evals.front().second["levels"])
      h << "<th>level " << l["level"].get<int>() << "</th>";
  h << "</tr>\n";
  for (const auto& [name, e] : evals) {
    h << "<tr><th>"
      << (name == "student" ? "twinforge (student, co-trained)" : "BC on the real demos")
      << "</th>";
    for (const auto& l : e["levels"])
      h << "<td>" << Percent(l["success_rate"]) << " (" << Percent(l["interval_95"][0]) << "-"
        << Percent(l["interval_95"][1]) << "), n=" << l["trials"].get<int>() << "</td>";
    h << "</tr>\n";
  }
  h << "</table>\n";
  if (evals.empty())
    h << "<p>No evaluation yet.</p>\n";
  else
    h << "<p>Moves: "
      << (evals.front().second.value("sample", false) ? "sampled from each policy's distribution"
                                                      : "each policy's most likely (greedy)")
      << ". 95% bootstrap intervals.</p>\n";

  h << "<h2>The twin next to the scan</h2>\n";
  const bool twin_view = RenderTwinView(root, dir / "twin_view.png");
  const core::Scan scan = std::filesystem::exists(root / "scan/frames.json")
                              ? core::ReadScan(root / "scan")
                              : core::Scan{};
  if (!scan.frames.empty())
    h << "<img src='../scan/" << scan.frames.front().color << "' alt='scan frame'>";
  if (twin_view) h << "<img src='twin_view.png' alt='twin rendered from the same camera'>";
  h << "<p>Left: the first scan frame. Right: the twin (collision shapes, robot at home) "
       "ray-cast from the same camera.</p>\n";
  const nlohmann::json build = ReadJson(root / "twin_build.json");
  if (build.is_object())
    h << "<details><summary>twin build report</summary><pre>" << core::EscapeXml(build.dump(2))
      << "</pre></details>\n";

  const nlohmann::json calibration = ReadJson(root / "calibrated/calibration/calibration.json");
  if (calibration.is_object()) {
    h << "<h2>Camera calibration</h2>\n";
    auto median = [&](const char* key) {
      double sum = 0;
      for (const auto& f : calibration[key]) sum += f["median_depth_error_mm"].get<double>();
      return calibration[key].empty() ? 0.0 : sum / calibration[key].size();
    };
    const auto& c = calibration["correction"];
    char line[512];
    std::snprintf(line, sizeof(line),
                  "<p>The camera is %.1f mm and %.2f deg from where its calibration said. The "
                  "twin's median depth error over the %zu frames went from %.1f mm to %.1f mm "
                  "(Open3D point-to-plane ICP: %.1f mm).</p>\n",
                  c["distance_mm"].get<double>(), c["angle_deg"].get<double>(),
                  calibration["frames_after"].size(), median("frames_before"),
                  median("frames_after"), median("frames_icp"));
    h << line;
    if (std::filesystem::exists(root / "calibrated/calibration/frame_00.png"))
      h << "<img style='max-width:96%;image-rendering:pixelated' "
           "src='../calibrated/calibration/frame_00.png' alt='calibration frame'>"
           "<p>Real colour | twin from the reported pose | twin from the calibrated pose | depth "
           "error before | after (black: agree, white: 8 cm or more).</p>\n";
  }
  const nlohmann::json mesh = ReadJson(root / "calibrated/calibration/mesh.json");
  if (mesh.is_object()) {
    double shift = 0;
    for (const auto& f : mesh["frame_corrections"]) shift += f["translation_mm"].get<double>();
    char line[512];
    std::snprintf(
        line, sizeof(line),
        "<h3>The scanned meshes</h3>\n<p>Refined against the %zu scan frames, each "
        "frame's pose corrected (%.1f mm on average): the frames' mean depth error "
        "went from %.1f mm to %.1f mm; the vertices moved %.1f mm rms.</p>\n",
        mesh["frame_corrections"].size(),
        mesh["frame_corrections"].empty() ? 0.0 : shift / mesh["frame_corrections"].size(),
        mesh["depth_error_mm"]["before"].get<double>(),
        mesh["depth_error_mm"]["after"].get<double>(), mesh["offset_rms_mm"].get<double>());
    h << line;
    // Each object placed on the table after it (or why not).
    const auto& objects = mesh.value("object_corrections", nlohmann::json::array());
    if (!objects.empty() && mesh.contains("meshes")) {
      h << "<p>Objects placed on the table by the same frames:</p>\n<ul>\n";
      for (size_t i = 0; i < objects.size() && i < mesh["meshes"].size(); ++i) {
        const auto& o = objects[i];
        const std::string name = mesh["meshes"][i].get<std::string>();
        const double before = o["depth_error_mm"]["before"].get<double>();
        const double placed = o["depth_error_mm"]["placed"].get<double>();
        if (o["placed"].get<bool>())
          std::snprintf(line, sizeof(line),
                        "<li>%s: moved %.1f mm and turned %.2f deg; its own depth error %.2f -> "
                        "%.2f mm</li>\n",
                        name.c_str(), o["translation_mm"].get<double>(),
                        o["rotation_deg"].get<double>(), before, placed);
        else
          std::snprintf(line, sizeof(line),
                        "<li>%s: kept where the scan put it (placed, its own depth error would "
                        "have gone %.2f -> %.2f mm)</li>\n",
                        name.c_str(), before, placed);
        h << line;
      }
      h << "</ul>\n";
    }
    if (std::filesystem::exists(root / "calibrated/calibration/mesh_00.png"))
      h << "<img style='max-width:96%;image-rendering:pixelated' "
           "src='../calibrated/calibration/mesh_00.png' alt='mesh refinement frame'>"
           "<p>Real colour | twin before | after | depth error before | after (black: agree, "
           "white: 1 cm or more).</p>\n";
  }

  const nlohmann::json sysid = ReadJson(root / "identified/sysid/sysid.json");
  if (sysid.is_object()) {
    const auto& start = sysid["start"];
    const auto& found = sysid["identified"];
    char line[512];
    std::snprintf(line, sizeof(line),
                  "<h2>Physics identified on the robot</h2>\n<p>The arm's joints in the twin "
                  "against the robot's, same targets (RMS): free moves %.3f deg before, %.3f "
                  "deg after; task runs %.3f deg before, %.3f deg after.</p>\n",
                  sysid["free_moves_rms_deg"]["before"].get<double>(),
                  sysid["free_moves_rms_deg"]["after"].get<double>(),
                  sysid["task_runs_rms_deg"]["before"].get<double>(),
                  sysid["task_runs_rms_deg"]["after"].get<double>());
    h << line << "<table><tr><th>value</th><th>twin before</th><th>identified</th></tr>\n";
    auto row = [&](const std::string& name, double before, double after) {
      std::snprintf(line, sizeof(line), "<tr><td>%s</td><td>%.4g</td><td>%.4g</td></tr>\n",
                    core::EscapeXml(name).c_str(), before, after);
      h << line;
    };
    for (const char* key : {"latency", "interpolation"})
      row(std::string("servo ") + key, start["servo"][key].get<double>(),
          found["servo"][key].get<double>());
    for (const char* key : {"kp", "kd", "damping", "frictionloss"})
      if (found["arm_scales"].contains(key))  // (sysid before stop 31 did not write the damping)
        row(std::string("arm ") + key + " scale", start["arm_scales"][key].get<double>(),
            found["arm_scales"][key].get<double>());
    if (found.contains("grip_force"))  // (sysid before stop 56 did not fit it)
      row("grip force (N)", start["grip_force"].get<double>(), found["grip_force"].get<double>());
    for (const auto& [name, value] : start["scene"].items())
      row(name, value.get<double>(), found["scene"][name].get<double>());
    h << "</table><p>A scene value the task runs do not pin down keeps the twin's.</p>\n";
  }

  h << "<h2>Learning</h2>\n";
  const auto bc = ReadCsv(root / "policies/bc_real.curve.csv");
  if (bc.size() > 1) {
    core::PlotPanel panel{"BC on the real demos", "epoch", "loss", {}};
    core::PlotSeries train{"train", {}, {}}, valid{"valid", {}, {}};
    for (std::size_t i = 1; i < bc.size(); ++i) {
      if (bc[i].size() < 3) continue;
      train.x.push_back(std::stod(bc[i][0]));
      train.y.push_back(std::stod(bc[i][1]));
      valid.x.push_back(std::stod(bc[i][0]));
      valid.y.push_back(std::stod(bc[i][2]));
    }
    panel.series = {train, valid};
    core::WriteSvgPlot(dir / "bc_curve.svg", {panel});
    h << "<h3>BC</h3><img src='bc_curve.svg' alt='BC loss'>\n";
  }
  const nlohmann::json sim_demos = ReadJson(root / "demos/sim.json");
  if (sim_demos.is_object())
    h << "<h3>Inverse distillation</h3><p>" << sim_demos["successes"].get<int>() << " successes in "
      << sim_demos["attempts"].get<int>() << " episodes of the real-demo policy in the twin ("
      << Percent(sim_demos["success_rate"]) << ").</p>\n";
  if (std::filesystem::exists(root / "policies/teacher.curve.svg")) {
    const nlohmann::json t = ReadJson(root / "policies/teacher.json");
    h << "<h3>Teacher: PPO + BC in the twin</h3>";
    if (t.is_object())
      h << "<p>Best evaluation " << Percent(t["best_eval_success"]) << " after "
        << t["env_steps"].get<int64_t>() << " env steps, "
        << int(std::lround(t["seconds"].get<double>() / 60)) << " min (stopped by "
        << t["stopped_by"].get<std::string>() << ").</p>";
    h << core::ReadTextFile(root / "policies/teacher.curve.svg") << "\n";
  }
  const auto distill = ReadCsv(root / "policies/student.curve.csv");
  if (distill.size() > 1) {
    h << "<h3>Teacher-student distillation</h3><table>";
    for (std::size_t i = 0; i < distill.size(); ++i) {
      h << "<tr>";
      for (const auto& cell : distill[i])
        h << (i ? "<td>" : "<th>") << core::EscapeXml(cell) << (i ? "</td>" : "</th>");
      h << "</tr>";
    }
    h << "</table><p>student_success: the success in the twin of the student the stage trained, on "
         "the next DAgger round's episodes (the last stage's on evaluation episodes of its own); "
         "-1: not scored.</p>\n";
  }

  h << "<h2>Frames</h2>\n";
  bool any = false;
  for (const char* p : {"student", "bc_real"}) {
    const auto frames = dir / "frames" / p;
    if (!std::filesystem::is_directory(frames)) continue;
    std::vector<std::string> names;
    for (const auto& f : std::filesystem::directory_iterator(frames))
      names.push_back(f.path().filename().string());
    std::sort(names.begin(), names.end());
    h << "<h3>" << p << "</h3>";
    for (const auto& n : names) {
      h << "<figure style='display:inline-block;margin:4px'><img style='max-width:320px' "
           "src='frames/"
        << p << "/" << n << "'><figcaption>" << core::EscapeXml(n) << "</figcaption></figure>";
      any = true;
    }
  }
  if (!any) h << "<p>No frames yet.</p>\n";

  if (manifest.is_object() && manifest.contains("stages")) {
    h << "<h2>Stages</h2><table><tr><th>stage</th><th>minutes</th><th>finished</th></tr>";
    for (const auto& [name, s] : manifest["stages"].items())
      h << "<tr><th>" << core::EscapeXml(name) << "</th><td>" << std::fixed << std::setprecision(1)
        << s.value("seconds", 0.0) / 60 << "</td><td>"
        << core::EscapeXml(s.value("finished_at", "")) << "</td></tr>";
    h << "</table>\n";
  }
  h << "</body></html>\n";
  const auto out = dir / "report.html";
  core::WriteFileAtomic(out, h.str());
  spdlog::info("report: {}", out.string());
  return out;
}

}  // namespace twinforge::pipeline
