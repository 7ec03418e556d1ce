#include "pipeline/sensing_q_training.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/test_support.h"
#include "learn/torch_runtime.h"

namespace twinforge::pipeline {
namespace {

nlohmann::json ReadJson(const std::filesystem::path& file) {
  std::ifstream in(file);
  return nlohmann::json::parse(in);
}

// Which of the episodes succeeded, by trial, as q.json lists them.
std::vector<bool> Outcomes(const std::filesystem::path& dir) {
  // (Held in a local: a range-for over a member of a temporary reads freed memory.)
  const nlohmann::json meta = ReadJson(dir / "q.json");
  std::vector<bool> outcomes;
  for (const auto& v : meta.at("views")) outcomes.push_back(v.at("success"));
  EXPECT_FALSE(outcomes.empty()) << dir;
  return outcomes;
}

// Rewrites a JSON-lines file in place, each line (numbered from 0) as `edit` returns it.
void EditLines(const std::filesystem::path& file,
               const std::function<std::string(int, std::string)>& edit) {
  std::ifstream in(file);
  std::string text, line;
  for (int n = 0; std::getline(in, line); ++n) text += edit(n, line) + "\n";
  in.close();
  std::ofstream(file) << text;
}

// The share of a look's objects not held that `belief` (a looks line's "objects" or "after") puts
// within 3 mm of its "truth", in the table's plane.
double ShareFound(const nlohmann::json& look, const char* belief) {
  int targets = 0, found = 0;
  for (const auto& [name, truth] : look.at("truth").items()) {
    if (name == look.at("held").get<std::string>()) continue;
    const auto& b = look.at(belief).at(name);
    ++targets;
    found += std::hypot(b[0].get<double>() - truth[0].get<double>(),
                        b[1].get<double>() - truth[1].get<double>()) <= 0.003;
  }
  return targets == 0 ? 1.0 : double(found) / targets;
}

// A small run: `episodes` on two workers, frames at twice the task camera's resolution, Q fitted
// in `fit_steps`.
SensingQTrainOptions SmallRun(int episodes, int fit_steps) {
  SensingQTrainOptions o;
  o.episodes = episodes;
  o.capture_scale = 2;
  o.fit.steps = fit_steps;
  o.workers = 2;
  return o;
}

// train samrl's loop, small: 6 simulated episodes of the twin actor on the occluded peg's twin,
// each look from its own random view and recorded with the actor's plan then. The episodes and
// their outcomes do not depend on how many workers run them; a second run reads them all back
// (a torn last line of a looks file dropped); the Q reads the plan, or with --view-only the view
// alone; it loads for this twin and is refused, by name, for another.
TEST(TrainSensingQ, RunsEpisodesResumesAndLoadsForItsTwinOnly) {
  learn::PinMathThreads(1);
  const sim::TaskSpec twin = sim::LoadTaskSpec("peg_insertion_occluded");
  const std::filesystem::path dir = core::testing::TestDir("sensing_q");
  SensingQTrainOptions o = SmallRun(6, 20);
  const SensingQTrainReport two = TrainSensingQ(twin, o, dir / "two");
  EXPECT_EQ(two.episodes, 6);
  EXPECT_EQ(two.resumed, 0);
  EXPECT_TRUE(std::filesystem::exists(dir / "two" / "episodes.0.jsonl"));
  EXPECT_TRUE(std::filesystem::exists(dir / "two" / "episodes.1.jsonl"));
  o.workers = 1;
  const SensingQTrainReport one = TrainSensingQ(twin, o, dir / "one");
  EXPECT_EQ(Outcomes(dir / "one"), Outcomes(dir / "two"));
  EXPECT_EQ(one.successes, two.successes);
  const nlohmann::json views = ReadJson(dir / "one" / "q.json").at("views");
  ASSERT_EQ(int(views.size()), one.looks);
  EXPECT_GE(one.looks, 6);
  EXPECT_LE(one.looks, 6 * o.max_looks);
  EXPECT_NE(views[0].at("azimuth"), views[1].at("azimuth")) << "each look its own view";
  const int steps = int(twin.expert.steps.size());
  for (const auto& v : views) {
    EXPECT_GE(v.at("step").get<int>(), 0);
    EXPECT_LE(v.at("step").get<int>(), steps);
    if (v.at("look").get<int>() == 0) EXPECT_EQ(v.at("step").get<int>(), 0) << v;
  }

  o.workers = 2;
  std::ofstream(dir / "two" / "looks.0.jsonl", std::ios::app) << "{\"seed\": 1, \"lo";
  const SensingQTrainReport again = TrainSensingQ(twin, o, dir / "two");
  EXPECT_EQ(again.resumed, 6);
  EXPECT_EQ(again.looks, one.looks);
  EXPECT_EQ(Outcomes(dir / "two"), Outcomes(dir / "one"));

  const SensingQModel q = LoadSensingQ(two.q_file, twin);
  EXPECT_EQ(q.net->action_dim(), steps) << "Q reads the plan";
  EXPECT_EQ(q.search.width, 40);
  o.plan = false;
  const SensingQTrainReport view_only = TrainSensingQ(twin, o, dir / "two");
  EXPECT_EQ(view_only.resumed, 6) << "the same episodes, fitted again";
  EXPECT_EQ(LoadSensingQ(view_only.q_file, twin).net->action_dim(), 0);
  // --return closeness: the same episodes, each return how near the twin came to success.
  o.ret = SensingQTrainOptions::Return::kCloseness;
  const SensingQTrainReport dense = TrainSensingQ(twin, o, dir / "two");
  EXPECT_EQ(dense.resumed, 6);
  const nlohmann::json dense_views = ReadJson(dir / "two" / "q.json").at("views");
  int failed_looks = 0, partly_near = 0;
  for (const auto& v : dense_views) {
    const double r = v.at("return");
    if (v.at("success").get<bool>()) {
      EXPECT_EQ(r, 1.0) << v;
    } else {
      ++failed_looks;
      EXPECT_GE(r, 0.0) << v;
      EXPECT_LT(r, 1.0) << v;
      partly_near += r > 0;
    }
  }
  EXPECT_GT(failed_looks, 0) << "all 6 episodes succeeded: the test shows nothing of closeness";
  EXPECT_GT(partly_near, 0) << "every failure scored 0: closeness told them apart no better";
  // Episodes logged without it (before it was) are refused by name, not read as 0.
  EditLines(dir / "two" / "episodes.0.jsonl", [](int n, std::string line) {
    if (n == 1)
      line.replace(line.find("\"grader\""), std::string("\"grader\"").size(), "\"judge\"");
    return line;
  });
  try {
    TrainSensingQ(twin, o, dir / "two");
    ADD_FAILURE() << "an episode without its closeness was fitted";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("success_closeness"), std::string::npos) << e.what();
  }

  // --return look: each look's own return, the share of the objects not held that the actor
  // believed within 3 mm of where they stood once it had looked. Every look line holds the twin's
  // truth and the belief after the look; the belief before a first look is the twin's nominal
  // scene, which the random scenes put elsewhere, so it finds less than the belief after.
  o.ret = SensingQTrainOptions::Return::kLook;
  const SensingQTrainReport own = TrainSensingQ(twin, o, dir / "two");
  EXPECT_EQ(own.resumed, 6);
  // The episodes' actor looks again as eval's does with a chosen view (EpisodeRelook): a later
  // look that sees an object it does not hold believes it where it put it, even a shift too small
  // to count as a move (under 2.5 mm, the least `moved` bound); without, only moves change it.
  double before_first = 0, after_first = 0;
  int refined = 0;
  for (const char* name : {"looks.0.jsonl", "looks.1.jsonl"}) {
    std::ifstream in(dir / "two" / name);
    for (std::string line; std::getline(in, line);) {
      const nlohmann::json look = nlohmann::json::parse(line);
      ASSERT_EQ(look.at("truth").size(), twin.objects.size()) << line;
      ASSERT_EQ(look.at("after").size(), twin.objects.size()) << line;
      if (look.at("look").get<int>() == 0) {
        before_first += ShareFound(look, "objects");
        after_first += ShareFound(look, "after");
        continue;
      }
      for (const auto& [object, after] : look.at("after").items()) {
        if (look.at("held") == object) continue;
        const auto& before = look.at("objects").at(object);
        const double shift = std::hypot(after[0].get<double>() - before[0].get<double>(),
                                        after[1].get<double>() - before[1].get<double>());
        refined += shift > 1e-5 && shift < 0.0025;
      }
    }
  }
  EXPECT_GT(after_first, before_first) << "the belief after a first look is no nearer the truth";
  EXPECT_GT(refined, 0) << "no later look put an object where it saw it, short of a move";
  int found_all = 0, missed = 0;
  const nlohmann::json own_views = ReadJson(dir / "two" / "q.json").at("views");
  for (const auto& v : own_views) {
    const double r = v.at("return");
    EXPECT_TRUE(r == 0 || r == 0.5 || r == 1) << v;
    found_all += r == 1;
    missed += r < 1;
  }
  EXPECT_GT(found_all, 0) << "no look found its objects";
  EXPECT_GT(missed, 0) << "every look found its objects: the return tells no view from another";
  // Looks logged before the truth was are refused by name, not read as found.
  EditLines(dir / "two" / "looks.1.jsonl", [](int n, const std::string& line) {
    nlohmann::json j = nlohmann::json::parse(line);
    if (n == 0) j.erase("truth");
    return j.dump();
  });
  try {
    TrainSensingQ(twin, o, dir / "two");
    ADD_FAILURE() << "a look without the twin's truth was fitted";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("truth"), std::string::npos) << e.what();
  }
  o.ret = SensingQTrainOptions::Return::kSuccess;
  EXPECT_EQ(q.mount.radius, samrl::ObjectsMount(sim::Task(twin)).radius);
  try {
    LoadSensingQ(two.q_file, sim::LoadTaskSpec("peg_insertion"));
    ADD_FAILURE() << "a Q of another twin was loaded";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("another twin"), std::string::npos) << e.what();
  }
  EXPECT_THROW(LoadSensingQ(dir / "missing.pt", twin), core::Error);
  // A q.json that describes another q.pt (a run killed between writing the two) is refused.
  nlohmann::json meta = ReadJson(dir / "two" / "q.json");
  meta["q_hash"] = "0";
  std::ofstream(dir / "two" / "q.json") << meta.dump();
  try {
    LoadSensingQ(two.q_file, twin);
    ADD_FAILURE() << "a q.json of another q.pt was accepted";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("describes another"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

// What the actor's earlier frames showed in the way is part of the view Q is fitted to, as the
// active look renders it at run time: on the hidden peg the screen stands elsewhere than the
// twin has it, so looks after the first are told of its columns. Looks files written before they
// were recorded are read as telling of none.
TEST(TrainSensingQ, FitsEachViewWithWhatEarlierFramesShowedInTheWay) {
  learn::PinMathThreads(1);
  const sim::TaskSpec twin = sim::LoadTaskSpec("peg_insertion_hidden");
  const std::filesystem::path dir = core::testing::TestDir("sensing_q_occluders");
  const SensingQTrainOptions o = SmallRun(4, 5);
  TrainSensingQ(twin, o, dir);
  const nlohmann::json told = ReadJson(dir / "q.json").at("views");
  int later_looks = 0, with_occluders = 0;
  for (const auto& v : told) {
    if (v.at("look").get<int>() == 0) {
      EXPECT_EQ(v.at("occluders").get<int>(), 0) << "a first look is told of nothing" << v;
    } else {
      ++later_looks;
      with_occluders += v.at("occluders").get<int>() > 0;
    }
  }
  ASSERT_GT(later_looks, 0);
  EXPECT_GT(with_occluders, 0) << "no look was told of the screen standing elsewhere";

  // The same looks as a file from before stop 75 holds them: no occluders, the views rendered
  // without them. A column only hides what is behind it: no view shows the targets less for
  // losing them, and some show them more.
  for (const char* name : {"looks.0.jsonl", "looks.1.jsonl"})
    EditLines(dir / name, [](int, const std::string& line) {
      nlohmann::json j = nlohmann::json::parse(line);
      j.erase("occluders");
      return j.dump();
    });
  const SensingQTrainReport old = TrainSensingQ(twin, o, dir);
  EXPECT_EQ(old.resumed, 4);
  const nlohmann::json untold = ReadJson(dir / "q.json").at("views");
  ASSERT_EQ(untold.size(), told.size());
  int shown_more = 0;
  for (std::size_t i = 0; i < told.size(); ++i) {
    EXPECT_EQ(untold[i].at("occluders").get<int>(), 0);
    const double with = told[i].at("targets_fill"), without = untold[i].at("targets_fill");
    EXPECT_GE(without, with - 1e-9) << told[i];
    shown_more += without > with + 1e-6;
  }
  EXPECT_GT(shown_more, 0) << "no view had a column in front of its targets";
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace twinforge::pipeline
