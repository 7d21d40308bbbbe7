#!/usr/bin/env bash
# Builds the library and the concurrency tests (tests/test_reliab_threads.c, and
# tests/test_world.c for the world's threads option and concurrent readers,
# tests/test_world_walk.c for the pairs walked on the world's threads) with
# ThreadSanitizer in build-tsan/ and runs it: many threads querying one tree, collider,
# geodesic index and mesh at once, and threads changing trees of their own; and
# tests/test_region.c and tests/test_collide.c, whose threaded batches must equal the
# single calls; tests/test_build.c, whose threaded bulk build must equal one thread's;
# tests/test_query.c, whose batches on a team of workers must equal one thread's.
# In test_world, test_build and test_collide the tests and runs that start no thread skip
# themselves here (QKT_TSAN, tests/support/qk_test.h): TSan finds nothing without a second
# thread. Any data race TSan sees fails the run; the tests run JOBS (2) at a time.
# Usage: scripts/tsan.sh [build-dir]
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:-build-tsan}
jobs=${JOBS:-2}
flags="-fsanitize=thread -fno-omit-frame-pointer -g"
cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DQUADKIT_WERROR=ON \
  -DCMAKE_C_FLAGS="$flags" -DCMAKE_CXX_FLAGS="$flags" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=thread" -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=thread" \
  >/dev/null
nice cmake --build "$dir" -j"$jobs" --target test_reliab_threads test_region test_world test_world_walk test_collide test_build test_query
# halt_on_error: the first race fails the test; second_deadlock_stack for lock reports.
TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$PWD/scripts/tsan.supp ${TSAN_OPTIONS:-}" \
  ctest --test-dir "$dir" --output-on-failure -j"$jobs" -R '^(test_reliab_threads|test_region|test_world|test_world_walk|test_collide|test_build|test_query)$'
