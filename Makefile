# The two commands a new machine needs (README.md):
#   make demo   install dependencies, build, run the built-in sample plant end to end
#   make test   install dependencies, build from scratch, run every test
BUILD ?= build
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=

.PHONY: deps configure build test demo clean
deps:
	bash .ci/install-deps

configure: deps
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS)

build: configure
	cmake --build $(BUILD) -j $(JOBS)

test: build
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

# The demo builds the five tools it runs, not the tests and benchmarks.
DEMO_TOOLS = canopy-voxelize canopy-lbsolve canopy-haar canopy-octreepack canopy-play
demo: configure
	cmake --build $(BUILD) -j $(JOBS) --target $(DEMO_TOOLS)
	$(MAKE) -C pipelines demo BIN=$(abspath $(BUILD))/bin O=$(abspath out)
	@echo "demo: out/demo/sample.png"

clean:
	rm -rf $(BUILD)
