// test_scene_json: the scene instance list reader/writer (formats/scene_json.h) that canopy-lbsolve,
// canopy-octreepack and canopy-voxelize share, under ASan/UBSan (the reader is compiled into this
// test). Every truncated prefix, every flipped byte, wrong versions, out-of-range models and
// non-finite / non-affine / singular matrices are rejected with a one-line canopy::Error naming the
// file and the entry; nothing else escapes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <string>

#include "canopy/errors.h"
#include "formats/scene_json.h"

namespace {

using canopy::ExitCode;

const char* kGood = R"({"canopy_scene": 1, "source": "grove.glb xxh64:0123456789abcdef",
  "models": [{"name": "oak", "mesh": 2, "density": "oak.density.vdb", "light": "oak.light.chaar"},
             {"density": "/abs/pine.density.vdb"}],
  "instances": [{"model": 0, "node": "Oak_1", "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]},
                {"model": 1, "matrix": [0,0,2,5, 0,2,0,0, -2,0,0,1.5, 0,0,0,1]}]})";

nlohmann::json good() { return nlohmann::json::parse(kGood); }

// Runs the reader on a document; returns the error (code, message) or ExitCode::Ok.
std::pair<ExitCode, std::string> check(const nlohmann::json& doc) {
  try {
    canopy::sceneFromJson(doc, "s.scene.json", "dir/");
  } catch (const canopy::Error& e) {
    return {e.code(), e.what()};
  }
  return {ExitCode::Ok, ""};
}

std::string tmpFile(const std::string& name, const std::string& text) {
  const std::string dir = std::string(CANOPY_BINARY_DIR) + "/tests/octreepack/scene_json";
  std::system(("mkdir -p '" + dir + "'").c_str());
  std::ofstream(dir + "/" + name, std::ios::binary) << text;
  return dir + "/" + name;
}

TEST(SceneJson, ReadsModelsInstancesAndResolvesPaths) {
  const canopy::Scene s = canopy::sceneFromJson(good(), "s.scene.json", "dir/");
  EXPECT_EQ(s.source, "grove.glb xxh64:0123456789abcdef");
  ASSERT_EQ(s.models.size(), 2u);
  EXPECT_EQ(s.models[0].name, "oak");
  EXPECT_EQ(s.models[0].mesh, 2);
  EXPECT_EQ(s.models[0].density, "dir/oak.density.vdb");
  EXPECT_EQ(s.models[0].light, "dir/oak.light.chaar");
  EXPECT_EQ(s.models[1].name, "model1");  // default label
  EXPECT_EQ(s.models[1].mesh, -1);
  EXPECT_EQ(s.models[1].density, "/abs/pine.density.vdb");  // absolute paths stay
  EXPECT_TRUE(s.models[1].light.empty());
  ASSERT_EQ(s.instances.size(), 2u);
  EXPECT_EQ(s.instances[0].node, "Oak_1");
  EXPECT_EQ(s.instances[1].model, 1u);
  EXPECT_EQ(s.instances[1].matrix[3], 5.0);
  EXPECT_EQ(s.instances[1].matrix[11], 1.5);
}

TEST(SceneJson, WriteThenReadGivesTheSameSceneAndBytes) {
  canopy::Scene s = canopy::sceneFromJson(good(), "s.scene.json");
  s.instances[1].matrix[3] = 0.1 + 0.2;  // doubles round-trip exactly (shortest repr.)
  const std::string path = tmpFile("rt.scene.json", "");
  canopy::writeSceneJson(path, s);
  const canopy::Scene r = canopy::readSceneJson(path);
  const std::string dir = path.substr(0, path.find_last_of('/') + 1);
  ASSERT_EQ(r.models.size(), s.models.size());
  EXPECT_EQ(r.models[0].density, dir + s.models[0].density);  // resolved against the file's folder
  EXPECT_EQ(r.models[0].mesh, 2);
  EXPECT_EQ(r.source, s.source);
  for (size_t i = 0; i < s.instances.size(); ++i) {
    EXPECT_EQ(r.instances[i].matrix, s.instances[i].matrix);
    EXPECT_EQ(r.instances[i].node, s.instances[i].node);
  }
  EXPECT_EQ(canopy::sceneToJson(canopy::sceneFromJson(canopy::sceneToJson(s), "x")), canopy::sceneToJson(s));
}

TEST(SceneJson, EveryTruncatedPrefixIsRejected) {
  const std::string text = good().dump();
  const std::string path = tmpFile("prefix.scene.json", "");
  for (size_t n = 0; n < text.size(); ++n) {
    std::ofstream(path, std::ios::binary | std::ios::trunc) << text.substr(0, n);
    try {
      canopy::readSceneJson(path);
      ADD_FAILURE() << "prefix of " << n << " bytes accepted";
    } catch (const canopy::Error& e) {
      ASSERT_EQ(e.code(), ExitCode::InvalidInput) << n << ": " << e.what();
      ASSERT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      ASSERT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
  }
}

TEST(SceneJson, FlippedBytesAreRejectedOrGiveAValidScene) {
  const std::string text = good().dump();
  size_t rejected = 0;
  for (size_t i = 0; i < text.size(); ++i)
    for (unsigned char mask : {0x01, 0x20, 0x80}) {
      std::string t = text;
      t[i] = char(t[i] ^ mask);
      const nlohmann::json j = nlohmann::json::parse(t, nullptr, false);
      if (j.is_discarded()) {
        ++rejected;  // readJsonFile's "not valid JSON"
        continue;
      }
      const auto [code, what] = check(j);
      if (code == ExitCode::Ok) continue;  // e.g. a digit of a matrix entry changed
      ++rejected;
      ASSERT_TRUE(code == ExitCode::InvalidInput || code == ExitCode::Unsupported) << what;
      ASSERT_EQ(what.rfind("s.scene.json: ", 0), 0u) << what;
    }
  EXPECT_GT(rejected, text.size());  // most flips break something
}

TEST(SceneJson, GarbageAndWrongShapesAreInvalidInput) {
  const std::string path = tmpFile("garbage.scene.json", "\x89PNG\r\n\x1a\n garbage");
  try {
    canopy::readSceneJson(path);
    FAIL();
  } catch (const canopy::Error& e) {
    EXPECT_EQ(e.code(), ExitCode::InvalidInput);
    EXPECT_NE(std::string(e.what()).find("not valid JSON"), std::string::npos) << e.what();
  }
  try {
    canopy::readSceneJson(path + ".missing");
    FAIL();
  } catch (const canopy::Error& e) {
    EXPECT_EQ(e.code(), ExitCode::Io);
  }
  const std::pair<const char*, const char*> cases[] = {
      {"[1, 2]", "not a Canopy scene"},
      {R"({"models": []})", "not a Canopy scene"},
      {R"({"canopy_scene": 1, "instances": []})", "'models' must be a non-empty array"},
      {R"({"canopy_scene": 1, "models": [], "instances": []})", "'models' must be a non-empty array"},
      {R"({"canopy_scene": 1, "models": [{"density": "a"}]})", "'instances' must be a non-empty array"},
      {R"({"canopy_scene": 1, "models": [{"density": "a"}], "instances": []})", "'instances' must be a non-empty array"},
      {R"({"canopy_scene": 1, "models": [{"name": "a"}], "instances": [{}]})", "models[0] needs a 'density' path"},
      {R"({"canopy_scene": 1, "models": [{"density": ""}], "instances": [{}]})", "models[0] needs a 'density' path"},
      {R"({"canopy_scene": 1, "models": [{"density": "a", "name": 3}], "instances": [{}]})", "models[0].name must be a string"},
      {R"({"canopy_scene": 1, "models": [{"density": "a", "light": 1}], "instances": [{}]})", "models[0].light must be"},
      {R"({"canopy_scene": 1, "models": [{"density": "a", "mesh": -2}], "instances": [{}]})", "models[0].mesh must be"},
      {R"({"canopy_scene": 1, "models": [{"density": "a"}], "instances": [{"model": "0"}]})", "instances[0] needs an integer 'model'"},
      {R"({"canopy_scene": 1, "models": [{"density": "a"}], "instances": [{"model": 0, "matrix": [1,2]}]})",
       "instances[0].matrix must be 16 numbers"},
      {R"({"canopy_scene": 1, "models": [{"density": "a"}], "instances": [{"model": 0, "matrix": [1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,"1"]}]})",
       "instances[0].matrix must be 16 numbers"},
      {R"({"canopy_scene": 1, "source": 7, "models": [{"density": "a"}], "instances": [{}]})", "'source' must be a string"},
  };
  for (const auto& [doc, want] : cases) {
    const auto [code, what] = check(nlohmann::json::parse(doc));
    EXPECT_EQ(code, ExitCode::InvalidInput) << doc;
    EXPECT_NE(what.find(want), std::string::npos) << doc << " -> " << what;
  }
}

TEST(SceneJson, OtherVersionsAreUnsupported) {
  for (const char* v : {"2", "0", "-1", "18446744073709551615"}) {
    nlohmann::json j = good();
    j["canopy_scene"] = nlohmann::json::parse(v);
    const auto [code, what] = check(j);
    EXPECT_EQ(code, ExitCode::Unsupported) << v;
    EXPECT_NE(what.find("scene format version " + std::string(v) + " is not supported (1)"), std::string::npos) << what;
  }
  for (const char* v : {"1.0", "\"1\"", "null"}) {
    nlohmann::json j = good();
    j["canopy_scene"] = nlohmann::json::parse(v);
    EXPECT_EQ(check(j).first, ExitCode::InvalidInput) << v;
  }
}

TEST(SceneJson, OutOfRangeModelsAreRejected) {
  for (const char* m : {"2", "-1", "4294967296", "18446744073709551615"}) {
    nlohmann::json j = good();
    j["instances"][1]["model"] = nlohmann::json::parse(m);
    const auto [code, what] = check(j);
    EXPECT_EQ(code, ExitCode::InvalidInput) << m;
    EXPECT_NE(what.find("s.scene.json: instances[1].model "), std::string::npos) << what;
    EXPECT_NE(what.find("out of range (2 models)"), std::string::npos) << what;
  }
}

TEST(SceneJson, NonFiniteNonAffineAndSingularMatricesAreRejected) {
  const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
  const std::pair<std::pair<int, double>, const char*> cases[] = {
      {{3, nan}, "instances[1].matrix is not finite"},
      {{0, inf}, "instances[1].matrix is not finite"},
      {{15, -inf}, "instances[1].matrix is not finite"},
      {{3, 1e20}, "instances[1].matrix has an entry beyond 1e9 in magnitude"},  // play cannot render it
      {{0, -2e9}, "instances[1].matrix has an entry beyond 1e9 in magnitude"},
      {{12, 0.5}, "instances[1].matrix last row must be 0,0,0,1"},
      {{15, 2.0}, "instances[1].matrix last row must be 0,0,0,1"},
      {{2, 0.0}, "instances[1].matrix is singular"},  // the row (0,0,2) becomes 0: rank 2
  };
  for (const auto& [edit, want] : cases) {
    nlohmann::json j = good();
    j["instances"][1]["matrix"][size_t(edit.first)] = edit.second;
    const auto [code, what] = check(j);
    EXPECT_EQ(code, ExitCode::InvalidInput) << want;
    EXPECT_EQ(what, std::string("s.scene.json: ") + want);
  }
  // checkScene applies the same rules to scenes that did not come from JSON (glTF).
  canopy::Scene s = canopy::sceneFromJson(good(), "s");
  s.instances[0].matrix[5] = nan;
  try {
    canopy::checkScene(s, "grove.glb");
    FAIL();
  } catch (const canopy::Error& e) {
    EXPECT_EQ(std::string(e.what()), "grove.glb: instances[0].matrix is not finite");
  }
}

}  // namespace
