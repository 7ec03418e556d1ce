// Typed config structs <-> YAML/JSON files.
//
// A config is a plain struct with member-initialised defaults and one Serialize function that
// names each field once; the same function reads, writes and validates:
//
//   struct PpoConfig {
//     double learning_rate = 3e-4;
//     int epochs = 10;
//     template <class A> void Serialize(A& a) {
//       a("learning_rate", learning_rate);
//       a("epochs", epochs);
//       a.Require(epochs > 0, "epochs", "a positive integer");
//     }
//   };
//
// Missing fields keep their defaults; unknown fields, wrong types and failed checks throw
// ConfigError naming the file (and line, for YAML), the dotted field path and what was expected.
#pragma once

#include <Eigen/Core>
#include <array>
#include <filesystem>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/error.h"

namespace twinforge::core {

using Json = nlohmann::json;

// A parsed config file: its tree and, for YAML, the source line of each value.
struct ConfigDocument {
  Json root;
  std::string file;                  // shown in errors; empty for in-memory documents
  std::map<std::string, int> lines;  // JSON pointer ("/a/0/b") -> 1-based line
};

// Parses a .yaml/.yml/.json file. Throws IoError if unreadable, ConfigError if malformed.
ConfigDocument ParseConfigFile(const std::filesystem::path& path);

// Parses YAML (JSON is valid YAML) text; `origin` names it in errors.
ConfigDocument ParseConfigText(const std::string& text, const std::string& origin);

// Writes `value` as YAML or JSON (by extension) atomically: temp file then rename.
void WriteConfigTree(const std::filesystem::path& path, const Json& value);

namespace config_detail {

template <class T, class = void>
struct HasSerialize : std::false_type {};
template <class T>
struct HasSerialize<
    T, std::void_t<decltype(std::declval<T&>().Serialize(std::declval<struct ProbeArchive&>()))>>
    : std::true_type {};
struct ProbeArchive {
  template <class T>
  void operator()(const char*, T&) {}
  template <class E>
  void Enum(const char*, E&, std::initializer_list<std::pair<const char*, E>>) {}
  template <class S>
  void Require(bool, const char*, const S&) {}
};

template <class T>
struct IsVector : std::false_type {};
template <class T, class A>
struct IsVector<std::vector<T, A>> : std::true_type {};
template <class T>
struct IsArray : std::false_type {};
template <class T, std::size_t N>
struct IsArray<std::array<T, N>> : std::true_type {};
template <class T>
struct IsOptional : std::false_type {};
template <class T>
struct IsOptional<std::optional<T>> : std::true_type {};
template <class T>
struct IsStringMap : std::false_type {};
template <class T>
struct IsStringMap<std::map<std::string, T>> : std::true_type {};
template <class T>
struct IsEigenVector : std::false_type {};
template <int N>
struct IsEigenVector<Eigen::Matrix<double, N, 1>> : std::true_type {};

// Element count of a fixed-size std::array or Eigen vector.
template <class T>
struct FixedSize;
template <class T, std::size_t N>
struct FixedSize<std::array<T, N>> : std::integral_constant<std::size_t, N> {};
template <int N>
struct FixedSize<Eigen::Matrix<double, N, 1>> : std::integral_constant<std::size_t, N> {};

std::string Describe(const Json& value);
std::string ClosestName(const std::string& name, const std::vector<std::string>& candidates);

}  // namespace config_detail

// Reads a struct's fields from a JSON node; throws ConfigError on the first problem.
class ConfigReader {
 public:
  ConfigReader(const ConfigDocument& doc, const Json& node, std::string path)
      : doc_(doc), node_(node), path_(std::move(path)) {}

  template <class T>
  void operator()(const char* name, T& field) {
    known_.emplace_back(name);
    if (!node_.contains(name)) return;
    Read(node_.at(name), Child(name), field);
  }

  template <class E>
  void Enum(const char* name, E& field, std::initializer_list<std::pair<const char*, E>> names) {
    known_.emplace_back(name);
    if (!node_.contains(name)) return;
    const Json& v = node_.at(name);
    std::string choices;
    for (const auto& [text, value] : names) {
      if (v.is_string() && v.get<std::string>() == text) {
        field = value;
        return;
      }
      choices += std::string(choices.empty() ? "" : ", ") + "\"" + text + "\"";
    }
    Fail(Child(name), "expected one of " + choices + ", got " + config_detail::Describe(v));
  }

  // Fails with "expected <expected>" at `field` (relative to this struct) unless `ok`.
  void Require(bool ok, const char* field, const std::string& expected) {
    if (ok) return;
    const std::string path = Child(field);
    const Json* v = Lookup(field);
    Fail(path, "expected " + expected + (v ? ", got " + config_detail::Describe(*v) : ""));
  }

  // Throws if the node holds keys no field claimed.
  void RejectUnknown() const;

  // Reads a whole struct (or value) from `node` at `path`.
  template <class T>
  void Read(const Json& node, const std::string& path, T& out);

  [[noreturn]] void Fail(const std::string& path, const std::string& message) const;

 private:
  std::string Child(const std::string& name) const {
    return path_.empty() ? name : path_ + "." + name;
  }
  const Json* Lookup(const std::string& dotted) const;

  const ConfigDocument& doc_;
  const Json& node_;
  std::string path_;
  std::vector<std::string> known_;
};

// Writes a struct's fields into a JSON object.
class ConfigWriter {
 public:
  explicit ConfigWriter(Json& out) : out_(out) {}
  template <class T>
  void operator()(const char* name, const T& field) {
    Json v;
    Write(v, field);
    if (!v.is_null()) out_[name] = std::move(v);
  }
  template <class E>
  void Enum(const char* name, const E& field,
            std::initializer_list<std::pair<const char*, E>> names) {
    for (const auto& [text, value] : names)
      if (value == field) out_[name] = text;
  }
  void Require(bool, const char*, const std::string&) {}

  template <class T>
  static void Write(Json& out, const T& value);

 private:
  Json& out_;
};

template <class T>
void ConfigReader::Read(const Json& node, const std::string& path, T& out) {
  using namespace config_detail;
  auto expect = [&](bool ok, const char* what) {
    if (!ok) Fail(path, std::string("expected ") + what + ", got " + Describe(node));
  };
  if constexpr (std::is_same_v<T, bool>) {
    expect(node.is_boolean(), "true or false");
    out = node.get<bool>();
  } else if constexpr (std::is_integral_v<T>) {
    expect(node.is_number_integer(), "an integer");
    if constexpr (std::is_unsigned_v<T>) expect(node.get<int64_t>() >= 0, "a non-negative integer");
    out = node.get<T>();
  } else if constexpr (std::is_floating_point_v<T>) {
    expect(node.is_number(), "a number");
    out = node.get<T>();
  } else if constexpr (std::is_same_v<T, std::string>) {
    expect(node.is_string(), "a string");
    out = node.get<std::string>();
  } else if constexpr (IsOptional<T>::value) {
    if (node.is_null()) {
      out.reset();
    } else {
      typename T::value_type v{};
      Read(node, path, v);
      out = std::move(v);
    }
  } else if constexpr (IsVector<T>::value) {
    expect(node.is_array(), "a list");
    out.clear();
    out.resize(node.size());
    for (std::size_t i = 0; i < node.size(); ++i)
      Read(node[i], path + "[" + std::to_string(i) + "]", out[i]);
  } else if constexpr (IsArray<T>::value || IsEigenVector<T>::value) {
    constexpr std::size_t n = FixedSize<T>::value;
    const std::string what = "a list of " + std::to_string(n) + " numbers";
    if (!node.is_array() || node.size() != n)
      Fail(path, "expected " + what + ", got " + Describe(node));
    for (std::size_t i = 0; i < n; ++i) Read(node[i], path + "[" + std::to_string(i) + "]", out[i]);
  } else if constexpr (IsStringMap<T>::value) {
    expect(node.is_object(), "a mapping");
    out.clear();
    for (const auto& [key, value] : node.items()) Read(value, path + "." + key, out[key]);
  } else if constexpr (HasSerialize<T>::value) {
    expect(node.is_object(), "a mapping of fields");
    ConfigReader sub(doc_, node, path);
    out.Serialize(sub);
    sub.RejectUnknown();
  } else {
    static_assert(sizeof(T) == 0, "config field type not supported");
  }
}

template <class T>
void ConfigWriter::Write(Json& out, const T& value) {
  using namespace config_detail;
  if constexpr (std::is_arithmetic_v<T> || std::is_same_v<T, std::string>) {
    out = value;
  } else if constexpr (IsOptional<T>::value) {
    if (value) Write(out, *value);
  } else if constexpr (IsVector<T>::value || IsArray<T>::value) {
    out = Json::array();
    for (const auto& item : value) {
      Json v;
      Write(v, item);
      out.push_back(std::move(v));
    }
  } else if constexpr (IsEigenVector<T>::value) {
    out = Json::array();
    for (int i = 0; i < value.size(); ++i) out.push_back(value[i]);
  } else if constexpr (IsStringMap<T>::value) {
    out = Json::object();
    for (const auto& [key, item] : value) Write(out[key], item);
  } else if constexpr (HasSerialize<T>::value) {
    out = Json::object();
    ConfigWriter writer(out);
    const_cast<T&>(value).Serialize(writer);
  } else {
    static_assert(sizeof(T) == 0, "config field type not supported");
  }
}

// Reads a config struct from a parsed document (fields at its root).
template <class T>
T ReadConfig(const ConfigDocument& doc) {
  T value{};
  ConfigReader reader(doc, doc.root, "");
  reader.Read(doc.root, "", value);
  return value;
}

// Loads a config struct from a YAML/JSON file; missing fields keep their defaults.
template <class T>
T LoadConfig(const std::filesystem::path& path) {
  return ReadConfig<T>(ParseConfigFile(path));
}

// The struct as a JSON tree (every field, defaults included).
template <class T>
Json ToJson(const T& value) {
  Json out;
  ConfigWriter::Write(out, value);
  return out;
}

// Runs the struct's checks (its Serialize's Require calls) on a value built in code, e.g. from
// command-line flags; throws ConfigError naming `origin` and the field that fails.
template <class T>
void Validate(const T& value, const std::string& origin) {
  ReadConfig<T>(ConfigDocument{ToJson(value), origin, {}});
}

// Writes the struct to a YAML/JSON file (by extension), atomically.
template <class T>
void SaveConfig(const std::filesystem::path& path, const T& value) {
  WriteConfigTree(path, ToJson(value));
}

}  // namespace twinforge::core
