#include "core/dataset.h"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>

#include "core/error.h"

namespace twinforge::core {

namespace {

// HDF5's library is not thread-safe in Debian's build: serialise every call from here.
std::recursive_mutex& Hdf5Mutex() {
  static std::recursive_mutex mutex;
  return mutex;
}

// Owns one HDF5 identifier and closes it with the right function.
class Handle {
 public:
  Handle() = default;
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  Handle(Handle&& other) noexcept : id_(std::exchange(other.id_, -1)), close_(other.close_) {}
  Handle& operator=(Handle&& other) noexcept {
    Reset();
    id_ = std::exchange(other.id_, -1);
    close_ = other.close_;
    return *this;
  }
  ~Handle() { Reset(); }
  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }
  void Reset() {
    if (id_ >= 0 && close_) close_(id_);
    id_ = -1;
  }

 private:
  hid_t id_ = -1;
  herr_t (*close_)(hid_t) = nullptr;
};

struct Context {
  std::string file;
  [[noreturn]] void Fail(const std::string& where, const std::string& what) const {
    throw DatasetError("dataset " + file + ": " + where + ": " + what);
  }
  Handle Check(hid_t id, herr_t (*close)(hid_t), const std::string& where,
               const std::string& what) const {
    if (id < 0) Fail(where, what);
    return Handle(id, close);
  }
};

void SilenceHdf5Errors() {
  static std::once_flag once;
  std::call_once(once, [] { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); });
}

bool LinkExists(hid_t loc, const std::string& name) {
  return H5Lexists(loc, name.c_str(), H5P_DEFAULT) > 0;
}

// Creates a dataset `name` in `loc` holding `data` of `shape`, typed `mem_type` in memory and
// `file_type` on disk. Images are chunked by time step and lightly compressed.
void WriteDataset(const Context& ctx, hid_t loc, const std::string& name,
                  const std::vector<std::size_t>& shape, hid_t mem_type, hid_t file_type,
                  const void* data, bool compress) {
  std::vector<hsize_t> dims(shape.begin(), shape.end());
  Handle space = ctx.Check(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr),
                           H5Sclose, name, "cannot create dataspace");
  Handle props = ctx.Check(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, name, "cannot create props");
  if (compress && !dims.empty() && dims[0] > 0) {
    std::vector<hsize_t> chunk = dims;
    chunk[0] = 1;
    H5Pset_chunk(props.get(), static_cast<int>(chunk.size()), chunk.data());
    H5Pset_deflate(props.get(), 1);
  }
  Handle set = ctx.Check(
      H5Dcreate2(loc, name.c_str(), file_type, space.get(), H5P_DEFAULT, props.get(), H5P_DEFAULT),
      H5Dclose, name, "cannot create dataset");
  if (H5Dwrite(set.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
    ctx.Fail(name, "cannot write dataset");
}

void WriteInt64Attribute(const Context& ctx, hid_t loc, const std::string& name, int64_t value) {
  if (H5Aexists(loc, name.c_str()) > 0) H5Adelete(loc, name.c_str());
  Handle space = ctx.Check(H5Screate(H5S_SCALAR), H5Sclose, name, "cannot create dataspace");
  Handle attr =
      ctx.Check(H5Acreate2(loc, name.c_str(), H5T_STD_I64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT),
                H5Aclose, name, "cannot create attribute");
  H5Awrite(attr.get(), H5T_NATIVE_INT64, &value);
}

// A variable-length UTF-8 string attribute, as h5py writes a Python str.
void WriteStringAttribute(const Context& ctx, hid_t loc, const std::string& name,
                          const std::string& value) {
  if (H5Aexists(loc, name.c_str()) > 0) H5Adelete(loc, name.c_str());
  Handle type = ctx.Check(H5Tcopy(H5T_C_S1), H5Tclose, name, "cannot create string type");
  H5Tset_size(type.get(), H5T_VARIABLE);
  H5Tset_cset(type.get(), H5T_CSET_UTF8);
  Handle space = ctx.Check(H5Screate(H5S_SCALAR), H5Sclose, name, "cannot create dataspace");
  Handle attr =
      ctx.Check(H5Acreate2(loc, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT),
                H5Aclose, name, "cannot create attribute");
  const char* text = value.c_str();
  H5Awrite(attr.get(), type.get(), &text);
}

int64_t ReadInt64Attribute(const Context& ctx, hid_t loc, const std::string& name) {
  Handle attr =
      ctx.Check(H5Aopen(loc, name.c_str(), H5P_DEFAULT), H5Aclose, name, "missing attribute");
  int64_t value = 0;
  if (H5Aread(attr.get(), H5T_NATIVE_INT64, &value) < 0) ctx.Fail(name, "not an integer");
  return value;
}

// Reads a string attribute stored either variable-length (h5py str) or fixed-length (bytes).
std::string ReadStringAttribute(const Context& ctx, hid_t loc, const std::string& name) {
  Handle attr =
      ctx.Check(H5Aopen(loc, name.c_str(), H5P_DEFAULT), H5Aclose, name, "missing attribute");
  Handle type = ctx.Check(H5Aget_type(attr.get()), H5Tclose, name, "unreadable type");
  if (H5Tget_class(type.get()) != H5T_STRING) ctx.Fail(name, "expected a string attribute");
  if (H5Tis_variable_str(type.get()) > 0) {
    Handle mem = Handle(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(mem.get(), H5T_VARIABLE);
    H5Tset_cset(mem.get(), H5Tget_cset(type.get()));
    char* text = nullptr;
    if (H5Aread(attr.get(), mem.get(), &text) < 0 || !text) ctx.Fail(name, "unreadable string");
    std::string value(text);
    H5free_memory(text);
    return value;
  }
  std::string value(H5Tget_size(type.get()), '\0');
  if (H5Aread(attr.get(), type.get(), value.data()) < 0) ctx.Fail(name, "unreadable string");
  value.resize(std::strlen(value.c_str()));
  return value;
}

// The shape of dataset `set`.
std::vector<std::size_t> DatasetShape(const Context& ctx, hid_t set, const std::string& name) {
  Handle space = ctx.Check(H5Dget_space(set), H5Sclose, name, "unreadable dataspace");
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 0) ctx.Fail(name, "unreadable rank");
  std::vector<hsize_t> dims(rank);
  H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr);
  return {dims.begin(), dims.end()};
}

// Reads any numeric dataset, converted by HDF5 to `mem_type`.
template <class T>
Array<T> ReadArray(const Context& ctx, hid_t loc, const std::string& name, hid_t mem_type) {
  Handle set =
      ctx.Check(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), H5Dclose, name, "missing dataset");
  Handle type = ctx.Check(H5Dget_type(set.get()), H5Tclose, name, "unreadable type");
  const H5T_class_t cls = H5Tget_class(type.get());
  if (cls != H5T_INTEGER && cls != H5T_FLOAT) ctx.Fail(name, "expected a numeric dataset");
  Array<T> out(DatasetShape(ctx, set.get(), name));
  if (!out.data.empty() &&
      H5Dread(set.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data.data()) < 0)
    ctx.Fail(name, "cannot read values");
  return out;
}

bool IsByteDataset(const Context& ctx, hid_t loc, const std::string& name) {
  Handle set =
      ctx.Check(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), H5Dclose, name, "missing dataset");
  Handle type = ctx.Check(H5Dget_type(set.get()), H5Tclose, name, "unreadable type");
  return H5Tget_class(type.get()) == H5T_INTEGER && H5Tget_size(type.get()) == 1 &&
         H5Tget_sign(type.get()) == H5T_SGN_NONE;
}

std::vector<std::string> ChildNames(hid_t group) {
  std::vector<std::string> names;
  H5Literate(
      group, H5_INDEX_NAME, H5_ITER_NATIVE, nullptr,
      [](hid_t, const char* name, const H5L_info_t*, void* out) -> herr_t {
        static_cast<std::vector<std::string>*>(out)->emplace_back(name);
        return 0;
      },
      &names);
  return names;
}

// demo_<i> -> i, or -1 if the name is not of that form.
int DemoIndex(const std::string& name) {
  if (name.rfind("demo_", 0) != 0 || name.size() == 5) return -1;
  int value = 0;
  for (std::size_t i = 5; i < name.size(); ++i) {
    if (name[i] < '0' || name[i] > '9') return -1;
    value = value * 10 + (name[i] - '0');
  }
  return value;
}

std::vector<std::string> ReadStringList(const Context& ctx, hid_t loc, const std::string& name) {
  Handle set =
      ctx.Check(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), H5Dclose, name, "missing dataset");
  Handle type = ctx.Check(H5Dget_type(set.get()), H5Tclose, name, "unreadable type");
  if (H5Tget_class(type.get()) != H5T_STRING) ctx.Fail(name, "expected a list of strings");
  const auto shape = DatasetShape(ctx, set.get(), name);
  const std::size_t n = shape.empty() ? 1 : shape[0];
  std::vector<std::string> out;
  if (n == 0) return out;
  if (H5Tis_variable_str(type.get()) > 0) {
    std::vector<char*> texts(n, nullptr);
    Handle mem = Handle(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(mem.get(), H5T_VARIABLE);
    if (H5Dread(set.get(), mem.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, texts.data()) < 0)
      ctx.Fail(name, "cannot read strings");
    for (char* t : texts) {
      out.emplace_back(t ? t : "");
      if (t) H5free_memory(t);
    }
  } else {
    const std::size_t width = H5Tget_size(type.get());
    std::vector<char> buffer(n * width);
    if (H5Dread(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, buffer.data()) < 0)
      ctx.Fail(name, "cannot read strings");
    for (std::size_t i = 0; i < n; ++i) {
      const char* start = buffer.data() + i * width;
      out.emplace_back(start, strnlen(start, width));
    }
  }
  return out;
}

// Rewrites mask/<split> as fixed-length byte strings, as robomimic does with numpy 'S' arrays.
void WriteStringList(const Context& ctx, hid_t loc, const std::string& name,
                     const std::vector<std::string>& values) {
  if (LinkExists(loc, name)) H5Ldelete(loc, name.c_str(), H5P_DEFAULT);
  std::size_t width = 1;
  for (const auto& v : values) width = std::max(width, v.size());
  std::vector<char> buffer(values.size() * width, '\0');
  for (std::size_t i = 0; i < values.size(); ++i)
    std::memcpy(buffer.data() + i * width, values[i].data(), values[i].size());
  Handle type = ctx.Check(H5Tcopy(H5T_C_S1), H5Tclose, name, "cannot create string type");
  H5Tset_size(type.get(), width);
  H5Tset_strpad(type.get(), H5T_STR_NULLPAD);
  WriteDataset(ctx, loc, name, {values.size()}, type.get(), type.get(), buffer.data(), false);
}

template <class T>
void CheckFinite(const std::string& where, const std::vector<T>& values) {
  if constexpr (std::is_floating_point_v<T>) {
    for (std::size_t i = 0; i < values.size(); ++i)
      if (!std::isfinite(values[i]))
        throw DatasetError("episode field '" + where + "' holds a non-finite value at element " +
                           std::to_string(i));
  }
}

void ValidateEpisode(const Episode& e) {
  const std::size_t t = e.length();
  if (t == 0) throw DatasetError("episode field 'actions' is empty: an episode needs >= 1 step");
  auto check_rows = [&](const std::string& field, std::size_t rows) {
    if (rows != t)
      throw DatasetError("episode field '" + field + "' has " + std::to_string(rows) +
                         " rows, expected " + std::to_string(t) + " (one per action)");
  };
  CheckFinite("actions", e.actions.data);
  if (!e.states.empty()) check_rows("states", e.states.rows());
  CheckFinite("states", e.states.data);
  check_rows("rewards", e.rewards.size());
  CheckFinite("rewards", e.rewards);
  check_rows("dones", e.dones.size());
  for (const auto& [key, value] : e.obs) {
    check_rows("obs/" + key, value.rows());
    CheckFinite("obs/" + key, value.data);
  }
  for (const auto& [key, value] : e.images) check_rows("obs/" + key, value.rows());
}

Handle OpenFile(const std::filesystem::path& path, unsigned flags) {
  SilenceHdf5Errors();
  if (!std::filesystem::exists(path))
    throw IoError("cannot open dataset " + path.string() + ": no such file");
  const hid_t id = H5Fopen(path.c_str(), flags, H5P_DEFAULT);
  if (id < 0)
    throw DatasetError("cannot open dataset " + path.string() +
                       ": not an HDF5 file, or it is damaged or locked by another process");
  return Handle(id, H5Fclose);
}

}  // namespace

DatasetWriter DatasetWriter::Create(const std::filesystem::path& path,
                                    const nlohmann::json& env_args) {
  std::lock_guard lock(Hdf5Mutex());
  SilenceHdf5Errors();
  if (std::filesystem::exists(path))
    throw IoError("cannot create dataset " + path.string() +
                  ": the file exists (append to it, or remove it first)");
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  const Context ctx{path.string()};
  Handle file = ctx.Check(H5Fcreate(path.c_str(), H5F_ACC_EXCL, H5P_DEFAULT, H5P_DEFAULT), H5Fclose,
                          "file", "cannot create");
  Handle data = ctx.Check(H5Gcreate2(file.get(), "data", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                          H5Gclose, "data", "cannot create group");
  WriteInt64Attribute(ctx, data.get(), "total", 0);
  WriteStringAttribute(ctx, data.get(), "env_args", env_args.dump());
  Handle mask = ctx.Check(H5Gcreate2(file.get(), "mask", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                          H5Gclose, "mask", "cannot create group");
  return DatasetWriter(path);
}

DatasetWriter DatasetWriter::Append(const std::filesystem::path& path) {
  std::lock_guard lock(Hdf5Mutex());
  const Context ctx{path.string()};
  Handle file = OpenFile(path, H5F_ACC_RDWR);
  if (!LinkExists(file.get(), "data")) ctx.Fail("data", "missing group (not a robomimic file)");
  Handle data = Handle(H5Gopen2(file.get(), "data", H5P_DEFAULT), H5Gclose);
  DatasetWriter writer(path);
  for (const auto& name : ChildNames(data.get())) {
    if (name.rfind(".partial_", 0) == 0) {
      H5Ldelete(data.get(), name.c_str(), H5P_DEFAULT);  // an interrupted write
      continue;
    }
    writer.next_index_ = std::max(writer.next_index_, DemoIndex(name) + 1);
  }
  H5Fflush(file.get(), H5F_SCOPE_GLOBAL);
  return writer;
}

std::string DatasetWriter::Add(const Episode& episode, Split split) {
  ValidateEpisode(episode);
  std::lock_guard lock(Hdf5Mutex());
  const Context ctx{path_.string()};
  Handle file = OpenFile(path_, H5F_ACC_RDWR);
  Handle data =
      ctx.Check(H5Gopen2(file.get(), "data", H5P_DEFAULT), H5Gclose, "data", "missing group");
  const std::string name = "demo_" + std::to_string(next_index_);
  const std::string partial = ".partial_" + name;
  if (LinkExists(data.get(), partial)) H5Ldelete(data.get(), partial.c_str(), H5P_DEFAULT);
  {
    Handle demo =
        ctx.Check(H5Gcreate2(data.get(), partial.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                  H5Gclose, name, "cannot create group");
    const hid_t g = demo.get();
    const std::size_t t = episode.length();
    WriteDataset(ctx, g, "actions", episode.actions.shape, H5T_NATIVE_FLOAT, H5T_IEEE_F32LE,
                 episode.actions.data.data(), false);
    if (!episode.states.empty())
      WriteDataset(ctx, g, "states", episode.states.shape, H5T_NATIVE_FLOAT, H5T_IEEE_F32LE,
                   episode.states.data.data(), false);
    WriteDataset(ctx, g, "rewards", {t}, H5T_NATIVE_FLOAT, H5T_IEEE_F32LE, episode.rewards.data(),
                 false);
    WriteDataset(ctx, g, "dones", {t}, H5T_NATIVE_UINT8, H5T_STD_U8LE, episode.dones.data(), false);
    Handle obs = ctx.Check(H5Gcreate2(g, "obs", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
                           name + "/obs", "cannot create group");
    for (const auto& [key, value] : episode.obs)
      WriteDataset(ctx, obs.get(), key, value.shape, H5T_NATIVE_FLOAT, H5T_IEEE_F32LE,
                   value.data.data(), false);
    for (const auto& [key, value] : episode.images)
      WriteDataset(ctx, obs.get(), key, value.shape, H5T_NATIVE_UINT8, H5T_STD_U8LE,
                   value.data.data(), true);
    WriteInt64Attribute(ctx, g, "num_samples", static_cast<int64_t>(t));
    if (!episode.meta.empty()) WriteStringAttribute(ctx, g, "meta", episode.meta.dump());
  }
  // The episode becomes visible under its final name only once complete.
  if (H5Lmove(data.get(), partial.c_str(), data.get(), name.c_str(), H5P_DEFAULT, H5P_DEFAULT) < 0)
    ctx.Fail(name, "cannot rename the finished episode into place");
  WriteInt64Attribute(
      ctx, data.get(), "total",
      ReadInt64Attribute(ctx, data.get(), "total") + static_cast<int64_t>(episode.length()));
  if (!LinkExists(file.get(), "mask"))
    Handle(H5Gcreate2(file.get(), "mask", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
  Handle mask =
      ctx.Check(H5Gopen2(file.get(), "mask", H5P_DEFAULT), H5Gclose, "mask", "cannot open group");
  const std::string key = split == Split::kTrain ? "train" : "valid";
  std::vector<std::string> names;
  if (LinkExists(mask.get(), key)) names = ReadStringList(ctx, mask.get(), key);
  names.push_back(name);
  WriteStringList(ctx, mask.get(), key, names);
  H5Fflush(file.get(), H5F_SCOPE_GLOBAL);
  ++next_index_;
  return name;
}

DatasetReader::DatasetReader(const std::filesystem::path& path) : path_(path) {
  std::lock_guard lock(Hdf5Mutex());
  const Context ctx{path.string()};
  Handle file = OpenFile(path, H5F_ACC_RDONLY);
  if (!LinkExists(file.get(), "data")) ctx.Fail("data", "missing group (not a robomimic file)");
  Handle data = Handle(H5Gopen2(file.get(), "data", H5P_DEFAULT), H5Gclose);
  for (const auto& name : ChildNames(data.get()))
    if (DemoIndex(name) >= 0) demos_.push_back(name);
  std::sort(demos_.begin(), demos_.end(),
            [](const std::string& a, const std::string& b) { return DemoIndex(a) < DemoIndex(b); });
  if (H5Aexists(data.get(), "total") > 0) total_ = ReadInt64Attribute(ctx, data.get(), "total");
  if (H5Aexists(data.get(), "env_args") > 0) {
    const std::string text = ReadStringAttribute(ctx, data.get(), "env_args");
    env_args_ = nlohmann::json::parse(text, nullptr, false);
    if (env_args_.is_discarded()) ctx.Fail("data.attrs[env_args]", "not valid JSON");
  }
}

Episode DatasetReader::Read(const std::string& demo) const {
  std::lock_guard lock(Hdf5Mutex());
  const Context ctx{path_.string()};
  Handle file = OpenFile(path_, H5F_ACC_RDONLY);
  const std::string group_name = "data/" + demo;
  if (!LinkExists(file.get(), "data") || !LinkExists(file.get(), group_name))
    ctx.Fail(group_name, "no such episode");
  Handle group = Handle(H5Gopen2(file.get(), group_name.c_str(), H5P_DEFAULT), H5Gclose);
  const hid_t g = group.get();
  const Context at{path_.string() + ":" + group_name};
  Episode e;
  e.actions = ReadArray<float>(at, g, "actions", H5T_NATIVE_FLOAT);
  if (LinkExists(g, "states")) e.states = ReadArray<float>(at, g, "states", H5T_NATIVE_FLOAT);
  if (LinkExists(g, "rewards"))
    e.rewards = ReadArray<float>(at, g, "rewards", H5T_NATIVE_FLOAT).data;
  if (LinkExists(g, "dones")) e.dones = ReadArray<uint8_t>(at, g, "dones", H5T_NATIVE_UINT8).data;
  if (H5Aexists(g, "meta") > 0) {
    e.meta = nlohmann::json::parse(ReadStringAttribute(at, g, "meta"), nullptr, false);
    if (e.meta.is_discarded()) at.Fail("attrs[meta]", "not valid JSON");
  }
  if (LinkExists(g, "obs")) {
    Handle obs = Handle(H5Gopen2(g, "obs", H5P_DEFAULT), H5Gclose);
    for (const auto& key : ChildNames(obs.get())) {
      if (IsByteDataset(at, obs.get(), key))
        e.images[key] = ReadArray<uint8_t>(at, obs.get(), key, H5T_NATIVE_UINT8);
      else
        e.obs[key] = ReadArray<float>(at, obs.get(), key, H5T_NATIVE_FLOAT);
    }
  }
  return e;
}

std::vector<std::string> DatasetReader::Mask(const std::string& name) const {
  std::lock_guard lock(Hdf5Mutex());
  const Context ctx{path_.string()};
  Handle file = OpenFile(path_, H5F_ACC_RDONLY);
  const std::string path = "mask/" + name;
  if (!LinkExists(file.get(), "mask") || !LinkExists(file.get(), path)) return {};
  return ReadStringList(ctx, file.get(), path);
}

}  // namespace twinforge::core
