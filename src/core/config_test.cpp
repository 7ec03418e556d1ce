#include "core/config.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "core/fs.h"

namespace twinforge::core {
namespace {

enum class Mode { kDiscrete, kContinuous };

struct Range {
  double lo = 0, hi = 0;
  template <class A>
  void Serialize(A& a) {
    a("lo", lo);
    a("hi", hi);
    a.Require(lo <= hi, "hi", "a value >= lo");
  }
};

struct Example {
  int horizon = 100;
  double learning_rate = 3e-4;
  std::string name = "drawer";
  bool enabled = true;
  Mode mode = Mode::kDiscrete;
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  std::vector<Range> ranges;
  std::map<std::string, double> gains;
  std::optional<int> seed;
  template <class A>
  void Serialize(A& a) {
    a("horizon", horizon);
    a("learning_rate", learning_rate);
    a("name", name);
    a("enabled", enabled);
    a.Enum("mode", mode, {{"discrete", Mode::kDiscrete}, {"continuous", Mode::kContinuous}});
    a("offset", offset);
    a("ranges", ranges);
    a("gains", gains);
    a("seed", seed);
    a.Require(horizon > 0, "horizon", "a positive integer");
  }
};

std::string ErrorOf(const std::string& yaml) {
  try {
    ReadConfig<Example>(ParseConfigText(yaml, "task.yaml"));
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(Config, MissingFieldsKeepDefaults) {
  const auto value = ReadConfig<Example>(ParseConfigText("horizon: 50\n", "x.yaml"));
  EXPECT_EQ(value.horizon, 50);
  EXPECT_DOUBLE_EQ(value.learning_rate, 3e-4);
  EXPECT_EQ(value.name, "drawer");
  EXPECT_FALSE(value.seed.has_value());
}

TEST(Config, ReadsEveryFieldKind) {
  const auto value = ReadConfig<Example>(ParseConfigText(R"(
horizon: 7
learning_rate: 1
name: "123"
enabled: false
mode: continuous
offset: [1, 2.5, -3]
ranges: [{lo: -1, hi: 2}]
gains: {kp: 10, kd: 2}
seed: 4
)",
                                                         "x.yaml"));
  EXPECT_EQ(value.horizon, 7);
  EXPECT_DOUBLE_EQ(value.learning_rate, 1.0);  // an integer is a fine number
  EXPECT_EQ(value.name, "123");                // quoted stays a string
  EXPECT_FALSE(value.enabled);
  EXPECT_EQ(value.mode, Mode::kContinuous);
  EXPECT_DOUBLE_EQ(value.offset.y(), 2.5);
  ASSERT_EQ(value.ranges.size(), 1u);
  EXPECT_DOUBLE_EQ(value.ranges[0].hi, 2.0);
  EXPECT_DOUBLE_EQ(value.gains.at("kd"), 2.0);
  EXPECT_EQ(value.seed, 4);
}

TEST(Config, WrongTypeNamesFileLineFieldAndExpectation) {
  const std::string message = ErrorOf("name: ok\nhorizon: lots\n");
  EXPECT_NE(message.find("task.yaml:2"), std::string::npos) << message;
  EXPECT_NE(message.find("'horizon'"), std::string::npos) << message;
  EXPECT_NE(message.find("expected an integer"), std::string::npos) << message;
  EXPECT_NE(message.find("\"lots\""), std::string::npos) << message;
}

TEST(Config, NestedFieldPathIsDotted) {
  const std::string message = ErrorOf("ranges:\n  - {lo: 0, hi: 1}\n  - {lo: 0, hi: x}\n");
  EXPECT_NE(message.find("'ranges[1].hi'"), std::string::npos) << message;
  EXPECT_NE(message.find("task.yaml:3"), std::string::npos) << message;
}

TEST(Config, ValidationFailureNamesField) {
  EXPECT_NE(ErrorOf("horizon: 0\n").find("'horizon': expected a positive integer, got 0"),
            std::string::npos);
  EXPECT_NE(ErrorOf("ranges: [{lo: 2, hi: 1}]\n").find("'ranges[0].hi': expected a value >= lo"),
            std::string::npos);
}

TEST(Config, ValidateChecksAValueBuiltInCode) {
  Example e;
  e.ranges = {{0, 1}};
  EXPECT_NO_THROW(Validate(e, "flags"));
  e.ranges[0].hi = -1;
  try {
    Validate(e, "eval's flags");
    ADD_FAILURE() << "a range with hi < lo passed";
  } catch (const ConfigError& error) {
    EXPECT_EQ(error.file(), "eval's flags");
    EXPECT_EQ(error.field(), "ranges[0].hi");
    EXPECT_NE(std::string(error.what()).find("expected a value >= lo, got -1"), std::string::npos)
        << error.what();
  }
}

TEST(Config, UnknownFieldSuggestsTheClosestName) {
  const std::string message = ErrorOf("horizn: 3\n");
  EXPECT_NE(message.find("'horizn': unknown field"), std::string::npos) << message;
  EXPECT_NE(message.find("did you mean 'horizon'"), std::string::npos) << message;
}

TEST(Config, BadEnumListsChoices) {
  const std::string message = ErrorOf("mode: fast\n");
  EXPECT_NE(message.find("expected one of \"discrete\", \"continuous\""), std::string::npos)
      << message;
}

TEST(Config, WrongVectorLength) {
  EXPECT_NE(ErrorOf("offset: [1, 2]\n").find("expected a list of 3 numbers"), std::string::npos);
}

TEST(Config, MalformedYamlNamesFileAndLine) {
  const std::string message = ErrorOf("a: [1, 2\nb: 3\n");
  EXPECT_NE(message.find("task.yaml"), std::string::npos) << message;
  EXPECT_NE(message.find("not valid YAML/JSON"), std::string::npos) << message;
}

TEST(Config, MissingFileIsAnIoErrorNamingThePath) {
  try {
    LoadConfig<Example>("/nonexistent/dir/task.yaml");
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/dir/task.yaml"), std::string::npos);
  }
}

TEST(Config, RoundTripsThroughYamlAndJson) {
  Example value;
  value.horizon = 42;
  value.mode = Mode::kContinuous;
  value.offset = {0.1, 0.2, 0.3};
  value.ranges = {{-0.26, 0.16}};
  value.gains = {{"kp", 4500.0}};
  value.seed = 9;
  const auto dir = std::filesystem::temp_directory_path() / "twinforge_config_test";
  for (const char* name : {"c.yaml", "c.json"}) {
    SaveConfig(dir / name, value);
    const auto back = LoadConfig<Example>(dir / name);
    EXPECT_EQ(ToJson(back), ToJson(value)) << name;
  }
  std::filesystem::remove_all(dir);
}

TEST(Config, JsonFilesParse) {
  const auto value =
      ReadConfig<Example>(ParseConfigText(R"({"horizon": 12, "name": "x"})", "c.json"));
  EXPECT_EQ(value.horizon, 12);
}

}  // namespace
}  // namespace twinforge::core
