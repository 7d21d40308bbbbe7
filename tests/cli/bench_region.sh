#!/usr/bin/env bash
# Smoke test of quadkit-bench's polygon point location on countries-50m: GEOS (planar,
# prepared "contains") must agree with quadkit's planar open rule; S2's geodesic edges
# may disagree on a few points near borders, which the bench reports and this test does
# not count as a failure. Skipped (exit 77) without the baselines, GEOS or S2, or without
# $QK_SHARED_DIR/data/countries-50m.geojson.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"
layer="${QK_SHARED_DIR:-$src/../shared}/data/countries-50m.geojson"
if [ ! -f "$layer" ]; then
  echo "SKIPPED: $layer not found (set QK_SHARED_DIR to the directory holding data/)"
  exit 77
fi
inc=${QK_BENCH_INCLUDE_DIR:-/usr/include}
for h in geos_c.h s2/mutable_s2shape_index.h; do
  [ -e "$inc/$h" ] || { echo "SKIPPED: $h not installed; 'make bench' installs it"; exit 77; }
done
export QK_SHARED_DIR="${QK_SHARED_DIR:-$src/../shared}"
# shellcheck source=lib/bench.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/bench.bash"
if "$bench" --quick --json --op region --n 5000 >"$out" 2>"$tmp/bench.err"; then
  passes=$((passes + 1))
else
  fail "quadkit-bench --op region exited non-zero: $(tail -5 "$tmp/bench.err")"
fi
if grep '"impl":"geos"' "$out" | grep -q '"matches":false'; then
  fail "GEOS disagrees with quadkit --planar: $(grep '"impl":"geos"' "$out" | grep '"matches":false')"
else
  passes=$((passes + 1))
fi
for i in quadkit geos s2; do expect_impl $i region; done
report
