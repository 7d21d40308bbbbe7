#!/usr/bin/env bash
# CLI regressions from a hostile-input review (one block per bug found): GeoJSON feature
# collections with features that have no polygon (mesh refused them with an internal
# error), GeometryCollections (their polygons were dropped silently), a byte order mark
# for mesh (its second read failed), NUL bytes and trailing commas in JSON (accepted), and
# a directory given as input. Every error must exit 1 and write nothing.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

same() { # same NAME GOT WANT: compare two strings
  if [ "$2" = "$3" ]; then
    passes=$((passes + 1))
  else
    fail "$1: got '$2', want '$3'"
  fi
}

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
same "join: mixed features" "$("$cli" join "$tmp/fc.geojson" "$tmp/p.csv" --planar --field name | tr '\n' ' ')" \
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
same "join: GeometryCollection" "$("$cli" join "$tmp/gc.geojson" "$tmp/g.csv" --planar --field name | tr '\n' ' ')" \
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
report
