// json_file.h: reading a JSON input file (parameter files, scene lists, keyframe paths).
#pragma once
#include <string>

#include <nlohmann/json.hpp>

namespace canopy {

// Parses the whole file. Throws canopy::Error: Io naming the path if it cannot be read,
// InvalidInput "<path>: not valid JSON (<first line of the parser's message>)" if it does not parse.
nlohmann::json readJsonFile(const std::string& path);

}  // namespace canopy
