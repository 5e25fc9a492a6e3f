// beam.h: the unscattered part of a sun base (its direct beam), which canopy-lbsolve removes from
// the stored sun bases so that the player's own direct sun term does not count the beam twice
// (docs/play.md, "Direct sun and the LB sun bases").
//
// Base B_j (j = 1..18) has boundary f_i = delta_ij, and its stored value is the total site density
// sum_m f_m, f_0 (the light absorbed at the node) included. Of that total, the beam U_j is the part
// that was never scattered:
//   - f_j carried straight along c_j from the boundary, each node r on the way keeping
//     max(0, f - sigma_t p_j(r) f) of it, i.e. what does not interact there (p_j: collide.h,
//     OmegaSet; with the default Beer-Lambert interaction and sigma_t = 1 this is exp(-sigma rho
//     |c_j|) per node, the player's direct-sun transmittance along c_j). What an interaction
//     scatters back into direction j itself (Omega_jj + sigma_t > 0) is scattered light: it
//     belongs to S_j, as the player's medium has no such forward spike (until 2026-12-04 it was
//     counted as beam, and the beam fell linearly, 1 - rho (sigma_t - that share) per node), and
//   - f_0, what the node absorbs of that beam (Omega_0j p_j f_j = sigma_a p_j f_j; at wood nodes f_0
//     is kept and decays with Omega_00 p_0 as in the full update, at leaf nodes it is zeroed every
//     iteration).
// B_j - U_j >= 0 is then the light scattered at least once (every other entry of Omega that feeds
// f_j or f_0 is >= 0 and the update is monotone), up to rounding.
#pragma once
#include <vector>

#include "solver.h"

namespace canopy::lb {

// U_j (f_0 + f_j, nodeTotal's sum) at lattice.stored (the order of SolveResult::values) after
// `iterations` iterations of the push update from the initial state of collide.h's initNode
// (interior 0, boundary f_j = boundary), with the channel's Omega. A node d steps downstream of the
// boundary along c_j receives the beam at iteration d, so after fewer iterations it holds 0. The
// values are bit for bit those of the push update restricted to Omega_jj, Omega_0j and Omega_00,
// iterated node by node (tests/lbsolve/test_collide.cpp, DirectBeam; on a node holding only beam
// light the full collision's rows j and 0 compute the same bits). O(nodes) on all cores, plus
// (iterations - depth) steps at each wood node.
// Precondition: 1 <= base <= 18.
std::vector<float> directBeam(const DenseLattice& lattice, const OmegaSet& omega, int base, int iterations,
                              float boundary = 1.0f);

}  // namespace canopy::lb
