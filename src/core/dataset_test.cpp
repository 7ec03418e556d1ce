#include "core/dataset.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/error.h"

namespace twinforge::core {
namespace {

std::filesystem::path TempPath(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / "twinforge_dataset_test";
  std::filesystem::create_directories(dir);
  const auto path = dir / name;
  std::filesystem::remove(path);
  return path;
}

Episode MakeEpisode(std::size_t t, float base) {
  Episode e;
  e.actions = FloatArray({t, 7});
  e.states = FloatArray({t, 5});
  e.obs["proprio"] = FloatArray({t, 9});
  e.images["agentview_image"] = ByteArray({t, 6, 8, 3});
  for (std::size_t i = 0; i < e.actions.data.size(); ++i) e.actions.data[i] = base + 0.5f * i;
  for (std::size_t i = 0; i < e.states.data.size(); ++i) e.states.data[i] = base - i;
  for (std::size_t i = 0; i < e.obs["proprio"].data.size(); ++i) e.obs["proprio"].data[i] = i;
  auto& image = e.images["agentview_image"].data;
  for (std::size_t i = 0; i < image.size(); ++i) image[i] = static_cast<uint8_t>(i * 7 + base);
  e.rewards.assign(t, 0.0f);
  e.rewards.back() = 1.0f;
  e.dones.assign(t, 0);
  e.dones.back() = 1;
  e.meta = {{"seed", 1000 + t}, {"level", 2}};
  return e;
}

void ExpectSameEpisode(const Episode& a, const Episode& b) {
  EXPECT_EQ(a.actions.shape, b.actions.shape);
  EXPECT_EQ(a.actions.data, b.actions.data);
  EXPECT_EQ(a.states.data, b.states.data);
  EXPECT_EQ(a.rewards, b.rewards);
  EXPECT_EQ(a.dones, b.dones);
  EXPECT_EQ(a.meta, b.meta);
  ASSERT_EQ(a.obs.size(), b.obs.size());
  for (const auto& [k, v] : a.obs) {
    EXPECT_EQ(v.shape, b.obs.at(k).shape) << k;
    EXPECT_EQ(v.data, b.obs.at(k).data) << k;
  }
  ASSERT_EQ(a.images.size(), b.images.size());
  for (const auto& [k, v] : a.images) {
    EXPECT_EQ(v.shape, b.images.at(k).shape) << k;
    EXPECT_EQ(v.data, b.images.at(k).data) << k;
  }
}

TEST(Dataset, TwoEpisodesWithImageAndVectorObsRoundTrip) {
  const auto path = TempPath("round_trip.hdf5");
  const Episode first = MakeEpisode(5, 1.0f), second = MakeEpisode(3, 2.0f);
  {
    auto writer = DatasetWriter::Create(path, {{"env_name", "open_drawer"}, {"type", 4}});
    EXPECT_EQ(writer.Add(first), "demo_0");
    EXPECT_EQ(writer.Add(second, Split::kValid), "demo_1");
  }
  DatasetReader reader(path);
  ASSERT_EQ(reader.demos(), (std::vector<std::string>{"demo_0", "demo_1"}));
  EXPECT_EQ(reader.total(), 8);
  EXPECT_EQ(reader.env_args()["env_name"], "open_drawer");
  EXPECT_EQ(reader.Mask("train"), std::vector<std::string>{"demo_0"});
  EXPECT_EQ(reader.Mask("valid"), std::vector<std::string>{"demo_1"});
  ExpectSameEpisode(reader.Read("demo_0"), first);
  ExpectSameEpisode(reader.Read("demo_1"), second);
}

TEST(Dataset, AppendContinuesNumberingAndKeepsEarlierEpisodes) {
  const auto path = TempPath("append.hdf5");
  DatasetWriter::Create(path, {}).Add(MakeEpisode(4, 0.0f));
  auto writer = DatasetWriter::Append(path);
  EXPECT_EQ(writer.Add(MakeEpisode(2, 3.0f)), "demo_1");
  DatasetReader reader(path);
  EXPECT_EQ(reader.demos().size(), 2u);
  EXPECT_EQ(reader.total(), 6);
  EXPECT_EQ(reader.Mask("train").size(), 2u);
  ExpectSameEpisode(reader.Read("demo_0"), MakeEpisode(4, 0.0f));
}

TEST(Dataset, RejectedEpisodeLosesNothingWritten) {
  const auto path = TempPath("reject.hdf5");
  auto writer = DatasetWriter::Create(path, {});
  writer.Add(MakeEpisode(3, 0.0f));
  Episode bad = MakeEpisode(3, 1.0f);
  bad.actions.data[4] = std::nanf("");
  try {
    writer.Add(bad);
    FAIL() << "a NaN action was accepted";
  } catch (const DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("'actions'"), std::string::npos) << e.what();
  }
  Episode short_rewards = MakeEpisode(3, 1.0f);
  short_rewards.rewards.pop_back();
  EXPECT_THROW(writer.Add(short_rewards), DatasetError);
  DatasetReader reader(path);
  EXPECT_EQ(reader.demos(), std::vector<std::string>{"demo_0"});
  EXPECT_EQ(reader.total(), 3);
}

TEST(Dataset, CreateRefusesToOverwrite) {
  const auto path = TempPath("exists.hdf5");
  DatasetWriter::Create(path, {});
  EXPECT_THROW(DatasetWriter::Create(path, {}), IoError);
}

TEST(Dataset, NonHdf5FileGivesAClearError) {
  const auto path = TempPath("garbage.hdf5");
  std::ofstream(path) << "this is not hdf5";
  try {
    DatasetReader reader(path);
    FAIL();
  } catch (const DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos);
  }
  EXPECT_THROW(DatasetReader(TempPath("missing.hdf5")), IoError);
}

// tests/fixtures/robomimic_layout.hdf5 was written by h5py exactly as robomimic's
// dataset_states_to_obs.py writes (float64 actions/states, int64 dones, str env_args attribute,
// numpy 'S' masks, next_obs group); see make_robomimic_fixture.py beside it.
TEST(Dataset, ReadsAFileWrittenTheWayRobomimicWritesIt) {
  DatasetReader reader(std::filesystem::path(TWINFORGE_TEST_DATA_DIR) / "robomimic_layout.hdf5");
  ASSERT_EQ(reader.demos(), (std::vector<std::string>{"demo_0", "demo_1", "demo_10"}));
  EXPECT_EQ(reader.total(), 4 + 3 + 2);
  EXPECT_EQ(reader.env_args()["env_name"], "Lift");
  EXPECT_EQ(reader.Mask("train"), (std::vector<std::string>{"demo_0", "demo_10"}));
  EXPECT_EQ(reader.Mask("valid"), std::vector<std::string>{"demo_1"});
  const Episode e = reader.Read("demo_1");
  ASSERT_EQ(e.actions.shape, (std::vector<std::size_t>{3, 7}));
  EXPECT_FLOAT_EQ(e.actions.row(2)[6], 1.0f * 100 + 2 * 7 + 6);
  EXPECT_EQ(e.states.shape, (std::vector<std::size_t>{3, 10}));
  EXPECT_EQ(e.dones, (std::vector<uint8_t>{0, 0, 1}));
  EXPECT_FLOAT_EQ(e.rewards[2], 1.0f);
  ASSERT_TRUE(e.images.count("agentview_image"));
  EXPECT_EQ(e.images.at("agentview_image").shape, (std::vector<std::size_t>{3, 8, 8, 3}));
  EXPECT_EQ(e.images.at("agentview_image").data[5], 5);
  ASSERT_TRUE(e.obs.count("robot0_eef_pos"));
  EXPECT_FLOAT_EQ(e.obs.at("robot0_eef_pos").row(1)[2], 0.5f);
}

}  // namespace
}  // namespace twinforge::core
