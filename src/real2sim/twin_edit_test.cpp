#include "real2sim/twin_edit.h"

#include <gtest/gtest.h>
#include <open3d/Open3D.h>

#include <fstream>
#include <sstream>

#include "core/error.h"
#include "core/test_support.h"

namespace twinforge::real2sim {
namespace {

std::string ReadText(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A twin of one fixed block (0.2 x 0.3 x 0.1 m on the table at x = 0.6), its scan, and a scene
// exported with one camera.
std::filesystem::path MakeBlockTwin(const std::string& name) {
  const auto dir = core::testing::TestDir("twin_edit", name);
  auto box = open3d::geometry::TriangleMesh::CreateBox(0.2, 0.3, 0.1);
  box->Translate(Eigen::Vector3d(0.5, -0.15, 0));
  box = box->SubdivideMidpoint(3);
  box->PaintUniformColor(Eigen::Vector3d(0.8, 0.2, 0.1));
  const Mesh mesh{box->vertices_, box->vertex_colors_, box->triangles_};
  WriteMesh(dir / "meshes/block.ply", mesh);
  WriteMesh(dir / "scan.ply", mesh);
  TwinSpec spec;
  PartSpec block;
  block.name = "block";
  block.mesh = "meshes/block.ply";
  block.fixed = true;
  spec.parts.push_back(block);
  SaveTwinSpec(dir / "twin.yaml", spec);
  ExportOptions options;
  options.cameras.push_back(
      {"front", {Eigen::Vector3d(1.2, 0.1, 0.7), core::FromRollPitchYaw(-2.2, 0.05, 1.6)}, 50});
  ExportMjcf(spec, dir, options);
  return dir;
}

// What the editor sends to cut `block` in two at x = 0.6: the block keeps x < 0.6, a new part
// `piece` gets the rest, slides out along +x, and has a site.
core::Json CutSlideAndSite(const TwinEditSession& session) {
  core::Json spec = core::ToJson(session.spec());
  const core::Json box = {{"center", {0.65, 0, 0.05}}, {"size", {0.1, 0.4, 0.2}}};
  core::Json piece = spec["parts"][0];
  piece["name"] = "piece";
  piece["fixed"] = false;
  piece["cuts"].push_back({{"op", "intersect"}, {"box", box}});
  spec["parts"][0]["cuts"].push_back({{"op", "subtract"}, {"box", box}});
  spec["parts"].push_back(piece);
  spec["joints"].push_back({{"name", "slide"},
                            {"type", "prismatic"},
                            {"parent", "block"},
                            {"child", "piece"},
                            {"axis", {1, 0, 0}},
                            {"range", {0, 0.2}}});
  spec["sites"].push_back({{"name", "grip"}, {"part", "piece"}, {"position", {0.7, 0, 0.05}}});
  return spec;
}

std::string ProposalError(TwinEditSession& session, const core::Json& spec) {
  try {
    session.Propose(spec);
  } catch (const core::ConfigError& e) {
    return e.what();
  }
  return "accepted";
}

TEST(TwinEdit, ACutSplitsThePartsMeshBetweenTheTwoPieces) {
  TwinEditSession session(MakeBlockTwin("cut"));
  const auto whole = session.PartMeshJson("block");
  session.Propose(CutSlideAndSite(session));
  ASSERT_EQ(session.spec().parts.size(), 2u);
  const auto kept = session.PartMeshJson("block");
  const auto piece = session.PartMeshJson("piece");
  EXPECT_EQ(kept["indices"].size() + piece["indices"].size(), whole["indices"].size());
  EXPECT_GT(piece["indices"].size(), 0u);
  // Every vertex of the piece is in the cut box's half (x >= 0.6), within a triangle's size.
  for (std::size_t i = 0; i < piece["positions"].size(); i += 3)
    EXPECT_GT(piece["positions"][i].get<double>(), 0.58);
  EXPECT_EQ(piece["colors"].size(), piece["positions"].size());
  EXPECT_NEAR(piece["colors"][0].get<double>(), 0.8, 1e-3);
  EXPECT_TRUE(session.dirty());
  EXPECT_TRUE(session.can_undo());
  EXPECT_THROW(session.PartMeshJson("nothing"), core::ConfigError);
}

TEST(TwinEdit, AnInvalidEditIsRefusedWithTheFieldAndChangesNothing) {
  TwinEditSession session(MakeBlockTwin("invalid"));
  session.Propose(CutSlideAndSite(session));
  const core::Json before = session.State();

  core::Json twice = core::ToJson(session.spec());
  twice["sites"].push_back(twice["sites"][0]);
  const std::string duplicate = ProposalError(session, twice);
  EXPECT_NE(duplicate.find("twin.yaml (edit)"), std::string::npos) << duplicate;
  EXPECT_NE(duplicate.find("sites[1].name"), std::string::npos) << duplicate;
  EXPECT_NE(duplicate.find("'grip'"), std::string::npos) << duplicate;

  core::Json heavy = core::ToJson(session.spec());
  heavy["parts"][1]["mass"] = "heavy";
  EXPECT_NE(ProposalError(session, heavy).find("parts[1].mass"), std::string::npos);

  core::Json orphan = core::ToJson(session.spec());
  orphan["joints"][0]["parent"] = "shelf";
  EXPECT_NE(ProposalError(session, orphan).find("joints[0].parent"), std::string::npos);

  core::Json quote = core::ToJson(session.spec());
  quote["parts"][1]["name"] = "a\"b";
  EXPECT_NE(ProposalError(session, quote).find("parts[1].name"), std::string::npos);
  core::Json outside = core::ToJson(session.spec());
  outside["parts"][1]["mesh"] = "../block/meshes/block.ply";
  EXPECT_NE(ProposalError(session, outside).find("inside the twin"), std::string::npos);

  core::Json loop = core::ToJson(session.spec());
  loop["joints"].push_back({{"name", "back"}, {"parent", "piece"}, {"child", "block"}});
  EXPECT_NE(ProposalError(session, loop).find("loop"), std::string::npos);

  core::Json nothing_left = core::ToJson(session.spec());
  nothing_left["parts"][1]["cuts"].push_back(
      {{"op", "intersect"}, {"box", {{"center", {2, 2, 2}}, {"size", {0.1, 0.1, 0.1}}}}});
  const std::string emptied = ProposalError(session, nothing_left);
  EXPECT_NE(emptied.find("parts[1].cuts"), std::string::npos) << emptied;
  EXPECT_NE(emptied.find("the cuts leave nothing of meshes/block.ply"), std::string::npos)
      << emptied;

  EXPECT_EQ(session.State(), before);
}

TEST(TwinEdit, UndoStepsBackThroughAcceptedEditsOnly) {
  TwinEditSession session(MakeBlockTwin("undo"));
  const core::Json original = core::ToJson(session.spec());
  EXPECT_THROW(session.Undo(), core::ConfigError);
  session.Propose(CutSlideAndSite(session));
  const core::Json cut = core::ToJson(session.spec());
  core::Json heavier = cut;
  heavier["parts"][1]["mass"] = 2.5;
  session.Propose(heavier);
  EXPECT_DOUBLE_EQ(session.spec().parts[1].mass, 2.5);
  ProposalError(session, core::Json{{"parts", "none"}});  // refused: not on the stack
  session.Undo();
  EXPECT_EQ(core::ToJson(session.spec()), cut);
  session.Undo();
  EXPECT_EQ(core::ToJson(session.spec()), original);
  EXPECT_FALSE(session.dirty());
  EXPECT_FALSE(session.can_undo());
}

TEST(TwinEdit, SavingKeepsThePreviousSpecAsABackup) {
  const auto dir = MakeBlockTwin("save");
  const std::string original = ReadText(dir / "twin.yaml");
  TwinEditSession session(dir);
  session.Propose(CutSlideAndSite(session));
  EXPECT_EQ(session.Save(), dir / "twin.yaml");
  EXPECT_FALSE(session.dirty());
  EXPECT_EQ(ReadText(dir / "twin.yaml.bak"), original);
  // A second save in the session, and one with nothing changed, keep the file it started from.
  core::Json heavier = core::ToJson(session.spec());
  heavier["parts"][1]["mass"] = 2.0;
  session.Propose(heavier);
  session.Save();
  session.Save();
  EXPECT_EQ(ReadText(dir / "twin.yaml.bak"), original);
  const TwinSpec saved = LoadTwinSpec(dir / "twin.yaml");
  EXPECT_DOUBLE_EQ(saved.parts[1].mass, 2.0);
  ASSERT_EQ(saved.parts.size(), 2u);
  EXPECT_EQ(saved.parts[1].cuts.back().op, CutOp::kIntersect);
  EXPECT_EQ(saved.joints[0].type, JointType::kPrismatic);
  EXPECT_EQ(saved.sites[0].part, "piece");
  // Nothing but the temp-then-rename writes touched the directory.
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    files += entry.is_regular_file();
  EXPECT_EQ(files, 4);  // twin.yaml, twin.yaml.bak, scan.ply, scene.xml
}

TEST(TwinEdit, ExportSavesCompilesAndKeepsTheCameras) {
  const auto dir = MakeBlockTwin("export");
  const auto cameras = ReadSceneCameras(dir / "scene.xml");
  ASSERT_EQ(cameras.size(), 1u);
  const core::Pose written{Eigen::Vector3d(1.2, 0.1, 0.7), core::FromRollPitchYaw(-2.2, 0.05, 1.6)};
  EXPECT_LT((cameras[0].pose.translation - written.translation).norm(), 1e-9);
  EXPECT_LT(core::AngleBetween(cameras[0].pose.rotation, written.rotation), 1e-9);
  EXPECT_DOUBLE_EQ(cameras[0].fovy_deg, 50);

  TwinEditSession session(dir);
  session.Propose(CutSlideAndSite(session));
  const core::Json exported = session.Export();
  EXPECT_EQ(exported["saved"], (dir / "twin.yaml").string());
  EXPECT_FALSE(session.dirty());
  EXPECT_GT(exported["boxes"]["piece"].get<int>(), 0);
  int piece_collision = 0, piece_visual = 0, robot = 0;
  for (const auto& g : exported["geoms"]) {
    if (g["body"] == "piece") (g["collision"].get<bool>() ? piece_collision : piece_visual)++;
    robot += g["robot"].get<bool>();
    if (g["type"] == "mesh") {
      const auto& mesh = exported["meshes"][g["mesh"].get<int>()];
      EXPECT_GT(mesh["indices"].size(), 0u);
    }
  }
  EXPECT_EQ(piece_collision, exported["boxes"]["piece"].get<int>());
  EXPECT_EQ(piece_visual, 1);
  EXPECT_GT(robot, 0);
  const std::string scene = ReadText(dir / "scene.xml");
  EXPECT_NE(scene.find("<camera name=\"front\""), std::string::npos);
  EXPECT_NE(scene.find("name=\"slide\""), std::string::npos);
}

TEST(TwinEdit, TheScanIsSubsampledToTheBudget) {
  TwinEditSession session(MakeBlockTwin("scan"));
  const auto scan = session.ScanJson(100);
  EXPECT_LE(scan["positions"].size(), 300u);
  EXPECT_GE(scan["positions"].size(), 150u);
  EXPECT_EQ(scan["colors"].size(), scan["positions"].size());
}

TEST(TwinEdit, AMissingTwinIsNamed) {
  try {
    TwinEditSession session("/nonexistent/twin");
    FAIL() << "opened a twin that does not exist";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/twin/twin.yaml"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace twinforge::real2sim
