#!/usr/bin/env bash
# CLI tests for `quadkit mesh` input handling that needs no general mode: GeoJSON input
# (feature choice, hole points, errors with line/column or feature), --round (counted in
# --stats, a note for .poly files), --project, the option rules, and --min-angle's report
# for the book's and dyadic modes.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# Two planar features: a square with a square hole (edges at 0/90 degrees, which the book's
# mode could mesh, but GeoJSON input takes the general mode unless told otherwise) and a
# diamond; properties to pick them by.
cat >"$tmp/two.geojson" <<'JSON'
{"type": "FeatureCollection", "features": [
 {"type": "Feature", "properties": {"name": "ring"}, "geometry": {"type": "Polygon",
  "coordinates": [[[0,0],[16,0],[16,16],[0,16],[0,0]], [[4,4],[4,12],[12,12],[12,4],[4,4]]]}},
 {"type": "Feature", "properties": {"name": "diamond"}, "geometry": {"type": "Polygon",
  "coordinates": [[[24,0],[28,4],[24,8],[20,4],[24,0]]]}}
]}
JSON
expect 0 '"triangles": [1-9][0-9]*,.*"input": \{"format": "geojson", "features": 1, "name": "ring", "projection": "none", "merged_vertices": 0, "dropped_rings": 0, "duplicate_segments": 0, "split_points": 0, "filled_holes": 0, "gap_faces": 0, "round": 0, "rounded_coordinates": 0\}, "mode": "general"' -- \
  "$cli" mesh "$tmp/two.geojson" --field name=ring -o "$tmp/ring" --stats
# The hole was cut out: no triangle has its centroid strictly inside [4,12]^2.
if awk 'FNR==NR { if (FNR > 1) { x[$1]=$2; y[$1]=$3 }; next } FNR > 1 {
      cx=(x[$2]+x[$3]+x[$4])/3; cy=(y[$2]+y[$3]+y[$4])/3; if (cx > 4 && cx < 12 && cy > 4 && cy < 12) bad=1 }
      END { exit bad }' "$tmp/ring.node" "$tmp/ring.ele"; then
  passes=$((passes + 1))
else
  fail "a triangle inside the hole"
fi
expect 0 '"features": 1, "name": "diamond"' -- "$cli" mesh "$tmp/two.geojson" --feature 1 -o "$tmp/d" --stats
expect 0 '"features": 2, ' -- "$cli" mesh "$tmp/two.geojson" -o "$tmp/both" --stats
expect 1 'no feature has name=lake \(of 2 features\)' -- "$cli" mesh "$tmp/two.geojson" --field name=lake -o "$tmp/bad"
expect 1 'feature 7 does not exist \(2 features\)' -- "$cli" mesh "$tmp/two.geojson" --feature 7 -o "$tmp/bad"
printf '{"type": "FeatureCollection", "features": [\n  {"type": "Feature", \n  "geometry": oops}]}\n' >"$tmp/broken.geojson"
expect 1 'broken.geojson:3:[0-9]+: ' -- "$cli" mesh "$tmp/broken.geojson" -o "$tmp/bad"
ls "$tmp"/bad* >/dev/null 2>&1 && fail "output written for bad input"

# Rounding: counted, and a note for .poly input (whose markers are not carried).
expect 0 '"round": 0.5, "rounded_coordinates": 0' -- "$cli" mesh "$tmp/two.geojson" --field name=ring --round 2^-1 -o "$tmp/r" --stats
printf '4 2 0 0\n0 0.25 0\n1 4 0\n2 4 4\n3 0 4\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/q.poly"
expect 0 '"round": 1, "rounded_coordinates": 1' -- "$cli" mesh "$tmp/q.poly" --round 1 -o "$tmp/q" --stats
expect 0 'round 1: 1 coordinates of .*q.poly moved to the grid' -- "$cli" mesh "$tmp/q.poly" --round 1 -o "$tmp/q"
check_node() { awk 'NR > 1 && $2 == 0 && $3 == 0 { z = 1 } NR > 1 && $2 == 0.25 { q = 1 } END { exit !(z && !q) }' "$tmp/q.node"; }
if check_node; then passes=$((passes + 1)); else fail "the rounded vertex is not (0, 0)"; fi

# Projection: lon/lat in degrees to metres (a 0.01-degree square at the equator is
# about 1113 m wide).
cat >"$tmp/ll.geojson" <<'JSON'
{"type": "Feature", "properties": {}, "geometry": {"type": "Polygon",
 "coordinates": [[[10,0],[10.01,0],[10.01,0.01],[10,0.01],[10,0]]]}}
JSON
expect 0 '"projection": "equirect", "lat0_deg": 0.00[0-9]*, .*"round": 0.0625, "rounded_coordinates": [1-9]' -- \
  "$cli" mesh "$tmp/ll.geojson" --project equirect --round 2^-4 -o "$tmp/ll" --stats
if awk 'NR > 1 { if ($2 > m) m = $2 } END { exit !(m > 1113000 && m < 1114200) }' "$tmp/ll.node"; then
  passes=$((passes + 1))
else
  fail "projected x is not about 1113 km"
fi

# A hole 5.8e-11 thin (a triangle across 512 units): its hole point is found (the probes
# began at 2^-41 of an edge's length, over the hole, and it was refused as "no point found
# strictly inside this hole ring").
printf '%s' '{"type":"Polygon","coordinates":[[[0,0],[1024,0],[1024,1024],[0,1024],[0,0]],[[256,512],[512,512.0000000000582],[768,512],[256,512]]]}' > "$tmp/thin.geojson"
expect 0 '"triangles": 10, ' -- "$cli" mesh "$tmp/thin.geojson" -o "$tmp/thin" --stats

# Option rules.
expect 2 'apply to GeoJSON input' -- "$cli" mesh "$src/examples/mesh/notes.poly" --project equirect -o "$tmp/u"
expect 2 'apply to GeoJSON input' -- "$cli" mesh "$src/examples/mesh/notes.poly" --feature 0 -o "$tmp/u"
expect 2 'exclude each other' -- "$cli" mesh "$tmp/two.geojson" --feature 0 --field name=ring -o "$tmp/u"
expect 2 'expected NAME=VALUE' -- "$cli" mesh "$tmp/two.geojson" --field name -o "$tmp/u"
expect 2 "the one projection is 'equirect'" -- "$cli" mesh "$tmp/ll.geojson" --project mercator -o "$tmp/u"
expect 2 'grid step must be a positive number' -- "$cli" mesh "$tmp/q.poly" --round -1 -o "$tmp/u"
expect 2 'expected 2\^-q' -- "$cli" mesh "$tmp/q.poly" --round 2^x -o "$tmp/u"
expect 2 'exclude each other' -- "$cli" mesh "$tmp/q.poly" --general --book -o "$tmp/u"
expect 2 '--size is the book' -- "$cli" mesh "$tmp/q.poly" --general --size 16 -o "$tmp/u"

# --min-angle's report in the book's mode.
expect 0 "book's mode: every angle in \[45, 90\] degrees \(proven" -- "$cli" mesh "$src/examples/mesh/notes.poly" --min-angle 30 -o "$tmp/n"
report
