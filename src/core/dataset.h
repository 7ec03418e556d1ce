// Demonstration datasets in robomimic's HDF5 layout.
//
//   data/                      attrs: total (int64), env_args (JSON string)
//     demo_0/                  attrs: num_samples (int64), meta (JSON string: seed, level...)
//       actions  [T, A]        rewards [T]   dones [T]   states [T, S]
//       obs/<key> [T, ...]     float vectors, or uint8 images [T, H, W, C]
//   mask/train, mask/valid     demo names (fixed-length byte strings)
//
// The writer opens and closes the file for every episode it adds and writes the episode under a
// temporary name before renaming it into place, so a crash or kill never leaves a half episode
// visible and never damages episodes already written.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace twinforge::core {

// A dense row-major n-d array.
template <class T>
struct Array {
  std::vector<std::size_t> shape;
  std::vector<T> data;

  Array() = default;
  Array(std::vector<std::size_t> shape_in) : shape(std::move(shape_in)) {
    std::size_t n = 1;
    for (auto s : shape) n *= s;
    data.assign(n, T{});
  }
  // Length of the first axis (0 for an empty array).
  std::size_t rows() const { return shape.empty() ? 0 : shape[0]; }
  // Elements per row.
  std::size_t row_size() const { return rows() ? data.size() / rows() : 0; }
  T* row(std::size_t i) { return data.data() + i * row_size(); }
  const T* row(std::size_t i) const { return data.data() + i * row_size(); }
  bool empty() const { return data.empty(); }
};

using FloatArray = Array<float>;
using ByteArray = Array<uint8_t>;

struct Episode {
  FloatArray actions;                              // [T, action_dim]
  FloatArray states;                               // [T, state_dim]; may be empty
  std::vector<float> rewards;                      // [T]
  std::vector<uint8_t> dones;                      // [T]
  std::map<std::string, FloatArray> obs;           // [T, ...] numeric observations
  std::map<std::string, ByteArray> images;         // [T, H, W, C] uint8 observations
  nlohmann::json meta = nlohmann::json::object();  // what started the episode (seed, level...)
  std::size_t length() const { return actions.rows(); }
};

enum class Split { kTrain, kValid };

class DatasetWriter {
 public:
  // Creates `path` (which must not exist) with `env_args` stored in data.attrs["env_args"].
  static DatasetWriter Create(const std::filesystem::path& path, const nlohmann::json& env_args);
  // Opens an existing dataset to add episodes after the ones it holds. Leftovers of an episode
  // whose write was interrupted are removed.
  static DatasetWriter Append(const std::filesystem::path& path);

  // Validates and appends `episode` as the next demo_<i>; returns its name.
  // Throws DatasetError naming the field if lengths disagree or values are not finite.
  std::string Add(const Episode& episode, Split split = Split::kTrain);

  int episodes() const { return next_index_; }
  const std::filesystem::path& path() const { return path_; }

 private:
  explicit DatasetWriter(std::filesystem::path path) : path_(std::move(path)) {}
  std::filesystem::path path_;
  int next_index_ = 0;
};

class DatasetReader {
 public:
  // Opens `path` read-only. Throws IoError if missing, DatasetError if it has no data group.
  explicit DatasetReader(const std::filesystem::path& path);

  // Demo names ordered by their index (demo_2 before demo_10).
  const std::vector<std::string>& demos() const { return demos_; }
  Episode Read(const std::string& demo) const;
  // Names listed under mask/<name> (e.g. "train", "valid"); empty if there is no such mask.
  std::vector<std::string> Mask(const std::string& name) const;
  nlohmann::json env_args() const { return env_args_; }
  int64_t total() const { return total_; }

 private:
  std::filesystem::path path_;
  std::vector<std::string> demos_;
  nlohmann::json env_args_;
  int64_t total_ = 0;
};

}  // namespace twinforge::core
