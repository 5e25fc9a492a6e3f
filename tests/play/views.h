// views.h: how the player's tests render: a converged view of a packed file, played on the CPU.
#pragma once
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "canopy/device.h"
#include "runtime/player.h"

namespace canopy::play::testing {

// The default options over `file` at w x h, every frame converged (the reference); `camera` as
// --camera ("" keeps the default orbit).
inline PlayOptions convergedView(const std::string& file, int w, int h, const std::string& camera = "") {
  PlayOptions o;
  o.input = file;
  o.width = w;
  o.height = h;
  o.converge = true;
  if (!camera.empty()) o.camera = camera;
  return o;
}

// Plays o on the CPU: the last frame's RGBA, and the report in `report`.
inline std::vector<float> render(const PlayOptions& o, nlohmann::json* report = nullptr) {
  std::vector<float> img;
  const nlohmann::json r = play(o, Device{}, &img);
  if (report) *report = r;
  return img;
}

}  // namespace canopy::play::testing
