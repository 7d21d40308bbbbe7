#!/usr/bin/env bash
# CLI tests for `quadkit mesh --round auto` (the grid chosen from the input) and for the
# refusal that suggests it: decimal coordinates refused without --round (exit 1, the
# file's line, the option and its grid to type), meshed with --round auto (the grid on
# stderr and in --stats), the suggestion after an explicit grid too fine; inputs that the
# auto grid collapses or invalidates refused with the grid named and nothing written;
# Norway and Maine from the shared data projected (SKIPPED when absent). The meshes
# themselves are checked exactly by tests/test_mesh_round_auto.c.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- decimal coordinates: refused without --round, meshed with --round auto ------------
printf '4 2 0 0\n1 0.1 0.1\n2 37.7 0.2\n3 21.3 22.9\n4 3.3 19.1\n4 0\n1 1 2\n2 2 3\n3 3 4\n4 4 1\n0\n' >"$tmp/t2.poly"
expect 1 "^quadkit mesh: $tmp/t2.poly:7: segment 1 \\(line 7\\) from \\(0.10000000000000001, 0.10000000000000001\\) to \\(37.700000000000003, 0.20000000000000001\\) needs a split point at steps of 2\\^-1 of its length; exact ones: none guaranteed\\. Round the input to a grid: --round auto \\(2\\^-20 here\\)$" \
  -- "$cli" mesh "$tmp/t2.poly" -o "$tmp/t2" --max-size 5
nothing_written "$tmp/t2"
# Coordinates below 2^6, extent 37.6 below 2^6: k = ceil((6 + 6 - 52) / 2) = -20.
expect 0 "^quadkit mesh: --round auto: the grid 2\\^-20 \\(coordinates below 2\\^6, extent below 2\\^6\\): 8 coordinates of $tmp/t2.poly moved to it, each by at most 2\\^-21$" \
  -- "$cli" mesh "$tmp/t2.poly" -o "$tmp/t2" --max-size 5 --round auto
[ -s "$tmp/t2.node" ] && [ -s "$tmp/t2.ele" ] || fail "t2 --round auto: no mesh written"
expect 0 '"input": \{"format": "poly", "round": 9.5367431640625e-07, "rounded_coordinates": 8\}, "mode": "general"' \
  -- "$cli" mesh "$tmp/t2.poly" -o "$tmp/t2s" --max-size 5 --round auto --stats
# The input vertices in the .node file are the input rounded to 2^-20 (0.1 * 2^20 =
# 104857.6 -> 104858; 37.7 * 2^20 = 39531315.2 -> 39531315), bit-identical through %.17g.
same_text "t2 --round auto: input vertices 1 and 2 rounded to 2^-20" \
  "$(sed -n '2,3p' "$tmp/t2.node" | awk '{printf "%s %.17g %.17g;", $1, $2 * 1048576, $3 * 1048576}')" \
  "1 104858 104858;2 39531315 209715;"
# From standard input, named as the errors name it (the note said "coordinates of -").
expect 0 "^quadkit mesh: --round auto: the grid 2\\^-20 .*: 8 coordinates of <stdin> moved to it" \
  -- bash -c "'$cli' mesh - -o '$tmp/t2in' --max-size 5 --round auto <'$tmp/t2.poly'"
# An explicit grid too fine: the suggestion names it and auto's grid.
expect 1 "needs a split point .* Round the input to a coarser grid than --round 2\\^-50 \\(--round auto: 2\\^-20 here\\)$" \
  -- "$cli" mesh "$tmp/t2.poly" -o "$tmp/t2f" --max-size 5 --round 2^-50
nothing_written "$tmp/t2f"
# Deeper splits than the auto grid's guarantee: vertex 4 lies (on the grid 2^-20) at a
# distance of 2^-40 / |segment 1| from segment 1, whose ends are on that grid too, so the
# segment needs pieces far below the grid step: refused, naming the grid auto chose.
printf '4 2 0 0\n1 0.1 0.1\n2 63.3 1.7\n3 0.3 40.1\n4 6.8234062194824219 0.27021312713623047\n3 0\n1 1 2\n2 2 3\n3 3 1\n0\n' >"$tmp/near.poly"
expect 1 "^quadkit mesh: $tmp/near.poly:7: segment 1 \\(line 7\\) .* needs a split point at steps of 2\\^-27 of its length; exact ones: 2\\^-26\\. Round the input to a coarser grid than 2\\^-20, which --round auto chose \\(e\\.g\\. --round 2\\^-18\\)$" \
  -- "$cli" mesh "$tmp/near.poly" -o "$tmp/near" --round auto
nothing_written "$tmp/near"
expect 0 "" -- "$cli" mesh "$tmp/near.poly" -o "$tmp/near" --round 2^-18
# Input already on the grid (integers): nothing moves.
printf '3 2 0 0\n1 0 0\n2 40 0\n3 0 30\n3 0\n1 1 2\n2 2 3\n3 3 1\n0\n' >"$tmp/int.poly"
expect 0 '"round": 9.5367431640625e-07, "rounded_coordinates": 0\}' \
  -- "$cli" mesh "$tmp/int.poly" -o "$tmp/int" --round auto --stats

# ---- the auto grid collapses or invalidates the input: refused, grid named --------------
# Vertex 5 is 1e-7 from vertex 1, below half the grid 2^-19 (extent 100): they coincide.
printf '5 2 0 0\n1 0 0\n2 100 0\n3 100 100\n4 0 100\n5 0.0000001 0.0000001\n5 0\n1 1 2\n2 2 3\n3 3 4\n4 4 5\n5 5 1\n0\n' >"$tmp/col.poly"
# (the advice says so: it said "Round the input to a grid: --round auto (2^-19 here)")
expect 1 "col.poly:11: segment 4 .* Rounding cannot help: --round auto's grid 2\\^-19 would make the vertices at \\(0, 0\\) and \\(9\\.9999999999999995e-08, 9\\.9999999999999995e-08\\) one" -- "$cli" mesh "$tmp/col.poly" -o "$tmp/col0"
expect 1 "^quadkit mesh: $tmp/col.poly:6: vertices 1 and 5 coincide at \\(0, 0\\) \\(the coordinates were rounded to the grid 2\\^-19 by --round auto\\)$" \
  -- "$cli" mesh "$tmp/col.poly" -o "$tmp/col" --round auto
nothing_written "$tmp/col"
# An internal segment's end 4e-7 above the bottom side lands on it.
printf '6 2 0 0\n1 0 0\n2 100 0\n3 100 100\n4 0 100\n5 10 10\n6 50 0.0000004\n5 0\n1 1 2\n2 2 3\n3 3 4\n4 4 1\n5 5 6\n0\n' >"$tmp/on.poly"
expect 1 "^quadkit mesh: $tmp/on.poly:9: vertex 6 \\(line 7\\) at \\(50, 0\\) lies on segment 1 \\(line 9\\) \\(the coordinates were rounded to the grid 2\\^-19 by --round auto\\)$" \
  -- "$cli" mesh "$tmp/on.poly" -o "$tmp/on" --round auto
nothing_written "$tmp/on"
# GeoJSON merges points that coincide in the input; two that only the auto grid makes one
# are refused, naming both positions (an explicit --round merges them, counted).
cat >"$tmp/col.geojson" <<'EOF'
{"type":"FeatureCollection","features":[
{"type":"Feature","properties":{"name":"A"},"geometry":{"type":"Polygon","coordinates":[[[0,0],[10,0],[10,10],[0.0000001,10],[0,10],[0,0]]]}}
]}
EOF
expect 1 "^quadkit mesh: $tmp/col.geojson:2:111: feature 0, polygon 0, ring 0, position 3 and feature 0, polygon 0, ring 0, position 4 \\(at 2:126\\) are distinct points that both round to \\(0, 10\\) on the grid 2\\^-22 that --round auto chose \\(coordinates below 2\\^4, extent below 2\\^4\\): merged, they would change the input's shape\\. Give a finer grid \\(--round 2\\^-30, say\\) or remove one of the points$" \
  -- "$cli" mesh "$tmp/col.geojson" -o "$tmp/cg" --round auto
nothing_written "$tmp/cg"
expect 0 '"merged_vertices": 1, .*"round": 0.0625, "rounded_coordinates": 1\}' \
  -- "$cli" mesh "$tmp/col.geojson" -o "$tmp/cg2" --round 2^-4 --stats

# ---- real coastlines, projected --------------------------------------------------------
shared=${QK_SHARED_DIR:-$src/../shared}
if [ -f "$shared/data/countries-50m.geojson" ] && [ -f "$shared/data/us-states-10m.geojson" ]; then
  expect 1 "^quadkit mesh: $shared/data/countries-50m.geojson:1:[0-9]+: feature Norway: segment [0-9]+ from .* needs a split point .* Round the input to a grid: --round auto \\(2\\^-3 here\\) \\(input segment feature 88, " \
    -- "$cli" mesh "$shared/data/countries-50m.geojson" --field name=Norway --project equirect -o "$tmp/no"
  nothing_written "$tmp/no"
  # Metres: y below 2^24 (Svalbard, 80 N: 8.9e6 m), extent below 2^22: k = -3.
  expect 0 "^quadkit mesh: --round auto: the grid 2\\^-3 \\(coordinates in metres below 2\\^24, extent below 2\\^22\\): [1-9][0-9]* coordinates of .*countries-50m.geojson moved to it, each by at most 2\\^-4$" \
    -- "$cli" mesh "$shared/data/countries-50m.geojson" --field name=Norway --project equirect --round auto -o "$tmp/no"
  [ -s "$tmp/no.node" ] || fail "Norway --round auto: no mesh written"
  expect 0 '"name": "Maine", "projection": "equirect", .*"round": 0.03125, "rounded_coordinates": [1-9][0-9]*\}, "mode": "general"' \
    -- "$cli" mesh "$shared/data/us-states-10m.geojson" --field name=Maine --project equirect --round auto -o "$tmp/me" --stats
else
  echo "no countries-50m.geojson / us-states-10m.geojson under $shared/data: SKIPPED the coastlines"
fi
report
