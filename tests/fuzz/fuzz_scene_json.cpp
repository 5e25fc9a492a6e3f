// libFuzzer harness: arbitrary bytes as a scene instance list (formats/scene_json.h), the reader
// canopy-lbsolve and canopy-octreepack share. It must either accept them (and then the scene holds
// its invariants and survives a write/read round trip) or throw canopy::Error (InvalidInput, or
// Unsupported for another version); any other exception, crash or sanitizer report is a bug.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include <nlohmann/json.hpp>

#include "canopy/errors.h"
#include "formats/scene_json.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const nlohmann::json j = nlohmann::json::parse(data, data + size, nullptr, false);
  if (j.is_discarded()) return 0;  // readSceneJson reports this as "not valid JSON"
  canopy::Scene s;
  try {
    s = canopy::sceneFromJson(j, "fuzz.scene.json", "base/");
  } catch (const canopy::Error& e) {
    if (e.code() != canopy::ExitCode::InvalidInput && e.code() != canopy::ExitCode::Unsupported) std::abort();
    return 0;
  }
  if (s.models.empty() || s.instances.empty()) std::abort();
  for (const auto& m : s.models)
    if (m.density.empty()) std::abort();
  for (const auto& in : s.instances) {
    if (in.model >= s.models.size()) std::abort();
    for (double v : in.matrix)
      if (!std::isfinite(v)) std::abort();
  }
  const canopy::Scene again = canopy::sceneFromJson(canopy::sceneToJson(s), "again.scene.json");
  if (again.models.size() != s.models.size() || again.instances.size() != s.instances.size()) std::abort();
  for (size_t i = 0; i < s.instances.size(); ++i)
    if (again.instances[i].matrix != s.instances[i].matrix) std::abort();
  return 0;
}
