#!/usr/bin/env bash
# CLI regressions from a ninth review (twenty-second session), on inputs not tried before
# (one block per finding; each failed before its fix).
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- GDAL layers: areal geometries other than (Multi)Polygon were dropped silently ------
# A MultiSurface (what GML and NAS files, such as INSPIRE cadastral parcels, hold), a
# CurvePolygon or CompoundCurve with straight edges only, a TIN, a PolyhedralSurface and a
# Triangle are all areas made of straight edges; the reader left them empty (counted as
# skipped), so join answered -1 for every point in them with exit status 0. They are read
# exactly now, and a geometry with a true arc (which no finite set of edges is) is refused,
# naming the feature, instead of being dropped. GDAL's CSV driver reads the WKT column.
cat >"$tmp/w.csv" <<'EOF2'
WKT,name
"POLYGON ((0 0,1 0,1 1,0 1,0 0))",poly
"CURVEPOLYGON ((2 0,3 0,3 1,2 1,2 0),COMPOUNDCURVE ((2.25 0.25,2.25 0.75),(2.25 0.75,2.75 0.75,2.75 0.25,2.25 0.25)))",curvepoly
"MULTISURFACE (((4 0,5 0,5 1,4 1,4 0)),CURVEPOLYGON ((4 2,5 2,5 3,4 2)))",msurf
"TIN Z (((6 0 1,7 0 1,7 1 1,6 0 1)),((6 0 1,7 1 1,6 1 1,6 0 1)))",tin
"POLYHEDRALSURFACE (((8 0,9 0,9 1,8 1,8 0)))",phs
"TRIANGLE ((10 0,11 0,11 1,10 0))",tri
"GEOMETRYCOLLECTION (POINT (0 9),MULTISURFACE (((12 0,13 0,13 1,12 1,12 0))))",gc
"LINESTRING (14 0,15 1)",line
EOF2
printf 'x,y\n0.5,0.5\n2.9,0.1\n2.5,0.5\n4.5,0.5\n4.75,2.5\n4.25,2.5\n6.9,0.1\n6.1,0.9\n8.5,0.5\n10.9,0.1\n10.1,0.9\n12.5,0.5\n14.5,0.5\n' >"$tmp/wp.csv"
if "$cli" regions "$tmp/w.csv" --planar 2>&1 | grep -q 'built without GDAL'; then
  echo "SKIPPED: built without GDAL: the areal geometry types through GDAL did not run"
else
  same_text "GDAL: every areal type of straight edges is read" \
    "$("$cli" join "$tmp/w.csv" "$tmp/wp.csv" --planar --field name 2>&1 | tr '\n' ' ')" \
    "x,y,feature,name 0.5,0.5,0,poly 2.9,0.1,1,curvepoly 2.5,0.5,-1, 4.5,0.5,2,msurf 4.75,2.5,2,msurf 4.25,2.5,-1, 6.9,0.1,3,tin 6.1,0.9,3,tin 8.5,0.5,4,phs 10.9,0.1,5,tri 10.1,0.9,-1, 12.5,0.5,6,gc 14.5,0.5,-1, "
  expect 0 '"features": 8, "rings": 10, "vertices": 46, "holes": 1, "self_intersecting_rings": 0, "skipped_geometries": 1,' \
    -- "$cli" regions "$tmp/w.csv" --planar
  # a true arc: refused, naming the feature and the layer, exit 1, nothing written
  printf 'WKT,name\n"POLYGON ((0 0,1 0,1 1,0 0))",a\n"CURVEPOLYGON (CIRCULARSTRING (0 0,1 1,2 0,1 -1,0 0))",b\n' >"$tmp/arc.csv"
  expect 1 "^quadkit join: $tmp/arc.csv: feature 1: a curved geometry \\(an arc of a CircularString\\) cannot be read exactly; convert it to straight edges first \\(ogr2ogr -nlt CONVERT_TO_LINEAR\\)$" \
    -- "$cli" join "$tmp/arc.csv" "$tmp/wp.csv" --planar -o "$tmp/arc-out.csv"
  [ -e "$tmp/arc-out.csv" ] && fail "join wrote $tmp/arc-out.csv after an error" || passes=$((passes + 1))
  printf 'WKT,n\n"MULTISURFACE (((0 0,1 0,1 1,0 0)),CURVEPOLYGON (COMPOUNDCURVE ((0 5,1 5),CIRCULARSTRING (1 5,2 6,3 5),(3 5,0 5))))",x\n' >"$tmp/arc2.csv"
  expect 1 "^quadkit regions: $tmp/arc2.csv: feature 0: a curved geometry \\(an arc of a CircularString\\) cannot be read exactly" \
    -- "$cli" regions "$tmp/arc2.csv" --planar
fi

# ---- a layer from a pipe: process substitution, /dev/stdin and FIFOs went to GDAL --------
# qk_region_read chose the reader by name alone, so `join <(curl ...) pts.csv` sent
# /dev/fd/63 to GDAL, which seeks and cannot read a pipe ("Failed to read GeoJSON data",
# exit 1). A layer that is not a regular file is now read as GeoJSON, the one format that
# streams; the GeoJSON reader reads it to the end.
printf '{"type": "Polygon", "coordinates": [[[0, 0], [2, 0], [2, 2], [0, 2], [0, 0]]]}' >"$tmp/sq.json"
printf 'x,y\n1,1\n3,3\n' >"$tmp/sqp.csv"
same_text "join, a layer through process substitution" \
  "$("$cli" join <(cat "$tmp/sq.json") "$tmp/sqp.csv" --planar 2>&1 | tr '\n' ' ')" "x,y,feature 1,1,0 3,3,-1 "
same_text "join, a layer on /dev/stdin" \
  "$("$cli" join /dev/stdin "$tmp/sqp.csv" --planar <"$tmp/sq.json" 2>&1 | tr '\n' ' ')" "x,y,feature 1,1,0 3,3,-1 "
mkfifo "$tmp/fifo"
(cat "$tmp/sq.json" >"$tmp/fifo" &)
expect 0 '"features": 1, "rings": 1, "vertices": 5,' -- "$cli" regions "$tmp/fifo" --planar
# a pipe that is not GeoJSON: the GeoJSON reader's error, with its line and column
expect 1 "^quadkit join: /dev/fd/[0-9]+:1:1: malformed JSON" -- bash -c '"$1" join <(printf "WKT\n") "$2"' - "$cli" "$tmp/sqp.csv"

# devices are not pipes: /dev/zero goes to GDAL, refused at once; an endless binary
# pipe, or a .geojson name for /dev/zero, stops at its first NUL byte instead of filling
# memory
expect 1 "^quadkit join: /dev/zero: GDAL cannot open /dev/zero" -- timeout 60 "$cli" join /dev/zero "$tmp/sqp.csv"
expect 1 "^quadkit join: /dev/fd/[0-9]+:1:1: binary data \\(NUL byte\\) in a text file$" -- timeout 60 bash -c '"$1" join <(cat /dev/zero) "$2"' - "$cli" "$tmp/sqp.csv"
ln -s /dev/zero "$tmp/zero.geojson"
expect 1 "^quadkit join: $tmp/zero.geojson:1:1: binary data \\(NUL byte\\) in a text file$" -- timeout 60 "$cli" join "$tmp/zero.geojson" "$tmp/sqp.csv"
# the mesher's own read of GeoJSON too (it said "out of memory reading it" once memory ran out)
expect 1 "^quadkit mesh: $tmp/zero.geojson:1:1: binary data \\(NUL byte\\) in a text file$" -- timeout 60 "$cli" mesh "$tmp/zero.geojson" -o "$tmp/zm"
nothing_written "$tmp/zm"

# ---- a line too long for memory was taken for the end of the input ---------------------
# getline's -1 on ENOMEM ended the loops of join's and world's readers as if the file had
# ended: `join layer points` with a binary points file without line breaks (/dev/zero)
# wrote nothing, not even the header, and exited 0; world said "no objects". (The tool's
# line reader now stops at the first NUL byte, and at a line past 1 MiB, before memory
# runs out: tests/cli/review10.sh; these checked "out of memory reading the line", exit 3.)
expect 1 "^quadkit join: /dev/zero:1:1: binary data \\(NUL byte\\) in a text file$" \
  -- timeout 60 "$cli" join "$tmp/sq.json" /dev/zero --planar
printf '1,disc,0,0,1\n' >"$tmp/obj.csv"
expect 1 "^quadkit world: /dev/zero:1:1: binary data \\(NUL byte\\) in a text file$" \
  -- timeout 60 "$cli" world /dev/zero "$tmp/obj.csv"
expect 1 "^quadkit world: /dev/zero:1:1: binary data \\(NUL byte\\) in a text file$" \
  -- timeout 60 "$cli" world "$tmp/obj.csv" /dev/zero

# ---- mesh, GeoJSON: a hole outside its shell was said to have no point "outside every
# other ring", which every point inside it is (under even-odd it is area, not a hole) --------
printf '{"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]],\n [[2, 2], [3, 2], [3, 3], [2, 2]]]}\n' >"$tmp/holeout.geojson"
expect 1 "^quadkit mesh: $tmp/holeout.geojson:2:2: feature 0, polygon 0, ring 1: no point found strictly inside this hole ring \\(through \\(2, 2\\)\\) and outside the area \\(even-odd over every ring\\): a hole must lie inside its shell, not outside it or covered by another polygon$" \
  -- "$cli" mesh "$tmp/holeout.geojson" -o "$tmp/holeout"
nothing_written "$tmp/holeout"

report
