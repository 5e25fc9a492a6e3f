// lattice_io.cpp: see lattice_io.h.
#include "lattice_io.h"

#include <unistd.h>

#include "canopy/errors.h"
#include "formats/density_lattice.h"

namespace canopy::lb {
openvdb::Coord nodeCoord(const Dims& d, const openvdb::Coord& mn, int64_t idx) {
  const int x = int(idx % d.nx), y = int((idx / d.nx) % d.ny), z = int(idx / (int64_t(d.nx) * d.ny));
  return mn + openvdb::Coord(x, y, z);
}

void requireHostMemory(const Dims& d, const std::string& what) {
  const double need = double(d.count()) * (2 * kQ + 2) * sizeof(float);
  const double have = double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE));
  if (have > 0 && need > have)
    throw runtimeError(what + ": a " + std::to_string(d.nx) + "x" + std::to_string(d.ny) + "x" +
                       std::to_string(d.nz) + " lattice needs " + std::to_string(int64_t(need / (1 << 20))) +
                       " MiB, more than this machine's " + std::to_string(int64_t(have / (1 << 20))) + " MiB");
}

LoadedLattice loadDensityLattice(const std::string& path, double woodThreshold) {
  const vdbio::DensityLattice file = vdbio::readDensityLattice(path);  // the contract: formats/density_lattice.h
  LoadedLattice L;
  L.meta = file.meta;
  const openvdb::Coord dim = L.meta.dim();
  if (dim.x() < 3 || dim.y() < 3 || dim.z() < 3)
    throw invalidInput(path + ": lattice " + std::to_string(dim.x()) + "x" + std::to_string(dim.y()) + "x" +
                       std::to_string(dim.z()) + " is too small (the solve needs a boundary layer and an interior)");
  Dims d{dim.x(), dim.y(), dim.z()};
  requireHostMemory(d, path);
  L.meta.source = vdbio::describeSource(path);
  L.transform = file.transform->copy();
  L.density.assign(size_t(d.count()), 0.f);
  std::vector<float> woodFraction(size_t(d.count()), 0.f);
  for (const vdbio::DensityCell& c : file.cells) {
    const size_t i = size_t(d.index(c.ijk[0] - L.meta.min.x(), c.ijk[1] - L.meta.min.y(), c.ijk[2] - L.meta.min.z()));
    L.density[i] = c.density;
    woodFraction[i] = c.wood;
  }

  L.dense.dims = d;
  L.dense.coded.resize(L.density.size());
  for (size_t i = 0; i < L.density.size(); ++i) {
    const float rho = L.density[i];
    L.dense.coded[i] = (rho > 0.f && woodFraction[i] >= woodThreshold) ? -rho : rho;
  }
  L.dense.stored = storedNodes(d, L.density);
  return L;
}

std::vector<int64_t> storedNodes(const Dims& d, const std::vector<float>& density) {
  std::vector<unsigned char> mark(density.size(), 0);
  for (int z = 0; z < d.nz; ++z)
    for (int y = 0; y < d.ny; ++y)
      for (int x = 0; x < d.nx; ++x) {
        if (density[size_t(d.index(x, y, z))] == 0.f) continue;
        for (int dz = -1; dz <= 1; ++dz)
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const int X = x + dx, Y = y + dy, Z = z + dz;
              if (X >= 0 && Y >= 0 && Z >= 0 && X < d.nx && Y < d.ny && Z < d.nz)
                mark[size_t(d.index(X, Y, Z))] = 1;
            }
      }
  std::vector<int64_t> out;
  for (size_t i = 0; i < mark.size(); ++i)
    if (mark[i]) out.push_back(int64_t(i));
  return out;
}

}  // namespace canopy::lb
