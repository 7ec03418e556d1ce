#include "core/fs.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"

namespace twinforge::core {

std::string ReadTextFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    const bool exists = std::filesystem::exists(path);
    throw IoError("cannot read " + path.string() +
                  (exists ? ": permission denied or not a regular file" : ": no such file"));
  }
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

void EnsureDirectory(const std::filesystem::path& dir) {
  if (dir.empty()) return;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw IoError("cannot create directory " + dir.string() + ": " + ec.message());
}

void WriteFileAtomic(const std::filesystem::path& path, const std::string& contents,
                     bool keep_backup) {
  EnsureDirectory(path.parent_path());
  const std::filesystem::path temp =
      path.string() + ".tmp." + std::to_string(static_cast<long>(::getpid()));
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) throw IoError("cannot write " + temp.string() + ": " + std::strerror(errno));
  std::size_t written = 0;
  while (written < contents.size()) {
    const ssize_t n = ::write(fd, contents.data() + written, contents.size() - written);
    if (n < 0) {
      const std::string reason = std::strerror(errno);
      ::close(fd);
      ::unlink(temp.c_str());
      throw IoError("cannot write " + temp.string() + ": " + reason);
    }
    written += static_cast<std::size_t>(n);
  }
  ::fsync(fd);
  ::close(fd);
  std::error_code ec;
  if (keep_backup && std::filesystem::exists(path)) {
    std::filesystem::copy_file(path, path.string() + ".bak",
                               std::filesystem::copy_options::overwrite_existing, ec);
    if (ec) throw IoError("cannot back up " + path.string() + ": " + ec.message());
  }
  std::filesystem::rename(temp, path, ec);
  if (ec) {
    std::filesystem::remove(temp);
    throw IoError("cannot replace " + path.string() + ": " + ec.message());
  }
}

void Fingerprint::Mix(const void* data, std::size_t size) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < size; ++i) {
    state_ ^= bytes[i];
    state_ *= 1099511628211ULL;
  }
}

Fingerprint& Fingerprint::Add(const std::string& text) {
  const uint64_t size = text.size();
  Mix(&size, sizeof size);
  Mix(text.data(), text.size());
  return *this;
}

Fingerprint& Fingerprint::AddFile(const std::filesystem::path& path) {
  Add(path.filename().string());
  if (!std::filesystem::exists(path)) return Add("<missing>");
  std::ifstream in(path, std::ios::binary);
  char buffer[1 << 16];
  while (in.read(buffer, sizeof buffer) || in.gcount() > 0)
    Mix(buffer, static_cast<std::size_t>(in.gcount()));
  return *this;
}

std::string Fingerprint::Hex() const {
  char buffer[17];
  std::snprintf(buffer, sizeof buffer, "%016llx", static_cast<unsigned long long>(state_));
  return buffer;
}

}  // namespace twinforge::core
