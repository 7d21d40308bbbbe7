#!/usr/bin/env bash
# Builds the libFuzzer targets in fuzz/ with clang (ASan + UBSan) and runs each for
# FUZZ_SECONDS (default 60), FUZZ_JOBS targets at a time (default 2), at low priority.
# The library is compiled once for all targets.
#
#   scripts/fuzz.sh                 build and run every target
#   scripts/fuzz.sh tree_ops csv    only these targets
#   FUZZ_SECONDS=600 scripts/fuzz.sh
#   FUZZ_BUILD_ONLY=1 scripts/fuzz.sh
#
# Each target starts from fuzz/corpus/<target>/ and fuzz/regressions/<target>/; what it
# learns goes to build-fuzz/corpus/<target>/ (not committed). A crash stops the run with
# exit status 1 and leaves the input in build-fuzz/crashes/<target>/: minimise it with
# `build-fuzz/fuzz_<target> -minimize_crash=1 -runs=10000 FILE`, then commit it under
# fuzz/regressions/<target>/ so that tests/test_reliability.c replays it from then on.
set -euo pipefail
cd "$(dirname "$0")/.."
src=$PWD
out=${FUZZ_BUILD_DIR:-$src/build-fuzz}
seconds=${FUZZ_SECONDS:-60}
cc=${FUZZ_CC:-clang}
jobs_nice=${FUZZ_NICE:-15}
jobs=${FUZZ_JOBS:-2}

all_targets=(tree_ops csv poly geojson mesh_dyadic mesh_general world)
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=("${all_targets[@]}")

if ! command -v "$cc" >/dev/null; then
  echo "fuzz.sh: $cc not found (make fuzz installs clang)" >&2
  exit 2
fi

mkdir -p "$out"
flags=(-g -O1 -std=c11 -D_XOPEN_SOURCE=700 -Wall -Wextra -Wpedantic
  "-fsanitize=fuzzer,address,undefined" -fno-sanitize-recover=all -fno-omit-frame-pointer
  -I"$src/include" -I"$src")
lib=("$src"/index/*.c "$src"/query/*.c "$src"/collide/*.c "$src"/mesh/*.c "$src"/region/*.c "$src"/io/*.c)
# The world's query tree from two cells on (collide/world_query.c), not 64: the world
# target's few dozen objects take it too; its nearest-objects heap of 6 entries, not
# 512, so that it overflows (the search then grows its square instead); and groups in
# every cell of two objects or more, not 16 (collide/world_internal.h).
flags+=(-DQK__TREE_MIN=2 -DQK__KHEAP=6 -DQK__FINE_MIN=2)
# region/ reads GeoJSON through json-c (and the geojson target parses it again for its oracle).
flags+=(-DQK_HAVE_JSONC=1 $(pkg-config --cflags json-c))
libs=($(pkg-config --libs json-c) -lpthread)

# Per-target sources and options (max_len bounds the work per input).
sources() {
  case "$1" in
    tree_ops) echo "$src/fuzz/fuzz_tree_ops.c" ;;
    csv) echo "$src/fuzz/fuzz_csv.c" ;;
    poly) echo "$src/fuzz/fuzz_poly.c" ;;
    geojson) echo "$src/fuzz/fuzz_geojson.c" ;;
    mesh_dyadic) echo "$src/fuzz/fuzz_mesh_dyadic.c" ;;
    mesh_general) echo "$src/fuzz/fuzz_mesh_general.c" ;;
    world) echo "$src/fuzz/fuzz_world.c" ;;
    *) echo "fuzz.sh: unknown target '$1' (have: ${all_targets[*]})" >&2; exit 2 ;;
  esac
}
options() {
  case "$1" in
    tree_ops) echo "-max_len=2048" ;;
    csv) echo "-max_len=4096 -close_fd_mask=2 -dict=$src/fuzz/csv.dict" ;;
    poly) echo "-max_len=4096 -dict=$src/fuzz/poly.dict" ;;
    geojson) echo "-max_len=4096 -dict=$src/fuzz/geojson.dict" ;;
    mesh_dyadic) echo "-max_len=2048 -dict=$src/fuzz/poly.dict" ;;
    mesh_general) echo "-max_len=1024 -dict=$src/fuzz/poly.dict" ;;
    world) echo "-max_len=2048" ;;
  esac
}

# The library once, JOBS files at a time, into objects named after their paths
# (region/predicates.c is compiled without contracting a*b+c, as CMakeLists.txt does).
echo "== build the library for the fuzz targets" >&2
mkdir -p "$out/obj"
export out jobs_nice cc
# shellcheck disable=SC2016 # the script runs in the child bash, one file (the last word) each
printf '%s\n' "${lib[@]}" | sed "s|^$src/||" | xargs -P "$jobs" -n 1 bash -c '
  f=${!#} extra=
  [ "$f" = region/predicates.c ] && extra=-ffp-contract=off
  nice -n "$jobs_nice" "$cc" "${@:1:$#-1}" $extra -c "$f" -o "$out/obj/${f//\//_}.o"' _ "${flags[@]}"
objs=()
for f in "${lib[@]}"; do
  f=${f#"$src"/}
  objs+=("$out/obj/${f//\//_}.o")
done
for t in "${targets[@]}"; do
  s=$(sources "$t")
  echo "== build fuzz_$t" >&2
  nice -n "$jobs_nice" "$cc" "${flags[@]}" "$s" "${objs[@]}" "${libs[@]}" -lm -o "$out/fuzz_$t"
done
[ "${FUZZ_BUILD_ONLY:-0}" = 1 ] && exit 0

fuzz_one() { # fuzz_one TARGET: runs it, reports, and leaves its verdict in fuzz_TARGET.rc
  local t=$1 work="$out/corpus/$1" crashes="$out/crashes/$1" log="$out/fuzz_$1.log" seeds=()
  mkdir -p "$work" "$crashes"
  [ -d "$src/fuzz/corpus/$t" ] && seeds+=("$src/fuzz/corpus/$t")
  [ -d "$src/fuzz/regressions/$t" ] && seeds+=("$src/fuzz/regressions/$t")
  # shellcheck disable=SC2046
  if nice -n "$jobs_nice" "$out/fuzz_$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=1024 \
    -print_final_stats=1 -artifact_prefix="$crashes/" $(options "$t") "$work" "${seeds[@]}" \
    >"$log" 2>&1; then
    runs=$(grep -m1 -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || true)
    cov=$(grep -o 'cov: [0-9]*' "$log" | tail -n 1 || true)
    echo "   ok: fuzz_$t ${runs:-?} runs, ${cov:-cov: ?}, corpus $(find "$work" -type f | wc -l) files" >&2
    echo ok >"$out/fuzz_$t.rc"
  else
    echo "   FAILED: fuzz_$t: see $log; input in $crashes/" >&2
    grep -E 'fuzz oracle|ERROR|runtime error|SUMMARY' "$log" | head -n 5 >&2 || true
    echo fail >"$out/fuzz_$t.rc"
  fi
}

for t in "${targets[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n || true; done
  rm -f "$out/fuzz_$t.rc"
  echo "== fuzz_$t for ${seconds}s" >&2
  fuzz_one "$t" &
done
wait
status=0
for t in "${targets[@]}"; do
  [ "$(cat "$out/fuzz_$t.rc" 2>/dev/null)" = ok ] || status=1
done
exit $status
