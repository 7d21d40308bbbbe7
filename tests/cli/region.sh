#!/usr/bin/env bash
# CLI tests for `quadkit join` and `quadkit regions`: exact output on the hand-made layer
# of examples/region (holes, a shared edge, an antimeridian square, a skipped point),
# --all, --boundary, --xy by name and number, --field, errors naming file and line, exit
# codes, atomic output; with ../shared/data present, the cities of issue 9 against
# countries-50m (that part is skipped otherwise; exit 77 when nothing else could run).
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"
same() { # same NAME FILE_GOT FILE_WANT
  if cmp -s "$2" "$3"; then
    passes=$((passes + 1))
  else
    echo "FAIL: $1 differs:"
    diff "$2" "$3" | head -10
    fails=$((fails + 1))
  fi
}
layer=$src/examples/region/islands.geojson
pts=$src/examples/region/places.csv

"$cli" join "$layer" "$pts" --xy lon,lat --field name >"$tmp/got" 2>"$tmp/err"
cat >"$tmp/want" <<'CSV'
name,lon,lat,feature,feature_name
centre west,1,1,0,West
in the hole,3.5,3.5,-1,
on the lake isle,4.5,4.5,2,Lake isle
shared edge,10,5,1,East
east,15,5,1,East
"Dateline, east",175,-15,3,Dateline
"Dateline, west",-175,-15,3,Dateline
nowhere,30,30,-1,
CSV
same "join by name" "$tmp/got" "$tmp/want"
# appended names already in the header are prefixed feature_ until unique
printf 'feature,feature_feature,lon,lat\n7,8,1,1\n' >"$tmp/fh.csv"
"$cli" join "$layer" "$tmp/fh.csv" --xy lon,lat --field name --field code >"$tmp/got"
printf 'feature,feature_feature,lon,lat,feature_feature_feature,name,code\n7,8,1,1,0,West,W\n' >"$tmp/want"
same "join: appended names unique" "$tmp/got" "$tmp/want"
# ... and --help says so (it said only that the names are appended)
expect 0 'prefixed feature_' -- "$cli" join --help
# by number, closed boundary: the shared edge is in both; --all lists both
"$cli" join "$layer" "$pts" --xy 2,3 --all --boundary closed --field code -o "$tmp/all.csv"
grep -c '^shared edge,10,5,' "$tmp/all.csv" | grep -qx 2 && passes=$((passes + 1)) ||
  fail "--all --boundary closed: shared edge should give two rows"
grep -q '^shared edge,10,5,0,W$' "$tmp/all.csv" && passes=$((passes + 1)) || fail "--all row 0"
"$cli" join "$layer" "$pts" --xy 2,3 --boundary open >"$tmp/open.csv"
grep -q '^shared edge,10,5,-1$' "$tmp/open.csv" && passes=$((passes + 1)) || fail "open boundary"
# --planar: the dateline square becomes a band, -175 is outside it
"$cli" join "$layer" "$pts" --xy lon,lat --planar >"$tmp/pl.csv"
grep -q '^"Dateline, west",-175,-15,-1$' "$tmp/pl.csv" && passes=$((passes + 1)) || fail "--planar"
# regions: stats as JSON and an SVG
expect 0 '"features": 5.*"holes": 1.*"skipped_geometries": 1' -- "$cli" regions "$layer" --stats
expect 0 '' -- "$cli" regions "$layer" --svg "$tmp/r.svg"
grep -q '</svg>' "$tmp/r.svg" && passes=$((passes + 1)) || fail "svg written"
# each ring one closed subpath, so that the even-odd fill fills (it was two-point subpaths)
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}' >"$tmp/sq.geojson"
"$cli" regions "$tmp/sq.geojson" --planar --svg "$tmp/sq.svg" >/dev/null
grep -qE '<path fill-rule="evenodd"[^>]* d="M[0-9. ]+(L[0-9. ]+){4}Z"' "$tmp/sq.svg" &&
  passes=$((passes + 1)) || fail "svg: the square as one closed subpath"
# a repeated position is no edge: the square stays simple (it counted as self-intersecting),
# while a spike doubling back, and a ring of one edge there and back, touch themselves
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,0],[1,1],[0,1],[0,0],[0,0]]]}' >"$tmp/dup.geojson"
expect 0 '"self_intersecting_rings": 0' -- "$cli" regions "$tmp/dup.geojson"
printf '{"type":"MultiPolygon","coordinates":[[[[0,0],[10,0],[15,0],[10,0],[10,10],[0,10],[0,0]]],[[[20,0],[30,0],[20,0],[20,0]]]]}' >"$tmp/spike.geojson"
expect 0 '"self_intersecting_rings": 2' -- "$cli" regions "$tmp/spike.geojson"

# errors
printf 'lon,lat\n1,1\n2,abc\n' >"$tmp/bad.csv"
expect 1 'bad.csv:3:3: field 2 \(lat\) is not a finite number' -- "$cli" join "$layer" "$tmp/bad.csv" -o "$tmp/none.csv"
[ ! -e "$tmp/none.csv" ] && passes=$((passes + 1)) || fail "half-written output left behind"
printf '1\n' >"$tmp/short.csv"
expect 1 'short.csv:1: no field 2' -- "$cli" join "$layer" "$tmp/short.csv"
expect 1 "no column named 'lng'" -- "$cli" join "$layer" "$pts" --xy lon,lng
expect 1 'islands.geojson: --field nmae: no feature of the [0-9]+ has that property' -- \
  "$cli" join "$layer" "$pts" --xy lon,lat --field nmae -o "$tmp/none.csv"
[ ! -e "$tmp/none.csv" ] && passes=$((passes + 1)) || fail "output written for a bad --field"
expect 2 'needs REGIONS' -- "$cli" join "$layer"
expect 2 'boundary must be' -- "$cli" join "$layer" "$pts" --boundary half
expect 2 'xy needs two columns' -- "$cli" join "$layer" "$pts" --xy lon
printf '{"type":"FeatureCollection",\n "features": [}\n' >"$tmp/bad.geojson"
expect 1 'bad.geojson:2:.*malformed JSON' -- "$cli" regions "$tmp/bad.geojson"
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1]]]}' >"$tmp/open.geojson"
expect 1 'feature 0, polygon 0, ring 0: not closed' -- "$cli" regions "$tmp/open.geojson"
# a lone surrogate escape (json-c reads it as U+FFFD; I-JSON forbids it)
printf '{"type":"Feature","properties":{"name":"a\\ud800b"},\n "geometry":null}' >"$tmp/sur.geojson"
expect 1 'sur.geojson:1:42: malformed JSON: \\ud800 .*half of a surrogate pair' -- "$cli" regions "$tmp/sur.geojson"
# coordinates nested one level too shallow or too deep for the type
printf '{"type":"MultiPolygon","coordinates":[[[0,0],[1,0],[1,1],[0,0]]]}' >"$tmp/mps.geojson"
expect 1 'mps.geojson:1:40: feature 0, polygon 0, ring 0: the coordinates array has the wrong depth for a MultiPolygon \(nested too shallow\)' -- "$cli" regions "$tmp/mps.geojson"
printf '{"type":"Polygon","coordinates":[[[[0,0],[1,0],[1,1],[0,0]]]]}' >"$tmp/pd.geojson"
expect 1 'wrong depth for a Polygon \(nested too deep\): expected positions as arrays of numbers' -- "$cli" regions "$tmp/pd.geojson"
printf '{"type":"Polygon","coordinates":[[[0,0],[500,0],[1,1],[0,0]]]}' >"$tmp/proj.geojson"
expect 1 'planar' -- "$cli" regions "$tmp/proj.geojson"
expect 0 '"mode": "planar"' -- "$cli" regions "$tmp/proj.geojson" --planar
expect 1 'cannot open' -- "$cli" join "$layer" "$tmp/missing.csv"

# real data
data=$src/../shared/data
if [ -r "$data/countries-50m.geojson" ]; then
  printf 'city,lon,lat\nRovaniemi,25.7294,66.5039\nTornio,24.1470,65.8481\nBodo,14.4049,67.2804\nMurmansk,33.0856,68.9585\nParis,2.3522,48.8566\nChukotka,-175,67\n' >"$tmp/c.csv"
  "$cli" join "$data/countries-50m.geojson" "$tmp/c.csv" --xy lon,lat --field name >"$tmp/got"
  grep -q '^Rovaniemi,.*,Finland$' "$tmp/got" && grep -q '^Tornio,.*,Finland$' "$tmp/got" &&
    ! grep -q '^Bodo,.*,Russia$' "$tmp/got" && grep -q '^Murmansk,.*,Russia$' "$tmp/got" &&
    grep -q '^Paris,.*,France$' "$tmp/got" && grep -q '^Chukotka,.*,Russia$' "$tmp/got" &&
    passes=$((passes + 1)) || { fail "cities of issue 9"; cat "$tmp/got"; }
else
  echo "SKIP: $data absent, real-data part not run"
fi
report
