#include "pipeline/run_directory.h"

#include <ctime>
#include <fstream>

#include "core/config.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/log.h"

namespace twinforge::pipeline {

namespace {
constexpr const char* kManifest = "manifest.json";

std::string NowIso8601() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y-%m-%dT%H:%M:%SZ", &utc);
  return buffer;
}
}  // namespace

RunDirectory::RunDirectory(std::filesystem::path root) : root_(std::move(root)) {
  core::EnsureDirectory(root_);
  const auto manifest = root_ / kManifest;
  if (std::filesystem::exists(manifest)) {
    const auto doc = core::ParseConfigFile(manifest);
    try {
      for (const auto& [stage, entry] : doc.root.at("stages").items()) {
        StageRecord record;
        record.inputs_hash = entry.at("inputs_hash").get<std::string>();
        record.outputs = entry.at("outputs").get<std::vector<std::string>>();
        record.seconds = entry.at("seconds").get<double>();
        record.finished_at = entry.at("finished_at").get<std::string>();
        stages_[stage] = record;
      }
    } catch (const core::Json::exception& e) {
      throw core::ConfigError(manifest.string(), "stages",
                              std::string("malformed manifest (") + e.what() +
                                  "); move it aside to re-run every stage");
    }
  }
  core::AttachLogFile(root_ / "log.txt");
}

RunDirectory::~RunDirectory() { core::DetachLogFile(); }

bool RunDirectory::UpToDate(const std::string& stage, const std::string& inputs_hash) const {
  const auto it = stages_.find(stage);
  if (it == stages_.end() || it->second.inputs_hash != inputs_hash) return false;
  for (const auto& output : it->second.outputs)
    if (!std::filesystem::exists(root_ / output)) return false;
  return true;
}

void RunDirectory::Record(const std::string& stage, StageRecord record) {
  if (record.finished_at.empty()) record.finished_at = NowIso8601();
  stages_[stage] = std::move(record);
  Save();
}

void RunDirectory::Save() const {
  core::Json stages = core::Json::object();
  for (const auto& [stage, r] : stages_)
    stages[stage] = {{"inputs_hash", r.inputs_hash},
                     {"outputs", r.outputs},
                     {"seconds", r.seconds},
                     {"finished_at", r.finished_at}};
  core::WriteFileAtomic(root_ / kManifest, core::Json{{"stages", stages}}.dump(2) + "\n");
}

}  // namespace twinforge::pipeline
