// File helpers that fail loudly and never leave a half-written file behind.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

namespace twinforge::core {

// The whole file as text. Throws IoError naming the path if it cannot be read.
std::string ReadTextFile(const std::filesystem::path& path);

// Writes `contents` to a temp file beside `path`, flushes it, then renames it over `path`, so a
// reader sees the old file or the new one, never a mix. Creates parent directories. If
// `keep_backup`, an existing file is first copied to `<path>.bak`.
void WriteFileAtomic(const std::filesystem::path& path, const std::string& contents,
                     bool keep_backup = false);

// Creates `dir` (and parents) or throws IoError saying why.
void EnsureDirectory(const std::filesystem::path& dir);

// Fingerprint (FNV-1a, hex) of strings and of files' contents (missing files hash as such).
class Fingerprint {
 public:
  Fingerprint& Add(const std::string& text);
  Fingerprint& AddFile(const std::filesystem::path& path);
  std::string Hex() const;

 private:
  void Mix(const void* data, std::size_t size);
  uint64_t state_ = 1469598103934665603ULL;
};

}  // namespace twinforge::core
