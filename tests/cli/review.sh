#!/usr/bin/env bash
# CLI regressions from a hostile-input review (one block per bug found): GeoJSON feature
# collections with features that have no polygon (mesh refused them with an internal
# error), GeometryCollections (their polygons were dropped silently), a byte order mark
# for mesh (its second read failed), NUL bytes and trailing commas in JSON (accepted), and
# a directory given as input. Every error must exit 1 and write nothing.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

nothing() { # nothing PREFIX: no file PREFIX.* was written
  if compgen -G "$1.*" >/dev/null; then
    fail "files written after an error: $(echo "$1".*)"
  else
    passes=$((passes + 1))
  fi
}

sq() { printf '[[[%s,%s],[%s,%s],[%s,%s],[%s,%s],[%s,%s]]]' "$1" "$2" "$3" "$2" "$3" "$4" "$1" "$4" "$1" "$2"; }

# ---- GeoJSON: features without area keep their numbers; mesh takes the others --------
printf '{"type":"FeatureCollection","features":[
{"type":"Feature","properties":{"name":"A"},"geometry":{"type":"MultiPolygon","coordinates":[[[[0,0],[10,0],[10,10],[0,10],[0,0]],[[2,2],[8,2],[8,8],[2,8],[2,2]]],[%s]]}},
{"type":"Feature","properties":null,"geometry":{"type":"Polygon","coordinates":%s}},
{"type":"Feature","properties":{"name":null},"geometry":null},
{"type":"Feature","properties":{},"geometry":{"type":"Polygon","coordinates":[]}},
{"type":"Feature","properties":{"name":"P"},"geometry":{"type":"Point","coordinates":[50,50]}}]}\n' \
  "$(sq 20 0 30 10 | cut -c2- | rev | cut -c2- | rev)" "$(sq 4 4 6 6)" >"$tmp/fc.geojson"
printf 'x,y\n1,1\n5,5\n3,3\n25,5\n50,50\n' >"$tmp/p.csv"
same_text "join: mixed features" "$("$cli" join "$tmp/fc.geojson" "$tmp/p.csv" --planar --field name | tr '\n' ' ')" \
  "x,y,feature,name 1,1,0,A 5,5,1, 3,3,-1, 25,5,0,A 50,50,-1, "
expect 0 '"components": 3, .*"features": 2, ' -- "$cli" mesh "$tmp/fc.geojson" -o "$tmp/fc" --stats
expect 0 '"components": 1, .*"features": 1, ' -- "$cli" mesh "$tmp/fc.geojson" -o "$tmp/f1" --feature 1 --stats
expect 1 'feature 2 has no Polygon or MultiPolygon geometry' -- "$cli" mesh "$tmp/fc.geojson" -o "$tmp/f2" --feature 2
nothing "$tmp/f2"
expect 1 'feature 5 does not exist \(5 features\)' -- "$cli" mesh "$tmp/fc.geojson" -o "$tmp/f5" --feature 5
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},"geometry":{"type":"Point","coordinates":[1,1]}}]}\n' >"$tmp/points.geojson"
expect 1 'no Polygon or MultiPolygon features' -- "$cli" mesh "$tmp/points.geojson" -o "$tmp/pt"
nothing "$tmp/pt"

# ---- GeometryCollection: its polygons are the feature's, nested ones too --------------
printf '{"type":"Feature","properties":{"name":"gc"},"geometry":{"type":"GeometryCollection","geometries":[{"type":"Point","coordinates":[5,5]},{"type":"Polygon","coordinates":%s},{"type":"GeometryCollection","geometries":[{"type":"MultiPolygon","coordinates":[%s]}]}]}}\n' \
  "$(sq 0 0 1 1)" "$(sq 2 0 3 1)" >"$tmp/gc.geojson"
printf 'x,y\n0.5,0.5\n2.5,0.5\n1.5,0.5\n' >"$tmp/g.csv"
same_text "join: GeometryCollection" "$("$cli" join "$tmp/gc.geojson" "$tmp/g.csv" --planar --field name | tr '\n' ' ')" \
  "x,y,feature,name 0.5,0.5,0,gc 2.5,0.5,0,gc 1.5,0.5,-1, "
expect 0 '"components": 2, .*"triangles": [1-9]' -- "$cli" mesh "$tmp/gc.geojson" -o "$tmp/gc" --stats
printf '{"type":"GeometryCollection","geometries":{}}\n' >"$tmp/gcbad.geojson"
expect 1 'GeometryCollection without a "geometries" array' -- "$cli" regions "$tmp/gcbad.geojson"

# ---- byte order mark: mesh reads the file once -----------------------------------------
printf '\xef\xbb\xbf{"type":"Polygon","coordinates":%s}\n' "$(sq 0 0 1 1)" >"$tmp/bom.geojson"
expect 0 '"triangles": 2, ' -- "$cli" mesh "$tmp/bom.geojson" -o "$tmp/bom" --stats

# ---- not JSON: NUL bytes, trailing commas, a directory ---------------------------------
printf '{"type":"Polygon","coordinates":%s}\0\n' "$(sq 0 0 1 1)" >"$tmp/nul.geojson"
expect 1 'nul.geojson:1:67: binary data \(NUL byte\)' -- "$cli" join "$tmp/nul.geojson" "$tmp/g.csv" --planar
expect 1 'nul.geojson:1:67: binary data \(NUL byte\)' -- "$cli" mesh "$tmp/nul.geojson" -o "$tmp/nulout"
nothing "$tmp/nulout"
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0],]]}\n' >"$tmp/comma.geojson"
expect 1 'comma.geojson:1:[0-9]+: malformed JSON' -- "$cli" regions "$tmp/comma.geojson" --planar
printf '{"type":"Polygon","coordinates":%s,}\n' "$(sq 0 0 1 1)" >"$tmp/comma2.geojson"
expect 1 'comma2.geojson:1:[0-9]+: malformed JSON' -- "$cli" mesh "$tmp/comma2.geojson" -o "$tmp/c2"
printf '{"type":"Polygon","coordinates":%s} x\n' "$(sq 0 0 1 1)" >"$tmp/after.geojson"
expect 1 'after.geojson:1:68: unexpected text after the JSON value' -- "$cli" regions "$tmp/after.geojson" --planar
mkdir "$tmp/dir.geojson"
expect 1 'dir.geojson.*Is a directory' -- "$cli" regions "$tmp/dir.geojson"
expect 1 'dir.geojson.*Is a directory' -- "$cli" mesh "$tmp/dir.geojson" -o "$tmp/d"
nothing "$tmp/d"
# ---- raycast: a zero direction is the point at the origin (documented, brute-forced) --
expect 0 'A direction of 0,0 is' -- "$cli" raycast --help
if command -v python3 >/dev/null; then
  python3 - "$tmp" <<'PY'
import random, sys
tmp = sys.argv[1]
rnd = random.Random(11)
discs = [(rnd.randrange(0, 20), rnd.randrange(0, 20), rnd.randrange(0, 5)) for _ in range(60)]
boxes = []
for _ in range(60):
    x, y = rnd.randrange(0, 20), rnd.randrange(0, 20)
    boxes.append((x, y, x + rnd.randrange(0, 5), y + rnd.randrange(0, 5)))
rays = [(rnd.randrange(-2, 22), rnd.randrange(-2, 22)) for _ in range(400)]
open(f'{tmp}/zd.csv', 'w').write(''.join(f'{x},{y},{r}\n' for x, y, r in discs))
open(f'{tmp}/zb.csv', 'w').write(''.join(f'{a},{b},{c},{d}\n' for a, b, c, d in boxes))
open(f'{tmp}/zr.csv', 'w').write(''.join(f'{x},{y},0,0\n' for x, y in rays))
def first(hit):
    return next((i for i in range(60) if hit(i)), -1)
with open(f'{tmp}/zd.want', 'w') as f, open(f'{tmp}/zb.want', 'w') as g:
    f.write('ray,disc,t\n'); g.write('ray,box,t\n')
    for k, (x, y) in enumerate(rays):
        d = first(lambda i: (x - discs[i][0])**2 + (y - discs[i][1])**2 <= discs[i][2]**2)
        b = first(lambda i: boxes[i][0] <= x <= boxes[i][2] and boxes[i][1] <= y <= boxes[i][3])
        f.write(f'{k},{d},0\n' if d >= 0 else f'{k},-1,inf\n')
        g.write(f'{k},{b},0\n' if b >= 0 else f'{k},-1,inf\n')
PY
  "$cli" raycast "$tmp/zd.csv" "$tmp/zr.csv" >"$tmp/zd.got" && cmp -s "$tmp/zd.got" "$tmp/zd.want" &&
    passes=$((passes + 1)) || fail "raycast: zero-direction rays differ from the brute force (discs)"
  "$cli" raycast "$tmp/zb.csv" "$tmp/zr.csv" --boxes >"$tmp/zb.got" && cmp -s "$tmp/zb.got" "$tmp/zb.want" &&
    passes=$((passes + 1)) || fail "raycast: zero-direction rays differ from the brute force (boxes)"
  [ "$(grep -c ',-1,inf' "$tmp/zd.want")" -gt 20 ] && [ "$(grep -vc ',-1,inf' "$tmp/zd.want")" -gt 20 ] &&
    passes=$((passes + 1)) || fail "raycast: the zero-direction scene tests too little"
fi

# ---- world: quoted fields (a quoted first row was taken for a header and dropped), and a
# first row with a bad id is an error, not a header -------------------------------------
printf '"1","disc",0,0,1\n"2",disc , 0.5 ,0,"1"\n3,"point",1,0,"",""\n' >"$tmp/wq.csv"
: >"$tmp/none.csv"
same_text "world: quoted fields" "$("$cli" world "$tmp/wq.csv" "$tmp/none.csv" | tr '\n' ' ')" "frame,a,b 0,1,2 0,1,3 0,2,3 "
printf '"id","kind","x","y","a","b"\n1,point,0,0\n2,point,0,0\n' >"$tmp/wqh.csv"
same_text "world: quoted header" "$("$cli" world "$tmp/wqh.csv" "$tmp/none.csv" | tr '\n' ' ')" "frame,a,b 0,1,2 "
printf '1,"disc,0,0,1\n' >"$tmp/wq2.csv"
expect 1 'wq2.csv:1: unterminated quoted field' -- "$cli" world "$tmp/wq2.csv" "$tmp/none.csv"
printf '1,"disc"x,0,0,1\n' >"$tmp/wq3.csv"
expect 1 'wq3.csv:1: text after a closing quote' -- "$cli" world "$tmp/wq3.csv" "$tmp/none.csv"
printf 'x1,disc,0,0,1\n2,disc,0,0,1\n' >"$tmp/wx1.csv"
expect 1 "wx1.csv:1:1: id is not a whole number: 'x1'" -- "$cli" world "$tmp/wx1.csv" "$tmp/none.csv"
printf 'f0,1,0,0,1\n' >"$tmp/mf0.csv"
expect 1 "mf0.csv:1:1: frame is not a whole number" -- "$cli" world "$tmp/wq.csv" "$tmp/mf0.csv"

# ---- points CSV: a first line with a number in it is data (x1,2 was a header, dropped) --
printf 'x1,2\n3,4\n' >"$tmp/h1.csv"
expect 1 "h1.csv:1:1: field 1 is not a number: 'x1'" -- "$cli" tree "$tmp/h1.csv"
expect 1 "h1.csv:1:1: field 1 is not a finite number: 'x1'" -- "$cli" join "$tmp/gc.geojson" "$tmp/h1.csv" --planar
printf 'x,y\n3,4\n' >"$tmp/h2.csv"
same_text "join: a header still is one" "$("$cli" join "$tmp/gc.geojson" "$tmp/h2.csv" --planar | tr '\n' ' ')" "x,y,feature 3,4,-1 "

printf '0,0\n1,1\n' >"$tmp/two.csv"
# ---- a directory as input: a clear error, exit 1 (was "read error", exit 3 for mesh) ---
mkdir "$tmp/adir" "$tmp/dir.poly"
expect 1 'adir: cannot read: it is a directory' -- "$cli" tree "$tmp/adir"
expect 1 'adir: cannot read: it is a directory' -- "$cli" knn "$tmp/two.csv" "$tmp/adir" -k 1
expect 1 'adir: cannot read: it is a directory' -- "$cli" world "$tmp/adir" "$tmp/none.csv"
expect 1 'adir: cannot read: it is a directory' -- "$cli" world "$tmp/wq.csv" "$tmp/adir"
expect 1 'adir: cannot read: it is a directory' -- "$cli" join "$tmp/gc.geojson" "$tmp/adir" --planar
expect 1 'dir.poly: cannot read: it is a directory' -- "$cli" mesh "$tmp/dir.poly" -o "$tmp/dp"
nothing "$tmp/dp"

# ---- CR-only line ends: an error naming the line (world and join read one line, the
# rest dropped without a word) ------------------------------------------------------------
printf '1,disc,0,0,1\r2,disc,0.5,0,1\r' >"$tmp/wcr.csv"
expect 1 'wcr.csv:1:13: a carriage return inside the line' -- "$cli" world "$tmp/wcr.csv" "$tmp/none.csv"
printf 'x,y\r0.5,0.5\r' >"$tmp/jcr.csv"
expect 1 'jcr.csv:1:4: a carriage return inside the line' -- "$cli" join "$tmp/gc.geojson" "$tmp/jcr.csv" --planar
expect 1 'jcr.csv:1:4: a carriage return inside the line' -- "$cli" tree "$tmp/jcr.csv"
printf '1,disc,0,0,1\r\n2,disc,0.5,0,1\r\n' >"$tmp/wcrlf.csv"
same_text "world: CRLF still fine" "$("$cli" world "$tmp/wcrlf.csv" "$tmp/none.csv" | tr '\n' ' ')" "frame,a,b 0,1,2 "

# ---- an output path that cannot be written fails before any work or output (tree
# printed its statistics, simulate its JSON, then failed) -------------------------------
expect 1 'cannot write .*adir' -- "$cli" tree "$tmp/two.csv" --svg "$tmp/adir"
same_text "tree: nothing on stdout when --svg fails" "$("$cli" tree "$tmp/two.csv" --svg "$tmp/adir" 2>/dev/null)" ""
same_text "regions: nothing on stdout when --svg fails" "$("$cli" regions "$tmp/gc.geojson" --planar --svg "$tmp/adir" 2>/dev/null)" ""
same_text "simulate: nothing on stdout when --svg fails" "$("$cli" simulate --n 20 --frames 2 --svg "$tmp/adir" 2>/dev/null)" ""
"$cli" simulate --n 20 --frames 2 -o "$tmp/sim.json" --svg "$tmp/nodir/s.svg" 2>/dev/null
[ $? -eq 1 ] && [ ! -e "$tmp/sim.json" ] && passes=$((passes + 1)) || fail "simulate: -o written although --svg failed"
"$cli" simulate --n 20 --frames 2 -o "$tmp/sim.json" --svg "$tmp/sim.svg" &&
  grep -q '"pairs": \[' "$tmp/sim.json" && grep -q '</svg>' "$tmp/sim.svg" &&
  passes=$((passes + 1)) || fail "simulate -o and --svg"

# ---- output that cannot be written is an error (it exited 0 for tree and --help) -------
if [ -w /dev/full ]; then
  expect 3 'cannot write standard output' -- sh -c "\"$cli\" tree \"$tmp/two.csv\" >/dev/full"
  expect 3 'cannot write standard output' -- sh -c "\"$cli\" --help >/dev/full"
  expect 3 'cannot write standard output' -- sh -c "\"$cli\" knn \"$tmp/two.csv\" \"$tmp/two.csv\" -k 1 >/dev/full"
  expect 3 'cannot write standard output' -- sh -c "\"$cli\" regions \"$tmp/gc.geojson\" --planar >/dev/full"
fi
report
