#!/usr/bin/env bash
# CLI tests with hostile and unusual input files, one regression per bug a review found:
# a UTF-8 byte order mark on OBJECTS/MOVES (world), GeoJSON and .poly files; long CSV
# fields in `join` (a field was cut at 255 characters, so junk after 300 blanks passed as
# a number); unknown GeoJSON types (a typo was skipped silently); the position of a JSON
# error given once. Every error must exit 1 and leave an existing -o target unchanged.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

unchanged() { # unchanged FILE: the -o target still holds "keep"
  if [ "$(cat "$1")" = keep ]; then
    passes=$((passes + 1))
  else
    fail "$1 changed after an error: $(head -c 200 "$1")"
  fi
}

# ---- world: a byte order mark must not turn the first data row into a header ----------
bom=$'\xef\xbb\xbf'
printf '%s1,disc,0,0,1\n2,disc,0.5,0,1\n' "$bom" >"$tmp/obj.csv"
: >"$tmp/none.csv"
same_text "world: BOM before the first object" "$("$cli" world "$tmp/obj.csv" "$tmp/none.csv" | tr '\n' ' ')" \
  "frame,a,b 0,1,2 "
printf '1,disc,0,0,1\n2,disc,0.5,0,1\n' >"$tmp/obj2.csv"
printf '%s0,1,9,9,1\n' "$bom" >"$tmp/mv.csv"
same_text "world: BOM before the first move" "$("$cli" world "$tmp/obj2.csv" "$tmp/mv.csv" | tr '\n' ' ')" \
  "frame,a,b "
printf '1,disc,0,0,1\r\n2,disc,0.5,0,1\r\n' >"$tmp/crlf.csv"
same_text "world: CRLF" "$("$cli" world "$tmp/crlf.csv" "$tmp/none.csv" | tr '\n' ' ')" "frame,a,b 0,1,2 "
echo keep >"$tmp/keep.csv"
printf '1,1,5,5,1\n0,1,5,5,1\n' >"$tmp/order.csv"
expect 1 'order.csv:2:1: frames out of order' -- "$cli" world "$tmp/obj2.csv" "$tmp/order.csv" -o "$tmp/keep.csv"
unchanged "$tmp/keep.csv"
printf '0,7,5,5,1\n' >"$tmp/unknown.csv"
expect 1 "unknown.csv:1:3: unknown id '7'" -- "$cli" world "$tmp/obj2.csv" "$tmp/unknown.csv" -o "$tmp/keep.csv"
unchanged "$tmp/keep.csv"

# ---- join: fields longer than 255 characters ---------------------------------------------
sq='{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}'
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"name":"sq"},"geometry":%s}]}\n' "$sq" >"$tmp/sq.geojson"
pad=$(printf '%300s' '')
printf 'x,y\n0.5,0.5%sjunk\n' "$pad" >"$tmp/junk.csv"
expect 1 'junk.csv:2:5: field 2 \(y\) is not a finite number' -- "$cli" join "$tmp/sq.geojson" "$tmp/junk.csv" -o "$tmp/keep.csv"
unchanged "$tmp/keep.csv"
zeros=$(printf '%0300d' 0)
printf 'x,y\n0.5,%s0.5\n0.5,0.%s1\n' "$zeros" "$zeros" >"$tmp/long.csv"
same_text "join: 300-digit numbers" "$("$cli" join "$tmp/sq.geojson" "$tmp/long.csv" | cut -d, -f3 | tr '\n' ' ')" \
  "feature 0 0 "
printf '%sname,x,y\r\n"Rome, Lazio",0.5,0.5\r\n"a ""b""",2,2\r\n' "$bom" >"$tmp/q.csv"
same_text "join: BOM, CRLF, quoted commas, --xy by name" \
  "$("$cli" join "$tmp/sq.geojson" "$tmp/q.csv" --xy x,y --field name | tr '\n' ' ')" \
  'name,x,y,feature,feature_name "Rome, Lazio",0.5,0.5,0,sq "a ""b""",2,2,-1, '
same_text "join: --xy by number" "$("$cli" join "$tmp/sq.geojson" "$tmp/q.csv" --xy 2,3 | awk -F, '{ print $NF }' | tr '\n' ' ')" \
  "feature 0 -1 "

printf 'x,x,y\n5,0.5,0.5\n' >"$tmp/twice.csv"
# (with the column of the second name, as the other commands say it)
expect 1 "twice.csv:1:3: column name 'x' appears twice in the header \\(fields 1 and 2\\)" -- \
  "$cli" join "$tmp/sq.geojson" "$tmp/twice.csv" --xy x,y -o "$tmp/keep.csv"
unchanged "$tmp/keep.csv"

# ---- GeoJSON: BOM accepted; unknown types refused; the position given once -------------
printf '%s' "$bom" >"$tmp/bom.geojson"
cat "$tmp/sq.geojson" >>"$tmp/bom.geojson"
printf 'x,y\n0.5,0.5\n' >"$tmp/p.csv"
same_text "GeoJSON with a BOM" "$("$cli" join "$tmp/bom.geojson" "$tmp/p.csv" | tail -1)" "0.5,0.5,0"
printf '{"type":"FeatureColection","features":[]}\n' >"$tmp/typo.geojson"
expect 1 'typo.geojson:1:1: unknown GeoJSON type "FeatureColection"' -- "$cli" join "$tmp/typo.geojson" "$tmp/p.csv" -o "$tmp/keep.csv"
unchanged "$tmp/keep.csv"
expect 1 'typo.geojson:1:1: unknown GeoJSON type' -- "$cli" mesh "$tmp/typo.geojson" -o "$tmp/m"
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},"geometry":{"type":"polygon","coordinates":[]}}]}\n' >"$tmp/lower.geojson"
expect 1 'feature 0: unknown geometry type "polygon"' -- "$cli" regions "$tmp/lower.geojson"
head -c 60 "$tmp/sq.geojson" >"$tmp/trunc.geojson"
expect 1 '^quadkit join: [^ ]*trunc.geojson:1:61: unexpected end of input$' -- "$cli" join "$tmp/trunc.geojson" "$tmp/p.csv" -o "$tmp/keep.csv"
unchanged "$tmp/keep.csv"
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},"geometry":{"type":"Point","coordinates":[0,0]}}]}\n' >"$tmp/point.geojson"
expect 0 '"skipped_geometries": 1' -- "$cli" regions "$tmp/point.geojson"

# An island cut at the antimeridian whose cut points differ (Natural Earth's Fiji): kept
# whole by --project equirect, the parts meet in T-junctions along the cut; they used to be
# refused ("vertex ... lies on segment ..."), now the cut edge is split there.
printf '{"type":"MultiPolygon","coordinates":[[[[179,-1],[180,-1],[180,1],[179,1],[179,-1]]],[[[-180,-0.5],[-179,-0.5],[-179,0.5],[-180,0.5],[-180,-0.5]]]]}\n' >"$tmp/cut.geojson"
expect 0 '"duplicate_segments": 1, "split_points": 2, ' -- "$cli" mesh "$tmp/cut.geojson" --project equirect --round 2^-4 -o "$tmp/cut" --stats
# ... and the same in planar data: a square with a smaller one against its side.
printf '{"type":"MultiPolygon","coordinates":[[[[0,0],[4,0],[4,4],[0,4],[0,0]]],[[[4,1],[6,1],[6,3],[4,3],[4,1]]]]}\n' >"$tmp/t.geojson"
expect 0 '"triangles": [1-9].*"split_points": 2, ' -- "$cli" mesh "$tmp/t.geojson" -o "$tmp/t" --stats

# A projected lon/lat square meets the book's conditions after rounding; it took the
# book's or dyadic mode and millions of triangles (minutes). GeoJSON means the general mode.
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}\n' >"$tmp/cell.geojson"
expect 0 '"triangles": 2, .*"mode": "general"' -- "$cli" mesh "$tmp/cell.geojson" --project equirect --round 2^-4 -o "$tmp/cell" --stats
# A degenerate ring (A, B, A) inside the domain is dropped, and so are its points: they
# stayed as isolated input vertices inside the mesh.
printf '{"type":"MultiPolygon","coordinates":[[[[0,0],[8,0],[8,8],[0,8],[0,0]]],[[[2.5,2.5],[3.75,2.25],[2.5,2.5],[2.5,2.5]]]]}\n' >"$tmp/deg.geojson"
expect 0 '"dropped_rings": 1' -- "$cli" mesh "$tmp/deg.geojson" -o "$tmp/deg" --stats
if awk 'NR > 1 && (($2 == 2.5 && $3 == 2.5) || ($2 == 3.75 && $3 == 2.25)) { found = 1 } END { exit !found }' "$tmp/deg.node"; then
  fail "the points of a dropped ring are in the mesh"
else
  passes=$((passes + 1))
fi

# Crossing rings in GeoJSON: both segments named by feature, polygon, ring and position,
# with their line and column (review6.sh has more).
printf '{"type":"MultiPolygon","coordinates":[[[[0,0],[4,0],[4,4],[0,4],[0,0]]],[[[2,2],[6,2.5],[6,3],[2,2]]]]}\n' >"$tmp/crossing.geojson"
expect 1 'crossing.geojson:1:47: segments 1 and 4 cross or overlap \(input segments feature 0, polygon 0, ring 0, position 1 and feature 0, polygon 1, ring 0, position 0, at 1:75\)' -- \
  "$cli" mesh "$tmp/crossing.geojson" -o "$tmp/crossing"

# ---- .poly: BOM accepted; bad geometry refused naming the line, nothing written ------
printf '%s4 2 0 0\n0 0 0\n1 1 0\n2 1 1\n3 0 1\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' "$bom" >"$tmp/bom.poly"
expect 0 '"triangles": [1-9]' -- "$cli" mesh "$tmp/bom.poly" -o "$tmp/b" --stats
printf '4 2 0 0\n0 0 0\n1 1 0\n2 1 1\n3 0 0\n3 0\n0 0 1\n1 1 2\n2 2 3\n0\n' >"$tmp/dup.poly"
expect 1 'dup.poly:5: vertices 0 and 3 coincide' -- "$cli" mesh "$tmp/dup.poly" -o "$tmp/d"
printf '4 2 0 0\n0 0 0\n1 1 0\n2 1 1\n3 0 1\n4 0\n0 0 2\n1 1 3\n2 0 1\n3 2 3\n0\n' >"$tmp/cross.poly"
expect 1 'cross.poly:[0-9]+: .*segments 0 \(line 7\) and 1 \(line 8\) meet' -- "$cli" mesh "$tmp/cross.poly" -o "$tmp/d"
printf '4 2 0 0\n0 0 0\n1 1 0\n2 1 1\n3 0 1\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n1\n0 5 5\n' >"$tmp/hole.poly"
expect 1 'hole.poly:12: hole 0 at \(5, 5\) lies outside the domain' -- "$cli" mesh "$tmp/hole.poly" -o "$tmp/d"
# Integer, axis-parallel, huge: a square of side 2^30 ran out of time and memory in the
# book's mode (unit cells all along its sides). Automatically the general mode meshes it;
# --book refuses at once, naming the longest segment and the way out.
printf '4 2 0 0\n0 0 0\n1 1073741824 0\n2 1073741824 1073741824\n3 0 1073741824\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/huge.poly"
expect 0 '"mode": "general"' -- "$cli" mesh "$tmp/huge.poly" -o "$tmp/h" --stats
expect 1 "huge.poly:7: the book's mode would need 4.29e\\+09 unit steps .*segment 0 alone 1.07e\\+09.*--general.*scale the input down" -- \
  "$cli" mesh "$tmp/huge.poly" -o "$tmp/d" --book
# A 2^31 by 1 rectangle: the general mode would need 2^31 cells along it; refused naming both
# long sides (once 18 s and 2.5 GB).
printf '4 2 0 0\n0 0 0\n1 2147483648 0\n2 2147483648 1\n3 0 1\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/sliver.poly"
expect 1 'sliver.poly: segment 0 \(line 7\) and segment 2 \(line 9\) stay within' -- "$cli" mesh "$tmp/sliver.poly" -o "$tmp/d"
# Two outputs naming one file: a usage error before any work, the file untouched.
echo keep >"$tmp/same.node"
expect 2 'both write' -- "$cli" mesh "$tmp/bom.poly" -o "$tmp/same" --svg "$tmp/same.node"
unchanged "$tmp/same.node"
expect 2 '--msh and --vtk both write' -- "$cli" mesh "$tmp/bom.poly" -o "$tmp/d" --msh "$tmp/x.msh" --vtk "$tmp/x.msh"
for f in d.node d.ele; do [ -e "$tmp/$f" ] && fail "$f written after an error"; done
report
