#include "core/config.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "core/fs.h"

namespace twinforge::core {

namespace {

std::string PointerEscape(const std::string& key) {
  std::string out;
  for (char c : key) {
    if (c == '~')
      out += "~0";
    else if (c == '/')
      out += "~1";
    else
      out += c;
  }
  return out;
}

// Plain YAML scalars become JSON booleans, nulls, integers or numbers; quoted ones stay strings.
Json ScalarToJson(const YAML::Node& node) {
  const std::string& text = node.Scalar();
  if (node.Tag() == "!") return text;  // quoted
  if (text == "true" || text == "True" || text == "TRUE") return true;
  if (text == "false" || text == "False" || text == "FALSE") return false;
  if (text.empty() || text == "~" || text == "null" || text == "Null" || text == "NULL")
    return nullptr;
  char* end = nullptr;
  errno = 0;
  const long long i = std::strtoll(text.c_str(), &end, 10);
  if (end && *end == '\0' && errno == 0) return static_cast<int64_t>(i);
  const double d = std::strtod(text.c_str(), &end);
  if (end && *end == '\0' && std::isfinite(d)) return d;
  return text;
}

Json YamlToJson(const YAML::Node& node, const std::string& pointer,
                std::map<std::string, int>& lines) {
  lines[pointer] = node.Mark().line + 1;
  switch (node.Type()) {
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined:
      return nullptr;
    case YAML::NodeType::Scalar:
      return ScalarToJson(node);
    case YAML::NodeType::Sequence: {
      Json out = Json::array();
      for (std::size_t i = 0; i < node.size(); ++i)
        out.push_back(YamlToJson(node[i], pointer + "/" + std::to_string(i), lines));
      return out;
    }
    case YAML::NodeType::Map: {
      Json out = Json::object();
      for (const auto& kv : node) {
        const std::string key = kv.first.as<std::string>();
        out[key] = YamlToJson(kv.second, pointer + "/" + PointerEscape(key), lines);
      }
      return out;
    }
  }
  return nullptr;
}

YAML::Node JsonToYaml(const Json& value) {
  YAML::Node node;
  if (value.is_object()) {
    node = YAML::Node(YAML::NodeType::Map);
    for (const auto& [key, item] : value.items()) node[key] = JsonToYaml(item);
  } else if (value.is_array()) {
    node = YAML::Node(YAML::NodeType::Sequence);
    bool flow = !value.empty();
    for (const auto& item : value) {
      node.push_back(JsonToYaml(item));
      flow = flow && item.is_primitive();
    }
    if (flow) node.SetStyle(YAML::EmitterStyle::Flow);
  } else if (value.is_boolean()) {
    node = value.get<bool>();
  } else if (value.is_number_integer()) {
    node = value.get<int64_t>();
  } else if (value.is_number()) {
    node = value.get<double>();
  } else if (value.is_string()) {
    node = value.get<std::string>();
  }
  return node;
}

// "a.b[2].c" -> "/a/b/2/c"
std::string DottedToPointer(const std::string& dotted) {
  std::string out = "/";
  for (char c : dotted) {
    if (c == '.' || c == '[')
      out += '/';
    else if (c != ']')
      out += c;
  }
  if (out == "/") return "";
  return out;
}

}  // namespace

ConfigDocument ParseConfigText(const std::string& text, const std::string& origin) {
  ConfigDocument doc;
  doc.file = origin;
  try {
    doc.root = YamlToJson(YAML::Load(text), "", doc.lines);
  } catch (const YAML::Exception& e) {
    throw ConfigError(
        origin, "",
        "not valid YAML/JSON at line " + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
  if (doc.root.is_null()) doc.root = Json::object();
  return doc;
}

ConfigDocument ParseConfigFile(const std::filesystem::path& path) {
  return ParseConfigText(ReadTextFile(path), path.string());
}

void WriteConfigTree(const std::filesystem::path& path, const Json& value) {
  const std::string ext = path.extension().string();
  std::string text;
  if (ext == ".json") {
    text = value.dump(2) + "\n";
  } else if (ext == ".yaml" || ext == ".yml") {
    YAML::Emitter emitter;
    emitter.SetDoublePrecision(17);
    emitter << JsonToYaml(value);
    text = std::string(emitter.c_str()) + "\n";
  } else {
    throw IoError("cannot write config " + path.string() +
                  ": expected a .yaml, .yml or .json extension");
  }
  WriteFileAtomic(path, text);
}

namespace config_detail {

std::string Describe(const Json& value) {
  std::string text = value.dump();
  if (text.size() > 60) text = text.substr(0, 57) + "...";
  if (value.is_object()) return "a mapping " + text;
  if (value.is_array()) return "a list " + text;
  if (value.is_null()) return "nothing (null)";
  return text;
}

std::string ClosestName(const std::string& name, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_distance = 3;  // suggest only close spellings
  for (const auto& candidate : candidates) {
    // Levenshtein distance.
    std::vector<std::size_t> row(candidate.size() + 1);
    for (std::size_t j = 0; j <= candidate.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= name.size(); ++i) {
      std::size_t diagonal = row[0];
      row[0] = i;
      for (std::size_t j = 1; j <= candidate.size(); ++j) {
        const std::size_t above = row[j];
        row[j] = std::min(
            {row[j] + 1, row[j - 1] + 1, diagonal + (name[i - 1] == candidate[j - 1] ? 0 : 1)});
        diagonal = above;
      }
    }
    if (row[candidate.size()] < best_distance) {
      best_distance = row[candidate.size()];
      best = candidate;
    }
  }
  return best;
}

}  // namespace config_detail

void ConfigReader::RejectUnknown() const {
  for (const auto& [key, value] : node_.items()) {
    if (std::find(known_.begin(), known_.end(), key) != known_.end()) continue;
    std::string message = "unknown field";
    const std::string suggestion = config_detail::ClosestName(key, known_);
    if (!suggestion.empty()) message += " (did you mean '" + suggestion + "'?)";
    std::string known;
    for (const auto& k : known_) known += (known.empty() ? "" : ", ") + k;
    Fail(Child(key), message + "; known fields: " + known);
  }
}

const Json* ConfigReader::Lookup(const std::string& dotted) const {
  try {
    const Json::json_pointer pointer(DottedToPointer(dotted));
    return node_.contains(pointer) ? &node_.at(pointer) : nullptr;
  } catch (const Json::exception&) {
    return nullptr;
  }
}

void ConfigReader::Fail(const std::string& path, const std::string& message) const {
  std::string file = doc_.file;
  // Find the line of the nearest enclosing value that has one.
  std::string pointer = DottedToPointer(path);
  while (true) {
    auto it = doc_.lines.find(pointer);
    if (it != doc_.lines.end()) {
      if (!file.empty()) file += ":" + std::to_string(it->second);
      break;
    }
    const auto slash = pointer.rfind('/');
    if (slash == std::string::npos) break;
    pointer = pointer.substr(0, slash);
  }
  throw ConfigError(file, path, message);
}

}  // namespace twinforge::core
