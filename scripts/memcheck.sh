#!/usr/bin/env bash
# valgrind memcheck over a representative subset of the test suite and the CLI, in its
# own build directory (no sanitizers: valgrind and ASan do not mix), JOBS runs at a time
# (2 by default). Any memory error or any leaked block (definite, indirect or possible)
# fails the run.
#
#   scripts/memcheck.sh                   the default subset
#   MEMCHECK_TESTS="test_index" scripts/memcheck.sh
#   MEMCHECK_BUILD_DIR=build scripts/memcheck.sh
#                                         in a build directory already configured (CI:
#                                         make test's, built with -g1), as it is
#
# The subset leaves out the tests that are long mostly because of their brute-force
# oracles (test_query, test_geo, test_balance): they exercise no allocation path that the
# tests below do not, and under valgrind they would take many minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
src=$PWD
dir=${MEMCHECK_BUILD_DIR:-build-memcheck}
jobs=${JOBS:-2}
tests=${MEMCHECK_TESTS:-"test_index test_collide test_reliab_threads test_mesh test_poly test_reliability test_io test_headers_c"}

if ! command -v valgrind >/dev/null; then
  echo "memcheck.sh: valgrind not found (make memcheck installs it)" >&2
  exit 2
fi
# (a directory already configured keeps its build type and flags: CI gives make test's,
# whose library and tests are then built already)
if [ ! -f "$dir/CMakeCache.txt" ]; then
  cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
fi
# shellcheck disable=SC2086 # the test names are words
nice cmake --build "$dir" -j"$jobs" --target quadkit_cli $tests

vg=(valgrind --tool=memcheck --error-exitcode=99 --leak-check=full
  '--show-leak-kinds=definite,indirect,possible' '--errors-for-leak-kinds=definite,indirect,possible'
  --num-callers=30 --quiet)
export QK_SOURCE_DIR="$src" QK_SHARED_DIR="$src/../shared"
log="$dir/memcheck"
rm -rf "$log"
mkdir -p "$log"
# run NAME EXPECTED_EXIT command...: in the background, at most $jobs at a time (the
# longest tests come first in the list); valgrind itself exits 99 on any error. Each run
# leaves NAME.rc with its verdict, counted once all have ended.
run() {
  while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n || true; done
  local name=$1 want=$2
  shift 2
  (
    start=$SECONDS rc=0
    "${vg[@]}" --log-file="$log/$name.log" "$@" >"$log/$name.out" 2>&1 || rc=$?
    if [ "$rc" -eq "$want" ]; then
      echo "   ok   $name ($((SECONDS - start))s)" >&2
      echo ok >"$log/$name.rc"
    else
      echo "   FAIL $name (exit $rc, want $want): see $log/$name.log and $log/$name.out" >&2
      head -n 30 "$log/$name.log" >&2
      echo fail >"$log/$name.rc"
    fi
  ) &
}

echo "== valgrind memcheck" >&2
ran=0
for t in $tests; do
  if [ -x "$dir/tests/$t" ]; then
    # valgrind runs a process's threads one at a time: test_collide's five threads* tests
    # (a third of its time here) are left to ASan, with its leak check, and TSan
    if [ "$t" = test_collide ]; then export QKT_SKIP_FILTER='test_collide_threads*'; fi
    run "$t" 0 "$dir/tests/$t"
    unset QKT_SKIP_FILTER
    ran=$((ran + 1))
  else
    echo "   skip $t (not built)" >&2
  fi
done
# The CLI, on good and bad input: errors must not leak either.
cli="$dir/quadkit"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
run cli_tree 0 "$cli" tree examples/points.csv --svg "$tmp/t.svg"
printf 'x,y\n0,0\n1,nan\n' >"$tmp/bad.csv"
run cli_tree_bad_input 1 "$cli" tree "$tmp/bad.csv"
run cli_tree_bad_output 1 "$cli" tree examples/points.csv --svg "$tmp/no/such/dir/t.svg"
if "$cli" knn --help >/dev/null 2>&1; then
  printf '0.5,0.5,0.1\n0.55,0.5,0.1\n0.9,0.9,-1\n' >"$tmp/discs.csv"
  run cli_knn 0 "$cli" knn examples/points.csv examples/points.csv -k 5 -o "$tmp/knn.csv"
  run cli_knn_keep 0 "$cli" knn examples/points.csv examples/points.csv -k 3 --keep both -o "$tmp/knn3.csv"
  run cli_knn_bad_input 1 "$cli" knn examples/points.csv "$tmp/bad.csv" -k 5 -o "$tmp/knn2.csv"
  run cli_collide_bad_input 1 "$cli" collide "$tmp/discs.csv"
fi
if "$cli" mesh --help >/dev/null 2>&1; then
  run cli_mesh 0 "$cli" mesh examples/mesh/notes.poly -o "$tmp/notes" --size 16
  run cli_mesh_bad_input 1 "$cli" mesh "$tmp/bad.csv" -o "$tmp/bad"
fi
wait
[ "$ran" -gt 0 ] || { echo "memcheck.sh: no test binaries found" >&2; exit 1; }
fails=$(cat "$log"/*.rc | grep -cx fail || true) # grep -c exits 1 on none
if [ "$fails" -ne 0 ]; then
  echo "memcheck: $fails failed" >&2
  exit 1
fi
echo "memcheck: all clean" >&2
