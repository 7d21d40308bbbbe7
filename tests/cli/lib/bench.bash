# Shared by the quadkit-bench smoke tests (sourced after common.bash): exits 77 (ctest:
# skipped) when a baseline library is missing, else builds quadkit-bench (Release, in
# <build dir>/bench-smoke, reused by later runs) and defines run and expect_impl.
# `make test` does not need the baselines; `make bench` installs them.
# QK_BENCH_INCLUDE_DIR (default /usr/include) is where the baselines' headers are looked
# for: pointing it at an empty directory checks the skip.
# quadkit-bench is built without sanitizers (Release) in every configuration, so in the
# sanitizer build (`make asan`) the run would repeat make test's exactly: skipped there.
if [ "${QK_SANITIZE:-0}" = 1 ]; then
  echo "SKIPPED: quadkit-bench is not built with sanitizers; make test runs this check"
  exit 77
fi
inc=${QK_BENCH_INCLUDE_DIR:-/usr/include}
missing=()
for h in flann/flann.hpp nanoflann.hpp embree3/rtcore.h CGAL/Orthtree.h p4est.h gmshc.h \
  GeographicLib/NearestNeighbor.hpp lz4.h; do
  [ -e "$inc/$h" ] || missing+=("$h")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "SKIPPED: quadkit-bench baselines not installed (missing ${missing[*]}); 'make bench' installs them"
  exit 77
fi
bdir="$(cd "$(dirname "$cli")" && pwd)/bench-smoke"
# (linked with the library of the build under test when it has one: built once, not twice)
lib="$(cd "$(dirname "$cli")" && pwd)/libquadkit.a"
[ -f "$lib" ] || lib=
if ! cmake -S "$src" -B "$bdir" -DCMAKE_BUILD_TYPE=Release -DQUADKIT_BUILD_BENCH=ON \
  -DQUADKIT_BUILD_TESTS=OFF -DQUADKIT_BUILD_TOOLS=OFF -DQUADKIT_BENCH_LIBRARY="$lib" \
  >"$bdir-build.log" 2>&1 ||
  ! nice -n 5 cmake --build "$bdir" --target quadkit_bench -j2 >>"$bdir-build.log" 2>&1; then
  echo "FAIL: building quadkit-bench (log: $bdir-build.log)"
  tail -n 30 "$bdir-build.log"
  exit 1
fi
bench="$bdir/bench/quadkit-bench"
out="$tmp/bench.jsonl"

run() { # run ARGS...: JSON lines into $out; must exit 0, agree, and carry every field
  if ! "$bench" --quick --json "$@" >"$out" 2>"$tmp/bench.err"; then
    fail "quadkit-bench $* exited non-zero: $(tail -5 "$tmp/bench.err")"
    return
  fi
  if grep -q '"matches":false' "$out"; then
    fail "quadkit-bench $*: an implementation disagreed with quadkit: $(grep '"matches":false' "$out")"
  fi
  local f
  for f in op impl dataset n queries k order batch threads seconds per_second bytes_per_point matches; do
    grep -q "\"$f\":" "$out" || fail "quadkit-bench $*: no field '$f' in the JSON lines"
  done
  passes=$((passes + 1))
}

expect_impl() { # expect_impl IMPL OP: the last run timed IMPL
  if grep -q "\"op\":\"$2\",\"impl\":\"$1\".*\"per_second\":[0-9]" "$out"; then
    passes=$((passes + 1))
  else
    fail "no timing of $1 for $2"
  fi
}
