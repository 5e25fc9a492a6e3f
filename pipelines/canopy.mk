# canopy.mk: pattern rules that chain the Canopy tools. Include it from your own Makefile:
#
#   CANOPY_BIN := /opt/canopy/bin          # where canopy-* live (empty: found on PATH)
#   include /path/to/canopy/pipelines/canopy.mk
#   all: oak.canopy pine.canopy            # oak.glb -> oak.density.vdb -> oak.light.vdb
#                                          #   -> oak.light.chaar -> oak.canopy
#
# Every tool writes its output atomically (temporary file + rename), so a killed build never
# leaves a half-written target that make would take as up to date, and the same inputs and options
# give the same bytes. Override any variable below on the command line (make RESOLUTION=64 ...).

# --- tools -----------------------------------------------------------------------------------
CANOPY_BIN ?=
canopy_tool = $(if $(CANOPY_BIN),$(CANOPY_BIN)/)canopy-$(1)
CANOPY_VOXELIZE ?= $(call canopy_tool,voxelize)
CANOPY_LBSOLVE ?= $(call canopy_tool,lbsolve)
CANOPY_HAAR ?= $(call canopy_tool,haar)
CANOPY_OCTREEPACK ?= $(call canopy_tool,octreepack)
CANOPY_PLAY ?= $(call canopy_tool,play)

# --- launcher: a prefix for every tool invocation (empty: run locally) -----------------------
# e.g. LAUNCH='srun -N1 -n1' runs each step as a Slurm job step. GPU tools (lbsolve, play) add
# GPU_LAUNCH_FLAGS after the launcher; set GPU_LAUNCH_FLAGS= on a cluster without GPUs.
LAUNCH ?=
GPU_LAUNCH_FLAGS ?= --gres=gpu:1
LAUNCH_GPU ?= $(LAUNCH)$(if $(strip $(LAUNCH)), $(GPU_LAUNCH_FLAGS))

# --- options ---------------------------------------------------------------------------------
# lattice cells per axis, and fine sub-cells per lattice cell per axis (voxelize)
RESOLUTION ?= 128
SUPERSAMPLE ?= 8
# empty, or the detail lattice's cells per axis (RESOLUTION x 2, 4, 8 or 16): the plants' .canopy
# then holds geometry that fine, lit from the RESOLUTION lattice (docs/voxelize.md, "Detail lattice")
DETAIL ?=
# auto | cpu | cuda | cuda:N (lbsolve, play)
DEVICE ?= auto
VOXELIZE_FLAGS ?=
LBSOLVE_FLAGS ?=
# the compression dial: --max-error E (guaranteed max abs error) or --threshold T. The .chaar's
# bricks go into the .canopy as the finest level's exact light (canopy-play --light exact,
# docs/canopy-format.md), so this also decides that part of the packed file. The threshold is
# absolute, and the sun bases (scattered light only, lbsolve's default) are ~14x smaller than the
# ambient base, so it is chosen for them. Default: threshold 0.01, fp16 coefficients; measured on
# oak_medium at 64^3 (bench/RESULTS.md, bench-light-packing): 5.4 MB of Haar pages, errors of the
# sun bases 1.1% RMS and 6.5% max of their peak (all 19 bases: 0.08% and 0.5% of the overall peak);
# at 0.05 (the default before) 1.5 MB but 4.2% and 29%. The float16 items (6.2 MB) are off by
# 3.9% RMS and 40% max of the sun bases' peak whatever the threshold.
HAAR_ERROR ?= --threshold 0.01
HAAR_FLAGS ?= --precision fp16
PACK_FLAGS ?=
PLAY_FLAGS ?= --size 512x512
CANOPY_QUIET ?= --quiet

# --- rules -----------------------------------------------------------------------------------
canopy_voxelize_cmd = $(LAUNCH) $(CANOPY_VOXELIZE) $(CANOPY_QUIET) --resolution $(RESOLUTION) \
  --supersample $(SUPERSAMPLE) $(VOXELIZE_FLAGS) $< -o $@

ifeq ($(strip $(DETAIL)),)
%.density.vdb: %.glb
	$(canopy_voxelize_cmd)
%.density.vdb: %.gltf
	$(canopy_voxelize_cmd)
%.density.vdb: %.obj
	$(canopy_voxelize_cmd)
%.density.vdb: %.ply
	$(canopy_voxelize_cmd)
else
# DETAIL=N (e.g. 1024): one voxelize run writes the light lattice (RESOLUTION, what lbsolve solves)
# and the detail lattice (N, what the player shows), nested in the same box (docs/voxelize.md).
# (the supersample is at least the detail factor: a detail cell holds whole sub-cells)
canopy_voxelize_detail_cmd = $(LAUNCH) $(CANOPY_VOXELIZE) $(CANOPY_QUIET) --resolution $(RESOLUTION) \
  --supersample $$(( $(SUPERSAMPLE) > $(DETAIL) / $(RESOLUTION) ? $(SUPERSAMPLE) : $(DETAIL) / $(RESOLUTION) )) \
  --detail $(DETAIL) $(VOXELIZE_FLAGS) $< -o $*.density.vdb --detail-output $*.detail.vdb
%.density.vdb %.detail.vdb: %.glb
	$(canopy_voxelize_detail_cmd)
%.density.vdb %.detail.vdb: %.gltf
	$(canopy_voxelize_detail_cmd)
%.density.vdb %.detail.vdb: %.obj
	$(canopy_voxelize_detail_cmd)
%.density.vdb %.detail.vdb: %.ply
	$(canopy_voxelize_detail_cmd)
endif

%.light.vdb: %.density.vdb
	$(LAUNCH_GPU) $(CANOPY_LBSOLVE) $(CANOPY_QUIET) --device $(DEVICE) $(LBSOLVE_FLAGS) $< -o $@

%.light.chaar: %.light.vdb
	$(LAUNCH) $(CANOPY_HAAR) $(CANOPY_QUIET) $(HAAR_ERROR) $(HAAR_FLAGS) $< -o $@

# One plant: its lattice (with DETAIL, the detail lattice) and its compressed lighting in one
# streamable file.
%.canopy: %.$(if $(strip $(DETAIL)),detail,density).vdb %.light.chaar
	$(LAUNCH) $(CANOPY_OCTREEPACK) $(CANOPY_QUIET) $(PACK_FLAGS) $^ -o $@

# A still of a packed plant or scene.
%.png: %.canopy
	$(LAUNCH_GPU) $(CANOPY_PLAY) $(CANOPY_QUIET) --device $(DEVICE) $(PLAY_FLAGS) $< -o $@

# Keep the intermediate files of the chain (make would otherwise delete them).
.PRECIOUS: %.density.vdb %.detail.vdb %.light.vdb %.light.chaar %.canopy
