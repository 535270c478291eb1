# sdfprune — top-level entry points. `make run` and `make test` work on a fresh Debian 12 machine.
BUILD ?= build
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=
PACKAGES = build-essential cmake ninja-build pkg-config libtbb-dev libcli11-dev rapidjson-dev \
           libgtest-dev libbenchmark-dev libpng-dev libopenvdb-dev libboost-iostreams-dev \
           valgrind clang-format time libvulkan-dev glslc spirv-tools mesa-vulkan-drivers \
           python3 python3-dev python3-venv python3-numpy python3-pytest python3-setuptools \
           python3-wheel pybind11-dev python3-skimage libcpp-httplib-dev chromium
# Only for `make fuzz`: clang and its runtime libraries (libFuzzer, ASan, UBSan).
FUZZ_PACKAGES = clang libclang-rt-14-dev
FUZZ_SECONDS ?= 600
# The Python package's test environment (never Debian's system python): a venv in the build tree.
PYENV = $(BUILD)/pyenv

.PHONY: setup build python test run bench sanitize gpu-rounding fuzz format clean

# Installs every system dependency (as root, non-interactive); does nothing when all are present.
# Node.js and npm (for the browser tests' playwright-core) come from Debian when not on PATH.
setup:
	@extra="$(EXTRA_PACKAGES)"; command -v node >/dev/null && command -v npm >/dev/null || \
	  extra="$$extra nodejs npm"; \
	missing=$$(for p in $(PACKAGES) $$extra; do dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q '^install ok installed' || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "make setup: installing$$(echo $$missing | sed 's/^/ /')"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	else echo "make setup: all dependencies present"; fi

$(BUILD)/build.ninja: CMakeLists.txt
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS)

build: setup $(BUILD)/build.ninja
	cmake --build $(BUILD) -j $(JOBS)

# The Python package, installed into $(PYENV) by pip from this tree, built in $(BUILD) (the
# engine library is not compiled a second time; only the module is added).
python: build
	@test -x $(PYENV)/bin/python || /usr/bin/python3 -m venv --system-site-packages $(PYENV)
	SDFPRUNE_BUILD_DIR=$(abspath $(BUILD)) CMAKE_BUILD_PARALLEL_LEVEL=$(JOBS) \
	  $(PYENV)/bin/pip install --no-build-isolation --no-deps -q .

# ctest, then the Python suite, then the viewer in headless Chromium (each runs even when an
# earlier one fails, so every summary shows).
test: build python
	@status=0; (cd $(BUILD) && ctest --output-on-failure -j $(JOBS)) || status=1; \
	SDFPRUNE_CLI=$(abspath $(BUILD))/sdfprune $(PYENV)/bin/python -m pytest python/tests -q \
	  -p no:cacheprovider || status=1; \
	./tests/browser/run.sh $(BUILD) || status=1; exit $$status

run: build
	./tools/run_demo.sh $(BUILD)

# Micro-benchmarks, then BENCHMARKS.md: the issues' targets on the reference scenes, Tables 1-2
# over generated scenes, and the scaling plot docs/scaling.png (tens of minutes on 2 cores: the
# naive baselines are slow by design and estimated beyond a budget).
bench: build python
	./$(BUILD)/sdfprune_bench --benchmark_min_time=0.2
	./bench/run_bench.sh $(BUILD)
	./bench/python.sh $(BUILD)

# The Gpu tests on shaders that round the values of primitives and operators otherwise than the
# CPU, by a last bit (a stand-in for a GPU whose arithmetic is not IEEE-exact, as NVIDIA's is
# not in Vulkan), held to what must hold on such a device (SDFPRUNE_GPU_EXACT=0), in
# build-rounding/. ROUNDING=kernel (default): each kernel its own way (the variants of one
# kernel's source alike); ROUNDING=shared: every kernel alike. In CI (.ci/run).
ROUNDING ?= kernel
gpu-rounding: setup
	cmake -S . -B build-rounding -G Ninja -DCMAKE_BUILD_TYPE=Release \
	  -DSDFPRUNE_SHADER_ROUNDING=$(ROUNDING) -DSDFPRUNE_BENCH=OFF
	cmake --build build-rounding -j $(JOBS) --target sdfprune_tests sdfprune
	cd build-rounding && SDFPRUNE_GPU_EXACT=0 ./sdfprune_tests --gtest_filter='Gpu*'

# Address + undefined-behaviour sanitizers, separate build tree.
sanitize: setup
	cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSDFPRUNE_SANITIZE=ON -DSDFPRUNE_BENCH=OFF
	cmake --build build-asan -j $(JOBS)
	cd build-asan && ASAN_OPTIONS=detect_leaks=1 ctest --output-on-failure -j $(JOBS)

# libFuzzer targets (fuzz/): built with clang, -fsanitize=fuzzer,address,undefined, in
# build-fuzz/; each runs FUZZ_SECONDS (default 600) and reports executions and coverage.
fuzz:
	@$(MAKE) --no-print-directory setup EXTRA_PACKAGES="$(FUZZ_PACKAGES)"
	CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DSDFPRUNE_FUZZ=ON -DSDFPRUNE_TESTS=OFF -DSDFPRUNE_BENCH=OFF -DSDFPRUNE_VULKAN=OFF
	cmake --build build-fuzz -j $(JOBS) --target fuzz_scene_loader fuzz_npy_reader fuzz_prune_eval
	FUZZ_SECONDS=$(FUZZ_SECONDS) ./fuzz/run.sh build-fuzz

format:
	clang-format -i $$(git ls-files '*.cpp' '*.hpp' '*.h')

clean:
	rm -rf $(BUILD) build-asan build-fuzz
