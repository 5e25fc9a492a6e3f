// json_file.cpp: see json_file.h.
#include "canopy/json_file.h"

#include "canopy/atomic_file.h"
#include "canopy/errors.h"

namespace canopy {

nlohmann::json readJsonFile(const std::string& path) {
  const auto bytes = readFile(path);
  try {
    return nlohmann::json::parse(bytes.begin(), bytes.end());
  } catch (const std::exception& e) {
    const std::string what = e.what();
    throw invalidInput(path + ": not valid JSON (" + what.substr(0, what.find('\n')) + ")");
  }
}

}  // namespace canopy
