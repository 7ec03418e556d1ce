// A run directory: every artifact of one pipeline run, its log and its manifest.
//
//   runs/<name>/log.txt         everything logged while the run was open
//   runs/<name>/manifest.json   one entry per finished stage: input hash, outputs, time taken
//
// A stage is re-run only when its inputs changed or an output went missing, so a killed run
// resumes where it stopped.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "core/fs.h"

namespace twinforge::pipeline {

struct StageRecord {
  std::string inputs_hash;           // Fingerprint of everything the stage read
  std::vector<std::string> outputs;  // paths relative to the run directory
  double seconds = 0;                // wall-clock time the stage took
  std::string finished_at;           // ISO-8601 UTC
};

class RunDirectory {
 public:
  // Creates `root` if needed, loads its manifest and appends the log to root/log.txt.
  explicit RunDirectory(std::filesystem::path root);
  ~RunDirectory();

  const std::filesystem::path& root() const { return root_; }
  std::filesystem::path operator/(const std::string& relative) const { return root_ / relative; }

  // True if `stage` finished with the same inputs and all its outputs still exist.
  bool UpToDate(const std::string& stage, const std::string& inputs_hash) const;
  // Records a finished stage and rewrites manifest.json atomically.
  void Record(const std::string& stage, StageRecord record);
  const std::map<std::string, StageRecord>& stages() const { return stages_; }

 private:
  void Save() const;
  std::filesystem::path root_;
  std::map<std::string, StageRecord> stages_;
};

// Fingerprints of stage inputs (core/fs.h).
using core::Fingerprint;

}  // namespace twinforge::pipeline
