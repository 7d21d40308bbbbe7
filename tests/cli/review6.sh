#!/usr/bin/env bash
# CLI regressions from a sixth review, on hostile inputs not tried before (one block per
# finding; each failed before its fix): the mesher's GeoJSON errors without a line and
# column, and a ring round a pole (Antarctica) reported by its symptoms.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- mesh, GeoJSON: errors named "feature F ring R point P" and no place in the file ----
# (the ring counted across the feature's polygons, the point after merging); now feature,
# polygon, ring and position as the region reader numbers them, with line and column.
# Nested GeometryCollections, a Point first, positions on lines of their own.
cat >"$tmp/gc.geojson" <<'EOF2'
{"type": "FeatureCollection",
 "features": [
  {"type": "Feature", "properties": {"name": "pt"}, "geometry": {"type": "Point", "coordinates": [9, 9]}},
  {"type": "Feature", "properties": {"name": "gc"},
   "geometry": {"type": "GeometryCollection", "geometries": [
     {"type": "Point", "coordinates": [0, 0]},
     {"type": "GeometryCollection", "geometries": [
       {"type": "Polygon", "coordinates": [
         [[0, 0], [4, 0], [4, 4], [0, 4], [0, 0]]]},
       {"type": "MultiPolygon", "coordinates": [[[[10, 10], [11, 10], [11, 11], [10, 10]]],
         [[[2, 2],
           [6, 2.5],
           [6, 3], [2, 2]]]]}]}]}}
 ]}
EOF2
# [4, 0] is at line 9, column 19; [2, 2] of the third polygon at line 11, column 12
expect 1 "^quadkit mesh: $tmp/gc.geojson:9:19: segments 1 and 7 cross or overlap \\(input segments feature 1, polygon 0, ring 0, position 1 and feature 1, polygon 2, ring 0, position 0, at 11:12\\)$" \
  -- "$cli" mesh "$tmp/gc.geojson" -o "$tmp/gc"
nothing_written "$tmp/gc"
# the same with a byte order mark and CRLF line ends (columns count bytes after the mark)
printf '\xEF\xBB\xBF' >"$tmp/gcbom.geojson"
sed 's/$/\r/' "$tmp/gc.geojson" >>"$tmp/gcbom.geojson"
expect 1 "gcbom.geojson:9:19: segments 1 and 7 cross or overlap .* at 11:12\\)$" \
  -- "$cli" mesh "$tmp/gcbom.geojson" -o "$tmp/gc"
# a feature without polygons: where its geometry is
expect 1 "^quadkit mesh: $tmp/gc.geojson:3:65: feature 0 has no Polygon or MultiPolygon geometry$" \
  -- "$cli" mesh "$tmp/gc.geojson" --field name=pt -o "$tmp/gc"
expect 1 "gc.geojson:3:65: feature 0 has no Polygon" -- "$cli" mesh "$tmp/gc.geojson" --feature 0 -o "$tmp/gc"
nothing_written "$tmp/gc"
# a position inside a ring whose repeated points were merged (position counts the file's)
cat >"$tmp/rep.geojson" <<'EOF2'
{"type": "Polygon", "coordinates": [
  [[0, 0], [0, 0], [0, 0], [4, 0], [4, 4], [0, 4], [0, 0]],
  [[1, 1], [1, 1], [5, 2],
   [3, 3], [1, 1]]]}
EOF2
# ([4, 0] is position 3, after two repeats of [0, 0]: it was "point 1")
expect 1 "^quadkit mesh: $tmp/rep.geojson:2:28: segments 1 and 4 cross or overlap \\(input segments feature 0, polygon 0, ring 0, position 3 and feature 0, polygon 0, ring 1, position 0, at 3:4\\)$" \
  -- "$cli" mesh "$tmp/rep.geojson" -o "$tmp/rep"
# a hole ring covered by another polygon: no hole point; the ring is named and placed
cat >"$tmp/hole.geojson" <<'EOF2'
{"type": "MultiPolygon", "coordinates": [
  [[[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]],
   [[2, 2], [2, 4], [4, 4], [4, 2], [2, 2]]],
  [[[1, 1], [5, 1], [5, 5], [1, 5], [1, 1]]]
]}
EOF2
expect 1 "^quadkit mesh: $tmp/hole.geojson:3:4: feature 0, polygon 0, ring 1: no point found strictly inside this hole ring \\(through \\(2, 2\\)\\) and outside the area \\(even-odd over every ring\\): a hole must lie inside its shell, not outside it or covered by another polygon$" \
  -- "$cli" mesh "$tmp/hole.geojson" -o "$tmp/hole"
nothing_written "$tmp/hole"
# the same hole from its corner (4, 2): the point named is x then y (the io/ mutation
# sweep: a message printing y twice passed with the corner (2, 2))
sed 's/\[\[2, 2\], \[2, 4\], \[4, 4\], \[4, 2\], \[2, 2\]\]/[[4, 2], [2, 2], [2, 4], [4, 4], [4, 2]]/' \
  "$tmp/hole.geojson" >"$tmp/hole42.geojson"
expect 1 "^quadkit mesh: $tmp/hole42.geojson:3:4: feature 0, polygon 0, ring 1: no point found strictly inside this hole ring \\(through \\(4, 2\\)\\) and outside" \
  -- "$cli" mesh "$tmp/hole42.geojson" -o "$tmp/hole42"
nothing_written "$tmp/hole42"

# ---- mesh, GeoJSON: a ring round a pole said "no point found inside the hole ring" or,
# projected, "segments ... cross" ---------------------------------------------------------
cat >"$tmp/cap.geojson" <<'EOF2'
{"type": "Feature", "properties": {"name": "cap"},
 "geometry": {"type": "Polygon", "coordinates": [
   [[-170, 80], [-50, 81], [70, 80], [-170, 80]]]}}
EOF2
pole='feature 0, polygon 0, ring 0 goes round the north pole'
expect 1 "^quadkit mesh: $tmp/cap.geojson:3:4: $pole \\(its longitudes wind once round the globe, across the antimeridian\\): --project equirect cannot map it to a closed ring; cut it along the antimeridian into rings that close in longitude, or project it with a polar projection \\(PROJ: \\+proj=stere \\+lat_0=90\\) and mesh the planar result without --project, or mesh other features with --feature N or --field NAME=VALUE$" \
  -- "$cli" mesh "$tmp/cap.geojson" --project equirect -o "$tmp/cap"
nothing_written "$tmp/cap"
# unprojected the planar triangle is meshed (it is one), and nothing is refused up front
expect 0 '"triangles": [1-9]' -- "$cli" mesh "$tmp/cap.geojson" -o "$tmp/cap" --stats
# a ring cut along the antimeridian and closed along it (180 to -180) is not one
cat >"$tmp/cut.geojson" <<'EOF2'
{"type": "Polygon", "coordinates": [
   [[-180, -80], [-90, -80], [0, -80], [90, -80], [180, -80], [180, -89], [-180, -89], [-180, -80]]]}
EOF2
expect 0 '"triangles": [1-9]' -- "$cli" mesh "$tmp/cut.geojson" -o "$tmp/cut" --stats
# ... and projected: the shift that joins parts across the antimeridian (negative
# longitudes + 360) tore it ("nothing to mesh"); the mesh must cover its rectangle exactly
expect 0 '"triangles": [1-9]' -- "$cli" mesh "$tmp/cut.geojson" --project equirect --round 2^-4 -o "$tmp/cutp" --stats
area_check() { # area_check PREFIX: the triangles' areas add up to the vertices' bounding box
  awk 'FNR == 1 { file++; next }
       file == 1 { x[$1] = $2; y[$1] = $3; if (!n++ || $2 < x0) x0 = $2; if ($2 > x1 || n == 1) x1 = $2;
                   if (n == 1 || $3 < y0) y0 = $3; if (n == 1 || $3 > y1) y1 = $3; next }
       file == 2 && NF >= 4 { a = (x[$3] - x[$2]) * (y[$4] - y[$2]) - (x[$4] - x[$2]) * (y[$3] - y[$2]);
                   t += (a < 0 ? -a : a) / 2 }
       END { box = (x1 - x0) * (y1 - y0); d = t - box; if (d < 0) d = -d;
             if (box > 0 && d <= 1e-9 * box) exit 0; print "area " t " box " box; exit 1 }' "$1.node" "$1.ele"
}
if area_check "$tmp/cutp"; then passes=$((passes + 1)); else fail "cut ring, projected: the mesh does not cover its rectangle"; fi
# (the same on Antarctica in countries-50m: review6_data.sh, which needs ../shared/data)

# ---- messages quoted input bytes raw: an escape sequence in a file cleared the screen or
# set the window title of whoever read the error; now \xNN (UTF-8 text is kept) ----------
printf 'x,y\n1,2\n3,\033]0;pwned\007\033[2Jred\n' >"$tmp/esc.csv"
expect 1 "^quadkit: $tmp/esc.csv:3:3: field 2 \\(y\\) is not a number: '\\\\x1B\\]0;pwned\\\\x07\\\\x1B\\[2Jred'$" -- "$cli" tree "$tmp/esc.csv"
printf '1,\033[2Jdisc,0,0,1\n' >"$tmp/wesc.csv"
printf '0,1,0,0,1\n' >"$tmp/wmv.csv"
expect 1 "^quadkit world: $tmp/wesc.csv:1:3: unknown kind '\\\\x1B\\[2Jdisc'" -- "$cli" world "$tmp/wesc.csv" "$tmp/wmv.csv"
printf '{"type":"Polyg\\u001b[2Jon","coordinates":[]}' >"$tmp/esc.geojson"
expect 1 'unknown GeoJSON type "Polyg\\x1B\[2Jon"' -- "$cli" regions "$tmp/esc.geojson"
printf '4 2 0 0\n0 0 0\n1 \033[2J 0\n' >"$tmp/esc.poly"
expect 1 "^quadkit mesh: $tmp/esc.poly:3: vertex 1: bad x coordinate '\\\\x1B\\[2J'$" -- "$cli" mesh "$tmp/esc.poly" -o "$tmp/esc"
printf 'x,y\n1,2\n3,\302\2331m\377\n' >"$tmp/c1.csv" # a C1 control (CSI) and a byte not UTF-8
expect 1 "is not a number: '\\\\xC2\\\\x9B1m\\\\xFF'$" -- "$cli" tree "$tmp/c1.csv"
printf 'x,y\n1,2\n3,C\303\264te\n' >"$tmp/utf8.csv"
expect 1 "is not a number: 'C$(printf '\303\264')te'$" -- "$cli" tree "$tmp/utf8.csv"
same_text "no raw escape byte in any message" \
  "$(for c in "tree $tmp/esc.csv" "world $tmp/wesc.csv $tmp/wmv.csv" "regions $tmp/esc.geojson" "tree $tmp/c1.csv"; do
    # shellcheck disable=SC2086
    "$cli" $c 2>&1 | LC_ALL=C grep -c $'[\x01-\x08\x0b-\x1f\x7f]'
  done | tr '\n' ' ')" "0 0 0 0 "

# ---- world: errors named the line only; the scene files are CSV, with columns ----------
printf '0,1,0,0,1\n' >"$tmp/mv.csv"
world_at() { # world_at NAME OBJECTS-TEXT PATTERN [MOVES-TEXT]
  printf "$2" >"$tmp/$1.csv"
  printf -- "${4:-0,1,0,0,1\\n}" >"$tmp/$1-mv.csv"
  expect 1 "^quadkit world: $tmp/$3" -- "$cli" world "$tmp/$1.csv" "$tmp/$1-mv.csv" -o "$tmp/$1.out"
  [ ! -e "$tmp/$1.out" ] || fail "world $1: output written after an error"
}
world_at wneg '1,disc,0,0,-1\n' "wneg.csv:1:12: disc radius is negative: '-1'$"
world_at wkind 'id,kind,x,y,a\n1, blob ,0,0,1\n' "wkind.csv:2:4: unknown kind 'blob'"
world_at wid '99999999999999999999,disc,0,0,1\n' "wid.csv:1:1: id is above 2\\^64 - 1"
world_at wbig '1,disc,0,1e308,1\n' "wbig.csv:1:10: value outside \\[2\\^-100, 2\\^100\\] in magnitude: '1e308'$"
world_at wquot '1,disc,0,0,"-1"\n' "wquot.csv:1:12: disc radius is negative: '-1'$"
world_at wbom '\357\273\2771,disc,0,0,-1\n' "wbom.csv:1:12: disc radius is negative"
world_at wmid '1,disc,0,0,1\n' "wmid-mv.csv:2:3: unknown id '7'$" '0,1,0,0,1\n1,7,0,0,1\n'
world_at wfr '1,disc,0,0,1\n' "wfr-mv.csv:1:1: frame is not a whole number from 0 to 1e8: '-1'$" '-1,1,0,0,1\n'
world_at wfew '1,box,0,0\n' "wfew.csv:1: too few fields for this kind of shape$"

# ---- range / collide / raycast: an inverted box, a negative radius or tmax named no value -
printf '0,0\n1,1\n' >"$tmp/qp.csv"
printf '0,0,1,1\n0,3,1,2\n' >"$tmp/ybox.csv"
expect 1 "^quadkit: $tmp/ybox.csv:2: box has xmin > xmax or ymin > ymax: ymin 3 > ymax 2 \\(fields 2 and 4\\)$" \
  -- "$cli" range "$tmp/qp.csv" "$tmp/ybox.csv"
printf '0,0,1,1\n5,0,4.5,1\n' >"$tmp/xbox.csv"
expect 1 "^quadkit: $tmp/xbox.csv:2: box has xmin > xmax or ymin > ymax: xmin 5 > xmax 4.5 \\(fields 1 and 3\\)$" \
  -- "$cli" collide "$tmp/xbox.csv" --boxes
printf 'x,y,r\n0,0,1\n0,0,-0.25\n' >"$tmp/negr.csv"
expect 1 "^quadkit: $tmp/negr.csv:3: disc radius is negative: -0.25 \\(field 3\\)$" -- "$cli" collide "$tmp/negr.csv" -o "$tmp/negr.out"
[ ! -e "$tmp/negr.out" ] || fail "collide: output written after an error"
printf '0,0,1
' >"$tmp/disc.csv"
printf '5,5,-1,-1,1
5,5,-1,-1,-0.5
' >"$tmp/rays.csv"
expect 1 "^quadkit: $tmp/rays.csv:2: tmax is negative: -0.5 \\(field 5\\)$" -- "$cli" raycast "$tmp/disc.csv" "$tmp/rays.csv"

# ---- GDAL layers: the polygons of a GeometryCollection were skipped (the GeoJSON reader
# takes them); a GeoJSON file under another name goes through GDAL ----------------------
cat >"$tmp/gcok.geojson" <<'EOF2'
{"type": "FeatureCollection", "features": [
 {"type": "Feature", "properties": {"name": "pt"}, "geometry": {"type": "Point", "coordinates": [9, 9]}},
 {"type": "Feature", "properties": {"name": "gc"}, "geometry": {"type": "GeometryCollection", "geometries": [
   {"type": "Point", "coordinates": [0, 0]},
   {"type": "GeometryCollection", "geometries": [
     {"type": "Polygon", "coordinates": [[[0, 0], [4, 0], [4, 4], [0, 4], [0, 0]]]},
     {"type": "MultiPolygon", "coordinates": [[[[10, 10], [11, 10], [11, 11], [10, 10]]]]}]}]}}]}
EOF2
cp "$tmp/gcok.geojson" "$tmp/gcok.txt"
printf 'x,y\n2,2\n10.7,10.2\n9,9\n' >"$tmp/jp.csv"
if "$cli" regions "$tmp/gcok.txt" 2>&1 | grep -q 'built without GDAL'; then
  echo "SKIPPED: built without GDAL: the GeometryCollection check through GDAL did not run"
else
  same_text "GDAL: a GeometryCollection's polygons, as the GeoJSON reader takes them" \
    "$("$cli" join "$tmp/gcok.txt" "$tmp/jp.csv" --field name 2>&1 | tr '\n' ' ')" \
    "$("$cli" join "$tmp/gcok.geojson" "$tmp/jp.csv" --field name 2>&1 | tr '\n' ' ')"
  same_text "the GeoJSON reader's answer" "$("$cli" join "$tmp/gcok.geojson" "$tmp/jp.csv" --field name | tr '\n' ' ')" \
    "x,y,feature,name 2,2,1,gc 10.7,10.2,1,gc 9,9,-1, "
  expect 0 '"features": 2, "rings": 2, "vertices": 9, "holes": 0, "self_intersecting_rings": 0, "skipped_geometries": 1,' \
    -- "$cli" regions "$tmp/gcok.txt"
fi

# ---- mesh: GeoJSON on stdin or under another name read as a .poly ("expected the number
# of vertices, found '{"type":'") --------------------------------------------------------
expect 1 "^quadkit mesh: <stdin>: this looks like JSON, but the input is read as a .poly file: GeoJSON is read from a file whose name ends in .geojson or .json \\(not from stdin\\)$" \
  -- bash -c '"$1" mesh - -o "$2" <"$3"' - "$cli" "$tmp/js" "$tmp/gcok.geojson"
expect 1 "^quadkit mesh: $tmp/gcok.txt: this looks like JSON" -- "$cli" mesh "$tmp/gcok.txt" -o "$tmp/js"
nothing_written "$tmp/js"
printf '4 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/sq.poly"
expect 0 '"triangles": [1-9]' -- bash -c '"$1" mesh - -o "$2" --stats <"$3"' - "$cli" "$tmp/sq" "$tmp/sq.poly"

# ---- --xy naming one column for x and y read every point onto the diagonal, silently ----
printf 'a,b\n1,2\n' >"$tmp/ab.csv"
for c in "tree $tmp/ab.csv --xy 2,2" "tree $tmp/ab.csv --xy b,b" "knn $tmp/ab.csv $tmp/ab.csv -k 1 --xy 1,01" \
  "join $tmp/gcok.geojson $tmp/ab.csv --xy a,a" "join $tmp/gcok.geojson $tmp/ab.csv --xy 1,1"; do
  # shellcheck disable=SC2086
  expect 2 "^quadkit ${c%% *}: --xy [0-9ab]+,[0-9ab]+: x and y name the same column$" -- "$cli" $c
done
expect 1 "^quadkit join: $tmp/ab.csv:1: --xy a,1: x and y name the same column \\(field 1\\)$" \
  -- "$cli" join "$tmp/gcok.geojson" "$tmp/ab.csv" --xy a,1 -o "$tmp/ab.out"
[ ! -e "$tmp/ab.out" ] || fail "join --xy a,1: output written after an error"
# two columns, in either order, are fine
same_text "--xy b,a" "$("$cli" join "$tmp/gcok.geojson" "$tmp/ab.csv" --xy b,a | tr '\n' ' ')" "a,b,feature 1,2,1 "

# ---- mesh of a .node file (vertices only): "truncated input: expected the segment section
# header", without a word about what a .node is ------------------------------------------
printf '4 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n' >"$tmp/v.node"
expect 1 "^quadkit mesh: $tmp/v.node:5: truncated input: expected the segment section header \\(a .node file holds vertices only: mesh reads a .poly file, which holds the segments and holes too\\)$" \
  -- "$cli" mesh "$tmp/v.node" -o "$tmp/vn"
nothing_written "$tmp/vn"
cp "$tmp/v.node" "$tmp/v.poly"
expect 1 "^quadkit mesh: $tmp/v.poly:5: truncated input: expected the segment section header$" -- "$cli" mesh "$tmp/v.poly" -o "$tmp/vn"

# ---- a write that fails only when its buffer goes out (a full disk): the outputs closed
# before it were left in place by a command that failed (mesh's PREFIX.node and .ele with
# --msh /dev/full; simulate's picture with -o /dev/full), and mesh said it twice ----------
if [ -w /dev/full ]; then
  mkdir "$tmp/full"
  for o in --msh --vtk --poly --svg; do
    expect 3 "^quadkit mesh: cannot write /dev/full: No space left on device$" \
      -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/full/m" "$o" /dev/full
    same_text "mesh $o /dev/full: one message" "$("$cli" mesh "$tmp/sq.poly" -o "$tmp/full/m" "$o" /dev/full 2>&1 | wc -l)" 1
  done
  expect 3 "^quadkit mesh: cannot write /dev/full" -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/full/m" --poly "$tmp/full/p.poly" --msh /dev/full --vtk "$tmp/full/v.vtu"
  expect 3 "^quadkit simulate: cannot write /dev/full" -- "$cli" simulate --n 5 --frames 2 -o /dev/full --svg "$tmp/full/s.svg"
  expect 3 "^quadkit simulate: cannot write standard output" -- bash -c '"$1" simulate --n 5 --frames 2 --svg "$2" >/dev/full' - "$cli" "$tmp/full/s2.svg"
  # tree and regions printed their statistics on stdout, then exited 3
  printf 'x,y\n0,0\n1,1\n' >"$tmp/two.csv"
  same_text "tree --svg /dev/full: no statistics" "$("$cli" tree "$tmp/two.csv" --svg /dev/full 2>/dev/null; echo "exit $?")" "exit 3"
  same_text "regions --svg /dev/full: no statistics" "$("$cli" regions "$tmp/gcok.geojson" --svg /dev/full 2>/dev/null; echo "exit $?")" "exit 3"
  expect 0 '^\{"points": 2, ' -- "$cli" tree "$tmp/two.csv" --svg "$tmp/t.svg"
  expect 0 '^\{"features": 2, "rings": 2,' -- "$cli" regions "$tmp/gcok.geojson" --svg "$tmp/r.svg"
  same_text "a failed write: nothing left" "$(ls -A "$tmp/full")" ""
  # all well, everything is there
  expect 0 '' -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/full/m" --poly "$tmp/full/p.poly" --msh "$tmp/full/m.msh"
  same_text "mesh: every output" "$(ls "$tmp/full" | tr '\n' ' ')" "m.ele m.msh m.node p.poly "
else
  echo "SKIPPED: no writable /dev/full: the failed-write checks did not run"
fi

# ---- GeoJSON: a property value holding \u0000 was cut short there in join's output ------
printf '{"type":"FeatureCollection","features":[\n{"type":"Feature","properties":{"a":1,\n  "name":"x\\u0000y"},"geometry":{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,0]]]}}]}\n' >"$tmp/nul.geojson"
printf 'x,y\n0.5,0.2\n' >"$tmp/nulpt.csv"
for c in join regions; do
  args=("$tmp/nul.geojson")
  [ $c = join ] && args+=("$tmp/nulpt.csv" --field name -o "$tmp/nul.out")
  expect 1 "^quadkit $c: $tmp/nul.geojson:3:10: feature 0: property \"name\" holds a NUL character \\(\\\\u0000\\), which a property value cannot keep$" \
    -- "$cli" $c "${args[@]}"
done
[ ! -e "$tmp/nul.out" ] || fail "join: output written after an error"
sed 's/x\\u0000y/x\\u0001y/' "$tmp/nul.geojson" >"$tmp/one.geojson" # other escapes are kept
expect 0 '^0.5,0.2,0,' -- "$cli" join "$tmp/one.geojson" "$tmp/nulpt.csv" --field name

# ---- a .poly coordinate beyond a double's range was only 'bad', like a typo -------------
printf '3 2 0 0\n1 1e400 0\n2 1 0\n3 0 1\n3 0\n1 1 2\n2 2 3\n3 3 1\n0\n' >"$tmp/huge.poly"
expect 1 "huge.poly:2: vertex 1: bad x coordinate '1e400' \\(beyond the range of a double\\)$" -- "$cli" mesh "$tmp/huge.poly" -o "$tmp/huge"
nothing_written "$tmp/huge"
sed 's/^2 1 0$/2 1 -1E+999/' "$tmp/huge.poly" | sed 's/1e400/0/' >"$tmp/huge2.poly"
expect 1 "vertex 2: bad y coordinate '-1E\\+999' \\(beyond the range of a double\\)$" -- "$cli" mesh "$tmp/huge2.poly" -o "$tmp/huge"
sed 's/1e400/Infinity/' "$tmp/huge.poly" >"$tmp/inf.poly"
expect 1 "bad x coordinate 'Infinity' \\(not a finite number\\)$" -- "$cli" mesh "$tmp/inf.poly" -o "$tmp/huge"
sed 's/1e400/0x1p3/' "$tmp/huge.poly" >"$tmp/hex.poly"
expect 1 "bad x coordinate '0x1p3' \\(hexadecimal numbers are not read\\)$" -- "$cli" mesh "$tmp/hex.poly" -o "$tmp/huge"

# ---- --xy naming the first column by its name and by its number (x,1) went past the
# CLI's check (it compares the names it was given) and read every point onto the diagonal
printf 'x,y\n1,2\n3,4\n' >"$tmp/xy1.csv"
expect 1 "xy1.csv:1: columns 'x' and 1 \\(1 and 2 of the selection\\) are both field 1$" -- "$cli" tree "$tmp/xy1.csv" --xy x,1
expect 0 '"points": 2' -- "$cli" tree "$tmp/xy1.csv" --xy y,1

# ---- locate --keep both was accepted and kept the query's fields only (locate has one side)
printf 'x,y\n0,0\n1,1\n' >"$tmp/kb.csv"
expect 2 "--keep takes query, not 'both'" -- "$cli" locate "$tmp/kb.csv" "$tmp/kb.csv" --keep both
expect 0 '^query,rank,point,distance,query_x,query_y,point_x,point_y$' -- "$cli" knn "$tmp/kb.csv" "$tmp/kb.csv" -k 1 --keep both

report
