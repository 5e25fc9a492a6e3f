// render_cuda_none.cpp: makeCudaBackend in a build without the CUDA backend.
#include "canopy/errors.h"
#include "runtime/backend.h"

namespace canopy::play {

std::unique_ptr<Backend> makeCudaBackend(const HostScene&, uint32_t, int) {
  throw unsupported("canopy-play: this build has no CUDA backend (use --device cpu)");
}

}  // namespace canopy::play
