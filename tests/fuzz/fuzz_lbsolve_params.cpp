// libFuzzer harness: arbitrary bytes as a canopy-lbsolve parameter file. The reader must either
// accept them (and then hold valid parameters) or throw canopy::Error(InvalidInput); any other
// exception, crash or sanitizer report is a bug.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include <nlohmann/json.hpp>

#include "canopy/errors.h"
#include "params.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const nlohmann::json j = nlohmann::json::parse(data, data + size, nullptr, false);
  if (j.is_discarded()) return 0;  // loadParams reports this as "not valid JSON"
  canopy::lb::LightParams p;
  try {
    canopy::lb::applyParams(p, j, "fuzz.json");
  } catch (const canopy::Error& e) {
    if (e.code() != canopy::ExitCode::InvalidInput) std::abort();
    return 0;
  }
  p.validate("fuzz.json");  // accepted parameters must be valid (throws -> libFuzzer reports)
  for (int c = 0; c < 3; ++c)
    if (!(p.g[c] >= -1 && p.g[c] <= 1)) std::abort();
  return 0;
}
