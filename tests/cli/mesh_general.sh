#!/usr/bin/env bash
# CLI tests for `quadkit mesh` in the general mode: any angles (the issue's coastline-like
# polygon, a lake, a pier), chosen automatically and with --general; --min-angle's report
# (proven bound, exempt angles, smallest input angle); --stats fields; Iceland from the
# shared data, projected and rounded, when present. Exits 77 (skipped) while the library
# does not know the general mode.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

printf '%s\n' '12 2 0 0' '0 0 0' '1 5 1.25' '2 30 3' '3 30.5 20' '4 12 27.75' '5 3 18' \
  '6 4.5 9.5' '7 10 8' '8 16 7.5' '9 14 13' '10 22 10' '11 26 15.5' \
  '11 0' '0 0 1' '1 1 2' '2 2 3' '3 3 4' '4 4 5' '5 5 6' '6 6 0' '7 7 8' '8 8 9' '9 9 7' \
  '10 10 11' '1' '0 12.5 9.5' >"$tmp/coast.poly"
if "$cli" mesh "$tmp/coast.poly" --general -o "$tmp/probe" 2>&1 | grep -q 'unknown mode'; then
  echo "the library does not know the general mode yet: skipped"
  exit 77
fi

expect 0 '"mode": "general", .*"proven_min_angle_deg": 20, "proven_max_angle_deg": 140, "exempt_angles": [0-9]+, "smallest_input_angle_deg": [0-9.]+, "split_vertices": 0, "merged_segments": 0, "angle_histogram": \[' -- \
  "$cli" mesh "$tmp/coast.poly" -o "$tmp/c" --svg "$tmp/c.svg" --msh "$tmp/c.msh" --vtk "$tmp/c.vtu" --poly "$tmp/c.out.poly" --stats
for f in c.node c.ele c.svg c.msh c.vtu c.out.poly; do
  [ -s "$tmp/$f" ] || fail "$f not written"
done
# Input vertices bit-identical in the .node output.
if awk 'NR > 1 { s[$2 " " $3] = 1 } END { exit !(s["5 1.25"] && s["30.5 20"] && s["12 27.75"] && s["26 15.5"]) }' "$tmp/c.node"; then
  passes=$((passes + 1))
else
  fail "input vertices not in the .node file"
fi
# Every angle at least 20 degrees outside small input angles: this input's smallest input
# angle is above 60, so the histogram's bins 0..19 are empty.
"$cli" mesh "$tmp/coast.poly" --general -o "$tmp/c2" --stats >"$tmp/c2.json"
if sed -E 's/.*"angle_histogram": \[//; s/\].*//' "$tmp/c2.json" | awk -F', ' '{ for (i = 1; i <= 20; i++) if ($i != 0) exit 1 }'; then
  passes=$((passes + 1))
else
  fail "an angle below 20 degrees with no small input angle"
fi
expect 0 'general mode: every angle >= 20 degrees \(proven; --min-angle 20\) and <= 140 degrees, except 0 angles inside input angles below 60 degrees' -- \
  "$cli" mesh "$tmp/coast.poly" --general --min-angle 20 -o "$tmp/c3"
# A sharp wedge: its 7-degree input angle is exempt.
printf '3 2 0 0\n0 0 0\n1 8 0\n2 8 1\n3 0\n0 0 1\n1 1 2\n2 2 0\n0\n' >"$tmp/wedge.poly"
expect 0 '"exempt_angles": [1-9][0-9]*, "smallest_input_angle_deg": 7.12' -- "$cli" mesh "$tmp/wedge.poly" --general -o "$tmp/w" --stats
# Size bound.
expect 0 '"mode": "general"' -- "$cli" mesh "$tmp/coast.poly" --general --max-size 2 -o "$tmp/s" --stats
# Crossing segments: refused with a message naming them, nothing written.
printf '4 2 0 0\n0 0 0\n1 4 4\n2 4 0\n3 0 4\n2 0\n0 0 1\n1 2 3\n0\n' >"$tmp/cross.poly"
expect 1 'cross.poly' -- "$cli" mesh "$tmp/cross.poly" --general -o "$tmp/bad"
# A spike whose base vertices are 2^-30 apart needs a split finer than its grid allows, and
# --round auto's grid (2^-24) would merge them: the advice says so rather than "--round auto"
# (which then refused "vertices 2 and 4 coincide"). Its sides slant: axis-parallel ones take
# any double as a split point (the same spike with vertical sides meshes, below).
printf '7 2 0 0\n0 -1 -1\n1 -0.75 -1\n2 -0.5 -9.313225746154785e-10\n3 0.5 0\n4 -0.5 9.313225746154785e-10\n5 -0.75 1\n6 -1 1\n7 0\n0 0 1\n1 1 2\n2 2 3\n3 3 4\n4 4 5\n5 5 6\n6 6 0\n0\n' > "$tmp/spk.poly"
printf '7 2 0 0\n0 -1 -1\n1 -0.5 -1\n2 -0.5 -9.313225746154785e-10\n3 0.5 0\n4 -0.5 9.313225746154785e-10\n5 -0.5 1\n6 -1 1\n7 0\n0 0 1\n1 1 2\n2 2 3\n3 3 4\n4 4 5\n5 5 6\n6 6 0\n0\n' > "$tmp/spkv.poly"
expect 0 '"mode": "general"' -- "$cli" mesh "$tmp/spkv.poly" -o "$tmp/spkv" --stats
# ... also after a --round finer than it (that advice named auto's grid again)
expect 1 "needs a split point .* Rounding cannot help: --round auto's grid 2\\^-24 would make the vertices at \\(-0\\.5, -9\\.3132257461547852e-10\\)" -- "$cli" mesh "$tmp/spk.poly" -o "$tmp/bad" --round 2^-32
expect 1 "needs a split point .* Rounding cannot help: --round auto's grid 2\\^-24 would make the vertices at \\(-0\\.5, -9\\.3132257461547852e-10\\) and \\(-0\\.5, 9\\.3132257461547852e-10\\) one" -- "$cli" mesh "$tmp/spk.poly" -o "$tmp/bad"
# No exact split point at all: the advice is rounding, also at an unproven --min-angle
# (review6_data.sh has the angle's advice).
printf '3 2 0 0\n0 0.1 0.2\n1 1.3 0.05\n2 0.7 1.1\n3 0\n0 0 1\n1 1 2\n2 2 0\n0\n' > "$tmp/dec.poly"
expect 1 'needs a split point.*exact ones: none guaranteed. Round the input to a grid: --round auto \(2\^-25 here\)$' -- "$cli" mesh "$tmp/dec.poly" --max-size 0.05 --min-angle 30 -o "$tmp/bad"
ls "$tmp"/bad* >/dev/null 2>&1 && fail "output written for bad input"
# An open chain encloses nothing: an error saying so, not an empty mesh.
printf '3 2 0 0\n0 0 0\n1 4 1\n2 8 0\n2 0\n0 0 1\n1 1 2\n0\n' >"$tmp/open.poly"
expect 1 'open.poly: nothing to mesh' -- "$cli" mesh "$tmp/open.poly" -o "$tmp/empty"
ls "$tmp"/empty* >/dev/null 2>&1 && fail "output written for an input without area"
# Touching input: two squares side by side, B's left side inside A's right side (integer,
# axis-parallel: the book's mode refuses touching components, so the automatic choice runs
# the general mode, which splits A's side at B's corners and merges B's side into it).
printf '8 2 0 1\n1 0 0 0\n2 4 0 0\n3 4 4 0\n4 0 4 0\n5 4 1 0\n6 8 1 0\n7 8 3 0\n8 4 3 0\n8 1\n1 1 2 1\n2 2 3 2\n3 3 4 3\n4 4 1 4\n5 5 6 5\n6 6 7 6\n7 7 8 7\n8 8 5 8\n0\n' >"$tmp/adj.poly"
expect 0 '"components": 2, .*"mode": "general", .*"split_vertices": 2, "merged_segments": 1, ' -- \
  "$cli" mesh "$tmp/adj.poly" -o "$tmp/adj" --poly "$tmp/adj.out.poly" --stats
# The shared side's mesh edges carry A's marker (2): the earlier segment's.
awk 'NR > 1 && $4 == 8 { bad = 1 } NR > 1 && $4 == 2 { n++ } END { exit !(n >= 1 && !bad) }' "$tmp/adj.out.poly" ||
  fail "adj.out.poly: the shared side's edges should carry marker 2, none 8"
expect 1 'adj.poly:17: components 1 and 2 touch or cross: segments 2 \(line 12\) and 7 \(line 17\) meet' -- \
  "$cli" mesh "$tmp/adj.poly" -o "$tmp/adjb" --book
# A crossing stays refused in the automatic choice too, with the book's mode's message.
printf '8 2 0 0\n1 0 0\n2 4 0\n3 4 4\n4 0 4\n5 3 1\n6 8 1\n7 8 3\n8 3 3\n8 0\n1 1 2\n2 2 3\n3 3 4\n4 4 1\n5 5 6\n6 6 7\n7 7 8\n8 8 5\n0\n' >"$tmp/adjx.poly"
expect 1 'adjx.poly:[0-9]+: components 1 and 2 touch or cross' -- "$cli" mesh "$tmp/adjx.poly" -o "$tmp/adjx"
ls "$tmp"/adjx* | grep -qv 'adjx.poly$' && fail "output written for crossing input"

shared=${QK_SHARED_DIR:-$src/../shared}
if [ -f "$shared/data/countries-50m.geojson" ]; then
  expect 0 '"input": \{"format": "geojson", "features": 1, "name": "Iceland", "projection": "equirect", "lat0_deg": 6[45]\.[0-9]*, .*"round": 0.0625, "rounded_coordinates": [1-9][0-9]*\}, "mode": "general"' -- \
    "$cli" mesh "$shared/data/countries-50m.geojson" --field name=Iceland --project equirect --round 2^-4 -o "$tmp/ice" --svg "$tmp/ice.svg" --stats
fi
report
