#!/usr/bin/env bash
# Real data the mesher and the point location were not tuned on (the sweep of
# tests/test_sweep_mesh.c and test_sweep_region.c, through the command line): features
# crossing the antimeridian (Fiji, Russia), Alaska's Aleutians, a tiny island, Oregon's
# zero-width spike, meshed with --project equirect --round 2^-4 at extent/64 or /256:
# exit 0 and the .ele holding the triangles --stats counts; Antarctica's polar ring and a
# ring of two distinct points refused with a message naming what is wrong; and `join`
# taking longitudes modulo 360 exactly (a Chukotka vertex given 360 degrees east is in
# Russia under --boundary closed). Skipped (exit 77) without $QK_SHARED_DIR/data.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"
data="${QK_SHARED_DIR:-$src/../shared}/data"
countries="$data/countries-50m.geojson"
states="$data/us-states-10m.geojson"
if [ ! -f "$countries" ] || [ ! -f "$states" ]; then
  echo "SKIPPED: $data/countries-50m.geojson or us-states-10m.geojson not found (set QK_SHARED_DIR)"
  exit 77
fi

mesh_ok() { # mesh_ok FILE NAME MAX_SIZE: meshes, and the .ele has --stats' triangles
  local out nt ne
  out=$("$cli" mesh "$1" --field "name=$2" --project equirect --round 2^-4 --max-size "$3" \
    -o "$tmp/m" --stats 2>&1)
  local rc=$?
  nt=$(grep -oE '"triangles": [0-9]+' <<<"$out" | grep -oE '[0-9]+$')
  ne=$(head -1 "$tmp/m.ele" 2>/dev/null | awk '{print $1}')
  if [ "$rc" -ne 0 ] || [ -z "$nt" ] || [ "$nt" != "$ne" ] || [ "$nt" -lt 1 ]; then
    fail "mesh $2 (max size $3): exit $rc, stats $nt triangles, .ele $ne: $out"
  else
    passes=$((passes + 1))
  fi
  rm -f "$tmp/m.node" "$tmp/m.ele"
}
mesh_ok "$countries" Fiji 4008    # both sides of the antimeridian, whole
mesh_ok "$countries" Russia 133304
mesh_ok "$countries" Bermuda 71   # a tiny island at extent/256
mesh_ok "$states" Alaska 52733
mesh_ok "$states" Oregon 2498     # a -> b -> a spike on its southern border

expect 1 'feature 239, polygon 2, ring 0 goes round the south pole' -- \
  "$cli" mesh "$countries" --field name=Antarctica --project equirect --round 2^-4 -o "$tmp/bad"
cat >"$tmp/flat.geojson" <<'JSON'
{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"name": "flat"},
 "geometry": {"type": "Polygon", "coordinates": [[[-75.56031536375363, 39.63006380532805],
 [-75.5567260697607, 39.60601013399133], [-75.56031536375363, 39.63006380532805],
 [-75.56031536375363, 39.63006380532805]]]}}]}
JSON
expect 1 'no ring with 3 distinct points' -- "$cli" mesh "$tmp/flat.geojson" --project equirect -o "$tmp/bad"
ls "$tmp"/bad* >/dev/null 2>&1 && fail "output written for refused input"

# Longitudes modulo 360, exactly: a vertex of Russia's Chukotka coast, and 360 degrees east.
printf 'lon,lat\n-174.43074430744306,67.038136425895516\n185.56925569255694,67.038136425895516\n' >"$tmp/p.csv"
got=$("$cli" join "$countries" "$tmp/p.csv" --field name --boundary closed | cut -d, -f3- | tr '\n' ' ')
same_text "join closed on a vertex and 360 east" "$got" "feature,name 75,Russia 75,Russia "
got=$("$cli" join "$countries" "$tmp/p.csv" --field name --boundary open | cut -d, -f3- | tr '\n' ' ')
same_text "join open on a vertex and 360 east" "$got" "feature,name -1, -1, "
report
