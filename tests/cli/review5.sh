#!/usr/bin/env bash
# CLI regressions from a fifth review, on hostile inputs not tried before (one block per
# finding; each failed before its fix): .poly files cut short or whose rows do not match
# their counts, mesh --stats fields in the general mode, GeoJSON errors without a line.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- .poly: a file that ends right after the segments was meshed with its holes solid -----
# An 8x8 square with a 4x4 hole; cut after the segments it gave 128 triangles (the hole
# filled). Triangle's reader refuses a file that ends before the hole section; so do we.
sq8='8 2 0 0\n0 0 0\n1 8 0\n2 8 8\n3 0 8\n4 2 2\n5 6 2\n6 6 6\n7 2 6\n'
seg8='8 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n4 4 5\n5 5 6\n6 6 7\n7 7 4\n'
printf "$sq8$seg8"'1\n0 4 4\n' >"$tmp/full.poly"
expect 0 '"triangles": 96,' -- "$cli" mesh "$tmp/full.poly" -o "$tmp/full" --stats
printf "$sq8$seg8" >"$tmp/nohole.poly"
expect 1 "^quadkit mesh: $tmp/nohole.poly:18: truncated input: the file ends here, where the hole section was expected \\(a line with the number of holes, 0 for none\\)$" \
  -- "$cli" mesh "$tmp/nohole.poly" -o "$tmp/nohole"
nothing_written "$tmp/nohole"
# the line named is the file's last, comments and blank lines included; from stdin too
printf "$sq8$seg8"'# no holes here\n\n' >"$tmp/nohole2.poly"
expect 1 'nohole2.poly:20: truncated input: the file ends here, where the hole section' \
  -- "$cli" mesh "$tmp/nohole2.poly" -o "$tmp/nohole2"
expect 1 "^quadkit mesh: <stdin>:18: truncated input: the file ends here" \
  -- bash -c '"$1" mesh - -o "$2" <"$3"' - "$cli" "$tmp/nh3" "$tmp/nohole.poly"
nothing_written "$tmp/nh3"
# "0" holes, and the optional regional attributes absent or present, are accepted
printf "$sq8$seg8"'0\n' >"$tmp/zero.poly"
expect 0 '"triangles": 128,' -- "$cli" mesh "$tmp/zero.poly" -o "$tmp/zero" --stats
printf "$sq8$seg8"'1\n0 4 4\n1\n0 1 1 7\n' >"$tmp/reg.poly"
expect 0 '"triangles": 96,' -- "$cli" mesh "$tmp/reg.poly" -o "$tmp/reg" --stats
# the repository's own example that lacked the line still meshes (it gained a "0")
expect 0 '"triangles": [1-9]' -- "$cli" mesh "$src/examples/mesh/notes.poly" -o "$tmp/notes" --stats

# ---- .poly: every truncation point, and rows that do not match their counts ---------------
V='4 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n'
S='4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n'
poly_case() { # poly_case NAME TEXT PATTERN: refused with exit 1, PATTERN, nothing written
  printf "$2" >"$tmp/$1.poly"
  expect 1 "^quadkit mesh: $tmp/$1.poly:$3" -- "$cli" mesh "$tmp/$1.poly" -o "$tmp/$1"
  nothing_written "$tmp/$1"
}
poly_case vhdr '4 2 0 0\n' '1: truncated input: expected 4 vertices, found 0$'
poly_case vpart '4 2 0 0\n0 0 0\n1 4 0\n' '3: truncated input: expected 4 vertices, found 2$'
poly_case vonly "$V" '5: truncated input: expected the segment section header$'
poly_case shdr "$V"'4 0\n' '6: truncated input: expected 4 segments, found 0$'
poly_case spart "$V"'4 0\n0 0 1\n1 1 2\n' '8: truncated input: expected 4 segments, found 2$'
poly_case nohole "$V$S" '10: truncated input: the file ends here, where the hole section was expected'
poly_case hpart "$V$S"'2\n0 1 1\n' '12: truncated input: expected 2 holes, found 1$'
poly_case rpart "$V$S"'0\n2\n0 1 1 5\n' '13: truncated input: expected 2 regional attributes, found 1$'
# too few rows: the next section's header is read as a row, and the message says so
poly_case vfew '5 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n'"$S"'0\n' \
  '6: vertex 4: expected x and y, found 2 fields \(fewer vertex rows than the 5 that line 1 declares\?\)$'
poly_case sfew "$V"'5 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' \
  '11: segment 0: expected two endpoints, found 1 field \(fewer segment rows than the 5 that line 6 declares\?\)$'
poly_case hfew "$V$S"'2\n0 1 1\n0\n' \
  '13: hole 0: expected x and y only, found 1 field \(fewer hole rows than the 2 that line 11 declares\?\)$'
poly_case rfew "$V$S"'0\n2\n0 1 1 5\n1\n' \
  '14: region 1: expected 4 or 5 fields, found 1 \(fewer region rows than the 2 that line 12 declares\?\)$'
# a decimal comma in a row of blank-separated fields: "3 0,5 4" with a marker declared was
# read as x = 0, y = 5, marker 4 and meshed (exit 0); rows separated by commas throughout
# still read (guard)
poly_case dcomma '4 2 0 1\n0 0 0 1\n1 4 0 1\n2 4 4 1\n3 0,5 4\n'"$S"'0\n' \
  "5: '0,5': a decimal comma\\? Numbers take a decimal point; fields are separated by blanks or commas$"
printf '4 2 0 0\n0,0,0\n1, 4, 0\n2,4,4\n3 , 0 , 4\n4,0\n0,0,1\n1,1,2\n2,2,3\n3,3,0\n0\n' >"$tmp/commas.poly"
expect 0 '"triangles": 32' -- "$cli" mesh "$tmp/commas.poly" -o "$tmp/commas" --stats
# a boundary marker beyond 32 bits is out of range (it was "not an integer"), for vertices
# and segments alike (a segment's said "bad marker")
poly_case mbig '4 2 0 1\n0 0 0 2147483648\n1 4 0 1\n2 4 4 1\n3 0 4 1\n'"$S"'0\n' \
  "2: vertex 0: boundary marker '2147483648' is out of range \\(boundary markers are 32-bit integers, -2147483648 to 2147483647\\)$"
poly_case sbad "$V"'4 1\n0 0 1 1\n1 1 2 1.5\n2 2 3 1\n3 3 0 1\n0\n' \
  "8: segment 1: boundary marker '1.5' is not an integer$"
# (numbered as the file numbers its rows: a file from 1 said "region 1" for its second row)
poly_case rfew1 '4 2 0 0\n1 0 0\n2 4 0\n3 4 4\n4 0 4\n4 0\n1 1 2\n2 2 3\n3 3 4\n4 4 1\n0\n2\n1 1 1 5\n2\n' \
  '14: region 2: expected 4 or 5 fields, found 1 \(fewer region rows than the 2 that line 12 declares\?\)$'
# extra rows: the row after the counted ones is read as the next header
poly_case vextra '3 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n'"$S"'0\n' \
  '5: segment section header has 3 fields, expected 2 \(more vertex rows than the 3 that line 1 declares\?\)$'
poly_case sextra "$V"'3 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' \
  '10: hole section header has 3 fields, expected 1 \(more segment rows than the 3 that line 6 declares\?\)$'
poly_case hextra "$V$S"'0\n0 1 1\n' \
  '12: region section header has 3 fields, expected 1 \(more hole rows than the 0 that line 11 declares\?\)$'
poly_case rextra "$V$S"'0\n1\n0 1 1 5\n1 2 2 5\n' \
  "14: unexpected content after the last section: '1' \\(more region rows than the 1 that line 12 declares\\?\\)$"

# ---- mesh --stats: the general mode printed the lattice modes' "U": 1 --------------------
# (and "uniform_triangles": 2 and a balance time of 0, which mean nothing there)
printf '3 2 0 0\n0 0 0\n1 3 0\n2 0 1\n3 0\n0 0 1\n1 1 2\n2 2 0\n0\n' >"$tmp/tri.poly"
gen=$("$cli" mesh "$tmp/tri.poly" -o "$tmp/tri" --stats)
same_text "general mode: mode" "$(grep -o '"mode": "[a-z]*"' <<<"$gen")" '"mode": "general"'
same_text "general mode: no lattice fields" "$(grep -oE '"(U|uniform_triangles|balance)":' <<<"$gen")" ""
same_text "general mode: its own fields" \
  "$(grep -oE '"(components|triangles|exempt_angles|smallest_input_angle_deg|lattice_exponent|triangulate)":' <<<"$gen" | tr '\n' ' ')" \
  '"components": "triangles": "triangulate": "lattice_exponent": "exempt_angles": "smallest_input_angle_deg": '
book=$("$cli" mesh "$tmp/zero.poly" -o "$tmp/zero" --stats)
same_text "book mode: the lattice fields" "$(grep -oE '"(U|uniform_triangles|balance|exempt_angles)": [0-9]+' <<<"$book" | cut -d: -f1 | tr '\n' ' ')" \
  '"U" "uniform_triangles" "balance" '
same_text "book mode: U and the uniform grid" "$(grep -oE '"(U|uniform_triangles)": [0-9]+' <<<"$book" | tr '\n' ' ')" \
  '"U": 8 "uniform_triangles": 128 '
# both are JSON
if command -v python3 >/dev/null; then
  for j in "$gen" "$book"; do
    if python3 -c 'import json, sys; json.loads(sys.argv[1])' "$j"; then passes=$((passes + 1)); else fail "not JSON: $j"; fi
  done
fi

# ---- GeoJSON: errors inside valid JSON had no line (only "FILE: feature 1: ...") --------
cat >"$tmp/short.geojson" <<'EOF2'
{"type": "FeatureCollection",
 "features": [
  {"type": "Feature", "properties": {"name": "ok"},
   "geometry": {"type": "Polygon", "coordinates": [[[0,0],[1,0],[1,1],[0,1],[0,0]]]}},
  {"type": "Feature", "properties": {"name": "bad"},
   "geometry": {"type": "Polygon",
     "coordinates": [
       [[0,0],[1,0],[0,0]]
     ]}}
 ]}
EOF2
printf 'x,y\n0.5,0.5\n' >"$tmp/half.csv"
echo keep >"$tmp/keep.csv"
for c in "join $tmp/short.geojson $tmp/half.csv -o $tmp/keep.csv" "regions $tmp/short.geojson" \
  "mesh $tmp/short.geojson -o $tmp/gm"; do
  # shellcheck disable=SC2086
  expect 1 "^quadkit ${c%% *}: $tmp/short.geojson:8:8: feature 1, polygon 0, ring 0: 3 positions \\(a ring needs at least 4\\)$" -- "$cli" $c
done
same_text "join: -o unchanged after a GeoJSON error" "$(cat "$tmp/keep.csv")" keep
nothing_written "$tmp/gm"
sed 's/\[\[0,0\],\[1,0\],\[0,0\]\]/[[0,0],[1,0],[1, 1e999],[0,0]]/' "$tmp/short.geojson" >"$tmp/huge.geojson"
expect 1 'huge.geojson:8:25: feature 1: coordinate 1e999 is beyond the largest double' -- "$cli" regions "$tmp/huge.geojson"
sed 's/\[\[0,0\],\[1,0\],\[0,0\]\]/[[0,0],[1,0],[1,"1"],[0,0]]/' "$tmp/short.geojson" >"$tmp/str.geojson"
expect 1 'str.geojson:8:21: feature 1, polygon 0, ring 0, position 2: expected \[x, y\] numbers, found \[ 1, "1" \]' \
  -- "$cli" regions "$tmp/str.geojson"
sed 's/"type": "Polygon",$/"type": "polygon",/' "$tmp/short.geojson" >"$tmp/lower.geojson"
expect 1 'lower.geojson:6:16: feature 1: unknown geometry type "polygon"' -- "$cli" regions "$tmp/lower.geojson"
# lon/lat out of range (join without --planar): the position, with CRLF line ends
sed 's/\[\[0,0\],\[1,0\],\[0,0\]\]/[[0,0],[181,0],[1,1],[0,0]]/' "$tmp/short.geojson" | sed 's/$/\r/' >"$tmp/lon.geojson"
expect 1 'lon.geojson:8:15: feature 1: \(181, 0\) is not a longitude/latitude' -- "$cli" join "$tmp/lon.geojson" "$tmp/half.csv"

# ---- world: one object moved twice in one frame (only the last counted, the other lost) --
printf '1,disc,0,0,1\n2,disc,5,0,1\n' >"$tmp/wobj.csv"
printf 'frame,id,x,y,a\n0,2,1,0,1\n0,1,9,9,1\n0,2,9,9,1\n' >"$tmp/wtwice.csv"
expect 1 '^quadkit world: .*wtwice.csv:4: id 2 moves twice in frame 0 \(also on line 2\): one shape per object and frame$' \
  -- "$cli" world "$tmp/wobj.csv" "$tmp/wtwice.csv"
# the same id in successive frames, and two ids in one frame, are fine
printf '0,2,1,0,1\n0,1,9,9,1\n1,2,9,9,1\n1,1,9,9,1\n' >"$tmp/wok.csv"
same_text "world: moves in successive frames" "$("$cli" world "$tmp/wobj.csv" "$tmp/wok.csv" | tr '\n' ' ')" \
  "frame,a,b 1,1,2 "

# ---- join: a layer without a single polygon answered -1 for every point, without a word --
# (a points CSV given as REGIONS, which GDAL reads as a table; a layer of points or lines)
printf 'x,y\n0.5,0.5\n' >"$tmp/pts.csv"
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},"geometry":{"type":"Point","coordinates":[0,0]}}]}\n' >"$tmp/onlypt.geojson"
expect 1 '^quadkit join: .*onlypt.geojson: no polygons to join against \(1 features, 1 skipped geometries: points, lines, empty or null\)$' \
  -- "$cli" join "$tmp/onlypt.geojson" "$tmp/pts.csv" -o "$tmp/keep.csv"
same_text "join: -o unchanged" "$(cat "$tmp/keep.csv")" keep
printf '{"type":"FeatureCollection","features":[]}\n' >"$tmp/nofeat.geojson"
expect 1 'nofeat.geojson: no polygons to join against \(0 features' -- "$cli" join "$tmp/nofeat.geojson" "$tmp/pts.csv"
if "$cli" regions "$tmp/pts.csv" >/dev/null 2>&1; then # GDAL is there: it reads the CSV as a table
  expect 1 'pts.csv: no polygons to join against \(1 features, 1 skipped' -- "$cli" join "$tmp/pts.csv" "$tmp/pts.csv"
fi
# regions still describes such a layer (its statistics are the answer)
expect 0 '"features": 1, "rings": 0' -- "$cli" regions "$tmp/onlypt.geojson"

# ---- an output naming an input replaced the input after reading it ---------------------
printf 'x,y\n0.1,0.2\n0.3,0.4\n' >"$tmp/in.csv"
printf 'x,y,r\n0.1,0.2,0.1\n0.3,0.4,0.2\n' >"$tmp/discs.csv"
cp "$tmp/in.csv" "$tmp/in.orig"
cp "$tmp/discs.csv" "$tmp/discs.orig"
sed 's/\[\[0,0\],\[1,0\],\[0,0\]\]/[[0,0],[1,0],[1,1],[0,0]]/' "$tmp/short.geojson" >"$tmp/layer.geojson"
cp "$tmp/layer.geojson" "$tmp/layer.orig"
cp "$tmp/zero.poly" "$tmp/in.poly"
ln -s in.csv "$tmp/link.csv"
same_input() { # same_input CMD...: exit 2 naming the input, nothing replaced, no temporary
  expect 2 "cannot write .*: it is the input file .*, which it would replace" -- "$cli" "$@"
}
same_input tree "$tmp/in.csv" --svg "$tmp/in.csv"
same_input tree "$tmp/in.csv" --svg "$tmp/link.csv"
same_input knn "$tmp/in.csv" "$tmp/pts.csv" -k 1 -o "$tmp/in.csv"
same_input knn "$tmp/pts.csv" "$tmp/in.csv" -k 1 -o "$tmp/in.csv"
same_input collide "$tmp/discs.csv" -o "$tmp/discs.csv"
same_input join "$tmp/layer.geojson" "$tmp/in.csv" -o "$tmp/in.csv"
same_input join "$tmp/layer.geojson" "$tmp/in.csv" -o "$tmp/layer.geojson"
same_input regions "$tmp/layer.geojson" --svg "$tmp/layer.geojson"
same_input mesh "$tmp/in.poly" -o "$tmp/im" --poly "$tmp/in.poly"
same_input mesh "$tmp/layer.geojson" -o "$tmp/im" --svg "$tmp/layer.geojson"
same_input world "$tmp/wobj.csv" "$tmp/wok.csv" -o "$tmp/wok.csv"
cmp -s "$tmp/in.csv" "$tmp/in.orig" && cmp -s "$tmp/discs.csv" "$tmp/discs.orig" &&
  cmp -s "$tmp/layer.geojson" "$tmp/layer.orig" && cmp -s "$tmp/in.poly" "$tmp/zero.poly" &&
  [ -L "$tmp/link.csv" ] && ! ls "$tmp" | grep -q '\.tmp\.' && [ ! -e "$tmp/im.node" ] ||
  fail "an input was replaced, or a temporary or output left"
# another file, and a device, are still fine
expect 0 '' -- "$cli" knn "$tmp/in.csv" "$tmp/pts.csv" -k 1 -o "$tmp/knn.csv"
expect 0 '' -- "$cli" tree "$tmp/in.csv" --svg /dev/null

# ---- an empty output name: it wrote ".tmp.PID.0", failed renaming it to "" and exited 3 ---
mkdir "$tmp/empty"
for c in "knn $tmp/in.csv $tmp/pts.csv -k 1 -o" "tree $tmp/in.csv --svg" "regions $tmp/layer.geojson --svg" \
  "world $tmp/wobj.csv $tmp/wok.csv -o" "simulate --n 5 --frames 1 --svg" "mesh $tmp/in.poly -o $tmp/em --vtk"; do
  # shellcheck disable=SC2086
  expect 2 "^quadkit ${c%% *}: an output file name is empty \\(''\\)$" -- bash -c 'cd "$1" && shift && "$@" ""' - "$tmp/empty" "$cli" $c
done
same_text "empty output name: nothing written" "$(ls -A "$tmp/empty")" ""

# ---- world: two moves 10^8 frames apart ran for minutes (an update per empty frame) ------
printf '1,disc,0,0,1\n2,disc,5,0,1\n' >"$tmp/far.csv"
printf '0,1,0,0,1\n100000000,1,5,0,1\n' >"$tmp/farmv.csv"
same_text "world: frames 10^8 apart" "$(timeout 60 "$cli" world "$tmp/far.csv" "$tmp/farmv.csv" --pairs began | tr '\n' ' ')" \
  "frame,a,b 100000000,1,2 "
# Frames without moves answer as an update would: the same scene padded with moves that
# leave object 9 where it is (which forces the update) gives the same output.
printf '1,disc,0,0,1\n2,disc,1.5,0,1\n3,box,3,3,4,4\n9,point,50,50\n' >"$tmp/sc.csv"
printf '0,2,9,9,1\n2,2,1,0,1\n2,3,0,0,1,1\n5,1,20,20,1\n8,1,0,0,1\n' >"$tmp/scmv.csv"
printf '0,2,9,9,1\n1,9,50,50\n2,2,1,0,1\n2,3,0,0,1,1\n3,9,50,50\n4,9,50,50\n5,1,20,20,1\n6,9,50,50\n7,9,50,50\n8,1,0,0,1\n' >"$tmp/scpad.csv"
for w in all began ended; do
  same_text "world --pairs $w: empty frames" "$("$cli" world "$tmp/sc.csv" "$tmp/scmv.csv" --pairs $w | md5sum)" \
    "$("$cli" world "$tmp/sc.csv" "$tmp/scpad.csv" --pairs $w | md5sum)"
done
same_text "world: the padded scene's pairs" "$("$cli" world "$tmp/sc.csv" "$tmp/scmv.csv" | tr '\n' ' ')" \
  "frame,a,b 2,1,2 2,1,3 2,2,3 3,1,2 3,1,3 3,2,3 4,1,2 4,1,3 4,2,3 5,2,3 6,2,3 7,2,3 8,1,2 8,1,3 8,2,3 "

# ---- GDAL layers: a missing or unknown file said only "GDAL cannot open X as vector data" --
if "$cli" regions "$tmp/no-such.shp" 2>&1 | grep -q 'GDAL cannot open'; then # built with GDAL
  expect 1 "^quadkit regions: $tmp/no-such.shp: GDAL cannot open $tmp/no-such.shp as vector data: .*No such file or directory$" \
    -- "$cli" regions "$tmp/no-such.shp"
  printf 'garbage\n' >"$tmp/junk.shp"
  expect 1 "junk.shp as vector data: .*junk.shp' not recognized as a supported file format" -- "$cli" join "$tmp/junk.shp" "$tmp/pts.csv"
  # GDAL is loaded by the first read of such a layer (region/ogr.c), not when a program
  # starts: a library that cannot be loaded, or is not GDAL, is named (exit 3: the machine's
  # set-up, not the input), and neither the CLI nor the shared library needs libgdal.
  expect 3 "^quadkit regions: $tmp/junk.shp: GDAL could not be loaded to read $tmp/junk.shp \(/nonexistent/libgdal.so.0: .*No such file or directory\); install GDAL's library or name it in QK_GDAL_LIBRARY$" \
    -- env QK_GDAL_LIBRARY=/nonexistent/libgdal.so.0 "$cli" regions "$tmp/junk.shp"
  expect 3 "GDAL could not be loaded to read .*\(libm.so.6 has no GDALAllRegister\)" \
    -- env QK_GDAL_LIBRARY=libm.so.6 "$cli" join "$tmp/junk.shp" "$tmp/pts.csv"
  if command -v readelf >/dev/null; then
    for f in "$cli" "$(dirname "$cli")/libquadkit.so"; do
      if [ -e "$f" ] && readelf -d "$f" | grep -q 'NEEDED.*libgdal'; then
        fail "$f needs libgdal at start-up: $(readelf -d "$f" | grep 'NEEDED.*libgdal')"
      else
        passes=$((passes + 1))
      fi
    done
  fi
fi

# ---- two outputs of one command naming one file: the one renamed first was lost ---------
mkdir "$tmp/two"
expect 2 "^quadkit simulate: cannot write $tmp/two/s.out: another output of this command writes that file too$" \
  -- "$cli" simulate --n 5 --frames 2 -o "$tmp/two/s.out" --svg "$tmp/two/s.out"
expect 2 "cannot write $tmp/two/../two/s.out: another output" \
  -- "$cli" simulate --n 5 --frames 2 -o "$tmp/two/s.out" --svg "$tmp/two/../two/s.out"
expect 2 "cannot write ./m.node: another output" -- bash -c 'cd "$1" && "$2" mesh "$3" -o m --svg ./m.node' - "$tmp/two" "$cli" "$tmp/in.poly"
same_text "two outputs, one file: nothing written" "$(ls -A "$tmp/two")" ""
expect 0 '"frames": 2' -- "$cli" simulate --n 5 --frames 2 --svg "$tmp/two/s.svg"

report
