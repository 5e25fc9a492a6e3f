// solver.h: one steady-state LB solve on a dense lattice, behind a CPU or CUDA backend.
//
// A Solver owns the lattice state for one device (two 19-value buffers, ping-pong: the step
// reads one and writes the other, see collide.h) and runs solve(spec) = iterate the update of
// collide.h from the initial state of the spec's boundary values until the residual falls to the
// tolerance or the iteration cap is reached. The loop is shared (solver.cpp); backends provide
// init/step/residual/gather (solve_cpu.cpp: TBB, the reference; solve_cuda.cu: CUDA kernels).
// No OpenVDB here: this header is included by the .cu file.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "canopy/device.h"
#include "collide.h"

namespace canopy::lb {

// The lattice as the solvers see it: coded density (rho, or -rho at wood nodes) per node, and the
// node indices whose light is returned (sorted ascending).
struct DenseLattice {
  Dims dims;
  std::vector<float> coded;
  std::vector<int64_t> stored;
};

struct SolveSpec {
  OmegaSet omega;
  float boundary[kQ] = {};  // fixed f_m on the outer layer
  int maxIterations = 1;    // cap (>= 1)
  float tolerance = 0.f;    // stop when residual <= tolerance; 0 = run exactly maxIterations
  int checkEvery = 16;      // residual is computed every checkEvery iterations (and at the cap)
};

struct SolveResult {
  int iterations = 0;
  // max over nodes |rho_t - rho_{t-1}| / max over nodes rho_t, for the last iteration run
  // (rho = sum of the 19 values, the stored quantity).
  float residual = 0.f;
  std::vector<float> values;  // rho at DenseLattice::stored, same order
  double seconds = 0.0;
};

class Solver {
 public:
  virtual ~Solver() = default;
  SolveResult solve(const SolveSpec& spec);
  virtual std::string name() const = 0;

 protected:
  virtual void init(const float boundary[kQ]) = 0;  // state := boundary on the outer layer, 0 inside
  // Called before a step whose result residual() will check: a backend that overwrites the state
  // in place keeps what residual() needs of the current state here (ping-pong backends: nothing).
  virtual void beforeCheckedStep() {}
  virtual void step(const OmegaSet& omega) = 0;     // one update; afterwards current = new state
  virtual float residual() = 0;                     // between the current and the previous state
  virtual std::vector<float> gather() = 0;          // rho of the current state at stored nodes
};

// How the CUDA backend advances the lattice (docs/performance.md has the measurements):
//   Shift:      streaming by index shift (shift_stream.h): one state buffer updated in place, work
//               only at occupied and boundary nodes, one launch per iteration. The default.
//   ShiftSplit: the same in three launches per iteration (leaf nodes, wood nodes, boundary nodes),
//               each kernel holding only its own path (fewer registers).
//   Push:       the push update of collide.h over every node, ping-pong buffers (listing 5.2).
//   Pull:       the same update over every node, reorganised (pull_stream.h): each node's
//               post-collision values stored aligned at the node, in tiles of 32 nodes with their 19
//               directions contiguous; arrivals read from the neighbours. The dense scheme nearest
//               the bandwidth roofline.
// All compute the CPU reference's bits (same IEEE operations in the same order).
enum class CudaScheme { Shift, ShiftSplit, Push, Pull };
const char* cudaSchemeName(CudaScheme scheme);

// How the CUDA solves run (docs/performance.md, 'Row order and solves in flight', has the measurements). Nothing
// here changes a result: every solve has its own buffers and computes the same bits.
struct CudaRun {
  CudaRun(CudaScheme s = CudaScheme::Shift) : scheme(s) {}  // NOLINT: a scheme alone is a CudaRun
  CudaScheme scheme;
  // Solves in flight on each GPU, each with its own stream and buffers, so that one solve's
  // launches fill the gaps of another's (a launch's ramp and tail, the host round trip of a
  // residual check). Fewer run where the GPU's free memory does not hold them all (never fewer
  // than one).
  int solvesPerGpu = 1;
};

std::unique_ptr<Solver> makeCpuSolver(const DenseLattice& lattice);
// Throws canopy::Error(Unsupported) in a build without CUDA.
std::unique_ptr<Solver> makeCudaSolver(const DenseLattice& lattice, int gpu, CudaScheme scheme = CudaScheme::Shift);

// Bytes of device memory a CUDA solver needs for this lattice. Push: 2 x 19 floats + coded density
// per node, the wood-node list, plus the stored-node index list and its values. Pull: the same with
// x padded to a multiple of 32, a total per node (residual) and no wood-node list. Shift (both): 19
// floats + coded density + a kept total per node, the occupied and boundary node lists, and the
// stored nodes.
int64_t cudaSolverBytes(const DenseLattice& lattice, CudaScheme scheme = CudaScheme::Shift);

// Runs every spec; results[k] belongs to specs[k]. CPU: one solver, specs in order. CUDA:
// run.solvesPerGpu solvers per GPU (device.index >= 0: that GPU only; -1: every GPU), each on its
// own host thread taking the next spec from a shared queue, so several GPUs, and several streams
// of one GPU, share the 57 solves. onDone(k, result) is called (serialised) as each solve finishes.
std::vector<SolveResult> runSolves(const DenseLattice& lattice, const std::vector<SolveSpec>& specs,
                                   const Device& device,
                                   const std::function<void(size_t, const SolveResult&)>& onDone = {},
                                   const CudaRun& run = CudaRun());

// Free device memory of GPU `gpu` in bytes (0 in a build without CUDA).
int64_t cudaFreeBytes(int gpu);

}  // namespace canopy::lb
