# build.mk: the targets of pipelines/Makefile, run inside an output directory (make -C OUT -f
# build.mk ...). Sources are found through vpath, so every output lands in the current directory.
PIPELINES ?= $(patsubst %/,%,$(dir $(abspath $(lastword $(MAKEFILE_LIST)))))

# Smaller defaults than canopy.mk's, so that every target also runs on a CPU-only machine in
# minutes (set before the include: canopy.mk only fills what is still unset).
RESOLUTION ?= 64
PLAY_SIZE ?= 512x512
include $(PIPELINES)/canopy.mk
PLAY_FLAGS = --size $(PLAY_SIZE)

.PHONY: demo plants library scene forest sweep
.DEFAULT_GOAL := demo

# --- demo: the built-in sample plant, end to end, to a PNG ------------------------------------
demo: sample.png
sample.glb:
	$(CANOPY_VOXELIZE) $(CANOPY_QUIET) --write-sample $@

# --- plants: every mesh in PLANTS -------------------------------------------------------------
PLANTS ?= .
PLANT_MESHES := $(sort $(wildcard $(addprefix $(PLANTS)/*.,glb gltf obj ply)))
PLANT_NAMES := $(basename $(notdir $(PLANT_MESHES)))
vpath %.glb $(PLANTS)
vpath %.gltf $(PLANTS)
vpath %.obj $(PLANTS)
vpath %.ply $(PLANTS)
plants: $(addsuffix .canopy,$(PLANT_NAMES))

# --- library: the plants plus an index of them (name, file, size, SHA-256, octreepack info) -----
# A cluster builds the plants as a job array and this index as the job that depends on them
# (pipelines/slurm/submit-library).
library: library.json
library.json: $(addsuffix .canopy,$(PLANT_NAMES)) $(PIPELINES)/library_index.py
	python3 $(PIPELINES)/library_index.py --octreepack $(CANOPY_OCTREEPACK) -o $@ $(filter %.canopy,$^)

# --- scene: a glTF scene whose nodes share meshes ----------------------------------------------
# Each distinct mesh is voxelised (in its own model space), lit and compressed once; the instance
# list comes from the glTF's nodes; the coarse scene lattice is solved over all instances.
SCENE ?=
# The coarse scene lattice (lbsolve --scene: B00..B18, each 1 where unoccluded) is packed whole: the
# player weights each instance's scattered sun by the coarse sun lookup and its ambient light by
# B00, so a tree in its neighbour's shadow loses in-scattered sun. SCENE_LIGHT_GRID=B00 packs the
# ambient grid alone (one static factor for both terms, as before 2026-12-04).
SCENE_LIGHT_GRID ?=
SCENE_NAME := $(basename $(notdir $(SCENE)))
ifneq ($(SCENE),)
scene: $(SCENE_NAME).canopy
$(SCENE_NAME).scene.json: $(SCENE)
	$(LAUNCH) $(CANOPY_VOXELIZE) $(CANOPY_QUIET) $< --instances $@ --model-pattern '$(SCENE_NAME).mesh{N}.density.vdb'
# The models the scene names, as make variables (regenerated when the instance list changes).
$(SCENE_NAME).models.mk: $(SCENE_NAME).scene.json $(PIPELINES)/scene_models.py
	python3 $(PIPELINES)/scene_models.py $< --light-suffix .light.chaar --makefile $@
ifeq ($(filter scene,$(MAKECMDGOALS)),scene)
include $(SCENE_NAME).models.mk
endif
$(SCENE_NAME).mesh%.density.vdb: $(SCENE)
	$(LAUNCH) $(CANOPY_VOXELIZE) $(CANOPY_QUIET) --resolution $(RESOLUTION) --supersample $(SUPERSAMPLE) \
	  $(VOXELIZE_FLAGS) $< --mesh $* -o $@
$(SCENE_NAME).lit.scene.json: $(SCENE_NAME).scene.json $(PIPELINES)/scene_models.py
	python3 $(PIPELINES)/scene_models.py $< --light-suffix .light.chaar --write-json $@
$(SCENE_NAME).scenelight.vdb: $(SCENE_NAME).lit.scene.json $(SCENE_DENSITIES)
	$(LAUNCH_GPU) $(CANOPY_LBSOLVE) $(CANOPY_QUIET) --device $(DEVICE) --scene $< -o $@
$(SCENE_NAME).canopy: $(SCENE_NAME).lit.scene.json $(SCENE_DENSITIES) $(SCENE_LIGHTS) $(SCENE_NAME).scenelight.vdb
	$(LAUNCH) $(CANOPY_OCTREEPACK) $(CANOPY_QUIET) $(PACK_FLAGS) --scene $< \
	  --scene-light $(SCENE_NAME).scenelight.vdb $(if $(SCENE_LIGHT_GRID),--scene-light-grid $(SCENE_LIGHT_GRID)) -o $@
endif

# --- forest: scatter the plants, pack, render a short flight ------------------------------------
FOREST_N ?= 400
FOREST_SEED ?= 1
# The shared plants are 30-65 model units tall: 400 of them on a 450-unit disk stand ~40 apart.
FOREST_RADIUS ?= 450
FOREST_PLANTS ?= $(filter-out %.draco,$(PLANT_NAMES))
FOREST_FRAMES ?= 24
# The forest's files: NAME.scene.json, NAME.canopy and the flight NAME/f_*.png. Forests of other
# names share the plants' files of the same directory (e.g. FOREST_NAME=forest4000 FOREST_N=4000).
# The scatter is remade only when scatter.py changes: a forest of another FOREST_N, FOREST_RADIUS or
# FOREST_SEED needs a name of its own (or the old NAME.scene.json removed).
FOREST_NAME ?= forest
forest: $(FOREST_NAME)/f_0000.png
$(FOREST_NAME).scene.json: $(PIPELINES)/scatter.py
	python3 $(PIPELINES)/scatter.py -o $@ --count $(FOREST_N) --seed $(FOREST_SEED) --radius $(FOREST_RADIUS) \
	  $(foreach p,$(FOREST_PLANTS),--model $(p)=$(p).density.vdb:$(p).light.chaar)
# The coarse scene lattice over the whole forest (lbsolve --scene, B00..B18): crowns in their
# neighbours' shade lose scattered sun, and the ground under the crowns loses sky light.
# FOREST_SCENE_RESOLUTION cells along the forest's longest side.
FOREST_SCENE_RESOLUTION ?= 64
$(FOREST_NAME).scenelight.vdb: $(FOREST_NAME).scene.json $(foreach p,$(FOREST_PLANTS),$(p).density.vdb)
	$(LAUNCH_GPU) $(CANOPY_LBSOLVE) $(CANOPY_QUIET) --device $(DEVICE) --scene $< --scene-resolution $(FOREST_SCENE_RESOLUTION) -o $@
$(FOREST_NAME).canopy: $(FOREST_NAME).scene.json $(foreach p,$(FOREST_PLANTS),$(p).density.vdb $(p).light.chaar) $(FOREST_NAME).scenelight.vdb
	$(LAUNCH) $(CANOPY_OCTREEPACK) $(CANOPY_QUIET) $(PACK_FLAGS) --scene $< --scene-light $(FOREST_NAME).scenelight.vdb -o $@
$(FOREST_NAME)/f_0000.png: $(FOREST_NAME).canopy
	@mkdir -p $(FOREST_NAME)
	$(LAUNCH_GPU) $(CANOPY_PLAY) $(CANOPY_QUIET) --device $(DEVICE) $(PLAY_FLAGS) --frames $(FOREST_FRAMES) \
	  --camera orbit:elevation=15,distance=$(FOREST_RADIUS),turns=0.25 $< -o $(FOREST_NAME)/f_%04d.png

# --- sweep: compression threshold comparison for one plant --------------------------------------
SWEEP_PLANT ?= $(firstword $(PLANT_NAMES))
SWEEP_THRESHOLDS ?= 0,0.001,0.003,0.01,0.03
sweep: $(SWEEP_PLANT).sweep.png
$(SWEEP_PLANT).sweep.png: $(SWEEP_PLANT).light.vdb
	$(LAUNCH) $(CANOPY_HAAR) $(CANOPY_QUIET) sweep $< --thresholds $(SWEEP_THRESHOLDS) -o $(SWEEP_PLANT).sweep
