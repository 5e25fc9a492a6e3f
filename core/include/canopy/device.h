// device.h: which backend runs a job, parsed from --device auto|cpu|cuda[:N].
#pragma once
#include <string>

namespace canopy {

struct Device {
  enum class Kind { Cpu, Cuda };
  Kind kind = Kind::Cpu;
  int index = 0;  // CUDA ordinal; -1 = all GPUs (plain "cuda" lets a tool spread work)
  bool isCuda() const { return kind == Kind::Cuda; }
  std::string str() const;
};

// Number of usable CUDA devices: 0 in a CPU-only build or where no GPU/driver is present.
int cudaDeviceCount();
// True when this binary was compiled with the CUDA backend.
bool builtWithCuda();

// Parses "auto" (CUDA if a GPU is present, else CPU), "cpu", "cuda" (all GPUs) or "cuda:N".
// Throws canopy::Error: Usage for an unknown spelling, Unsupported for CUDA in a CPU-only build or
// a GPU that is not there.
Device resolveDevice(const std::string& spec);

}  // namespace canopy
