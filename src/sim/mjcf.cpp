#include "sim/mjcf.h"

#include <tinyxml2.h>

#include <sstream>

#include "core/error.h"
#include "core/fs.h"

namespace twinforge::sim {

namespace {

using tinyxml2::XMLDocument;
using tinyxml2::XMLElement;
using tinyxml2::XMLNode;

void Parse(XMLDocument& doc, const std::filesystem::path& path) {
  const std::string text = core::ReadTextFile(path);
  if (doc.Parse(text.c_str()) != tinyxml2::XML_SUCCESS)
    throw core::ConfigError(path.string(), "",
                            std::string("not well-formed XML: ") + doc.ErrorStr());
  if (!doc.RootElement() || std::string(doc.RootElement()->Name()) != "mujoco")
    throw core::ConfigError(path.string(), "", "expected an MJCF file with a <mujoco> root");
}

// Rewrites file="..." attributes under <asset> to absolute paths, honouring meshdir/texturedir.
void AbsolutizeAssets(XMLElement* root, const std::filesystem::path& source) {
  std::filesystem::path meshdir = source.parent_path(), texturedir = source.parent_path();
  if (XMLElement* compiler = root->FirstChildElement("compiler")) {
    if (const char* d = compiler->Attribute("meshdir")) meshdir /= d;
    if (const char* d = compiler->Attribute("texturedir")) texturedir /= d;
  }
  for (XMLElement* asset = root->FirstChildElement("asset"); asset;
       asset = asset->NextSiblingElement("asset")) {
    for (XMLElement* e = asset->FirstChildElement(); e; e = e->NextSiblingElement()) {
      const char* file = e->Attribute("file");
      if (!file) continue;
      const std::filesystem::path dir = std::string(e->Name()) == "mesh" ? meshdir : texturedir;
      const std::filesystem::path p(file);
      e->SetAttribute("file", (p.is_absolute() ? p : (dir / p).lexically_normal()).c_str());
    }
  }
}

// Replaces each top-level <include file="..."/> (a path relative to the including file) by the
// children of that file's <mujoco> root, its own includes expanded and asset paths made
// absolute first: a scene variant is its base scene plus what it adds.
void ExpandIncludes(XMLDocument& doc, XMLElement* root, const std::filesystem::path& source,
                    int depth = 0) {
  for (XMLElement* inc = root->FirstChildElement("include"); inc;) {
    XMLElement* next = inc->NextSiblingElement("include");
    const char* file = inc->Attribute("file");
    if (!file)
      throw core::ConfigError(source.string(), "include", "an <include> needs a file attribute");
    if (depth >= 8)
      throw core::ConfigError(source.string(), "include",
                              "includes nested deeper than 8 (a loop?)");
    const std::filesystem::path path = (source.parent_path() / file).lexically_normal();
    XMLDocument included;
    Parse(included, path);
    XMLElement* inc_root = included.RootElement();
    AbsolutizeAssets(inc_root, path);
    ExpandIncludes(included, inc_root, path, depth + 1);
    for (const XMLNode* child = inc_root->FirstChild(); child; child = child->NextSibling())
      if (child->ToElement()) root->InsertEndChild(child->DeepClone(&doc));
    root->DeleteChild(inc);
    inc = next;
  }
}

// Appends deep copies of every child of each <section> in `from` to `into`'s <section>.
void CopySection(XMLDocument& out, XMLElement* into_root, XMLElement* from_root,
                 const char* section, XMLElement* into = nullptr) {
  for (XMLElement* s = from_root->FirstChildElement(section); s;
       s = s->NextSiblingElement(section)) {
    if (!into) {
      into = into_root->FirstChildElement(section);
      if (!into) into = into_root->InsertNewChildElement(section);
    }
    for (const XMLNode* child = s->FirstChild(); child; child = child->NextSibling())
      if (child->ToElement()) into->InsertEndChild(child->DeepClone(&out));
  }
}

}  // namespace

std::string FormatNumbers(const double* v, int n) {
  std::ostringstream s;
  s.precision(17);
  for (int i = 0; i < n; ++i) s << (i ? " " : "") << v[i];
  return s.str();
}

std::string AssembleMjcf(const MjcfParts& parts) {
  XMLDocument robot, scene, out;
  Parse(robot, parts.robot);
  Parse(scene, parts.scene);
  XMLElement* robot_root = robot.RootElement();
  XMLElement* scene_root = scene.RootElement();
  AbsolutizeAssets(robot_root, parts.robot);
  AbsolutizeAssets(scene_root, parts.scene);
  ExpandIncludes(scene, scene_root, parts.scene);

  XMLElement* root = out.NewElement("mujoco");
  out.InsertFirstChild(root);
  root->SetAttribute("model", "twinforge_task");
  XMLElement* compiler = root->InsertNewChildElement("compiler");
  compiler->SetAttribute("angle", "radian");
  compiler->SetAttribute("autolimits", "true");
  XMLElement* option = root->InsertNewChildElement("option");
  option->SetAttribute("timestep", parts.timestep);
  option->SetAttribute("integrator", "implicit");
  option->SetAttribute("cone", "elliptic");
  option->SetAttribute("impratio", "5");
  // Bodies (distractors) may be created far away; no sleep or warmstart tricks are relied on.
  for (const char* section : {"size", "visual", "statistic"})
    CopySection(out, root, scene_root, section);
  for (XMLElement* source : {robot_root, scene_root}) {
    CopySection(out, root, source, "default");
    CopySection(out, root, source, "asset");
  }
  XMLElement* world = root->InsertNewChildElement("worldbody");
  CopySection(out, root, scene_root, "worldbody", world);
  XMLElement* mount = world->InsertNewChildElement("body");
  mount->SetAttribute("name", "robot_mount");
  mount->SetAttribute("pos", FormatNumbers(parts.robot_mount.translation.data(), 3).c_str());
  double quat[4];
  core::QuatToMj(parts.robot_mount.rotation, quat);
  mount->SetAttribute("quat", FormatNumbers(quat, 4).c_str());
  CopySection(out, root, robot_root, "worldbody", mount);
  if (!parts.extra_worldbody.empty()) {
    XMLDocument extra;
    const std::string wrapped = "<worldbody>" + parts.extra_worldbody + "</worldbody>";
    if (extra.Parse(wrapped.c_str()) != tinyxml2::XML_SUCCESS)
      throw core::Error(std::string("generated MJCF is not well-formed: ") + extra.ErrorStr());
    for (const XMLNode* child = extra.RootElement()->FirstChild(); child;
         child = child->NextSibling())
      world->InsertEndChild(child->DeepClone(&out));
  }
  for (const char* section : {"contact", "equality", "tendon", "actuator", "sensor"})
    for (XMLElement* source : {robot_root, scene_root}) CopySection(out, root, source, section);

  tinyxml2::XMLPrinter printer;
  out.Print(&printer);
  return printer.CStr();
}

}  // namespace twinforge::sim
