# Front door. `make demo` and `make test` install what is missing, build, and run.
BUILD ?= build
JOBS ?= 2
CMAKE_FLAGS ?=

.PHONY: all deps build demo test asan scalar tsan memcheck fuzz bench format format-check check-layout install clean

all: build

deps:
	@bash scripts/install-deps.sh core

build: deps
	@cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS) >/dev/null
	@cmake --build $(BUILD) -j$(JOBS)

demo: build
	@bash scripts/demo.sh $(BUILD)/quadkit

test: build
	@ctest --test-dir $(BUILD) --output-on-failure -j$(JOBS)

# The whole suite under AddressSanitizer + UndefinedBehaviorSanitizer, warnings as errors.
asan: deps
	@cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DQUADKIT_SANITIZE=ON -DQUADKIT_WERROR=ON >/dev/null
	@cmake --build build-asan -j$(JOBS)
	@ctest --test-dir build-asan --output-on-failure -j$(JOBS)

# The library and the unit tests without SSE2 (-U__SSE2__): the portable code that ARM and
# other targets compile, which an x86-64 build never does, warnings as errors.
scalar: deps
	@cmake -S . -B build-scalar -DCMAKE_BUILD_TYPE=Release -DQUADKIT_WERROR=ON -DCMAKE_C_FLAGS=-U__SSE2__ >/dev/null
	@cmake --build build-scalar -j$(JOBS)
	@ctest --test-dir build-scalar --output-on-failure -j$(JOBS) -R '^test_'

format-check: deps
	@cmake -S . -B $(BUILD) >/dev/null
	@cmake --build $(BUILD) --target format-check

# index/ owns the tree's layout: no node fields or index_internal.h outside it (issue 11).
check-layout:
	@bash scripts/check-layout.sh

format: deps
	@cmake -S . -B $(BUILD) >/dev/null
	@cmake --build $(BUILD) --target format

install: build
	@cmake --install $(BUILD)

clean:
	rm -rf $(BUILD) build-asan build-tsan build-bench build-fuzz build-memcheck

# Benchmarks against the baselines (installs them first); see docs/benchmarks.md.
bench:
	@bash scripts/install-deps.sh core bench
	@bash scripts/bench.sh

# The concurrency test under ThreadSanitizer.
tsan: deps
	@bash scripts/tsan.sh

# valgrind memcheck over a representative subset of the tests.
memcheck:
	@bash scripts/install-deps.sh core memcheck
	@bash scripts/memcheck.sh

# libFuzzer targets, each for FUZZ_SECONDS (default 60).
fuzz:
	@bash scripts/install-deps.sh core fuzz
	@bash scripts/fuzz.sh
