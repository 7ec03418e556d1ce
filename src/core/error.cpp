#include "core/error.h"

namespace twinforge::core {

namespace {
std::string FormatConfigError(const std::string& file, const std::string& field,
                              const std::string& message) {
  std::string text = "config error in " + (file.empty() ? std::string("<memory>") : file);
  if (!field.empty()) text += ": field '" + field + "'";
  return text + ": " + message;
}
}  // namespace

ConfigError::ConfigError(std::string file, std::string field, std::string message)
    : Error(FormatConfigError(file, field, message)),
      file_(std::move(file)),
      field_(std::move(field)) {}

}  // namespace twinforge::core
