#!/usr/bin/env bash
# `make demo`, query part: a planar kNN, collisions and ray casting on the built-in
# examples, and the ten places nearest to Paris by geodesic distance (km) on
# ../shared/data/cities.csv when present, else on the committed excerpt.
# Usage: scripts/demo-query.sh CLI [OUTDIR]
set -euo pipefail
cli=${1:-build/quadkit}
out=${2:-out/demo}
root=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$out"

echo "== kNN: the 3 points of examples/points.csv nearest to (0.5, 0.5) and (0.1, 0.9)"
printf 'x,y\n0.5,0.5\n0.1,0.9\n' >"$out/knn-queries.csv"
"$cli" knn "$root/examples/points.csv" "$out/knn-queries.csv" -k 3

echo "== collide: overlapping discs of examples/query/discs.csv (touching counts)"
"$cli" collide "$root/examples/query/discs.csv"
echo "== raycast: first disc hit by each ray of examples/query/rays.csv"
"$cli" raycast "$root/examples/query/discs.csv" "$root/examples/query/rays.csv"

cities=${QK_CITIES:-$root/../shared/data/cities.csv} # QK_CITIES overrides (tests use it)
if [ ! -f "$cities" ]; then
  cities="$root/examples/query/cities-excerpt.csv"
  echo "(cities.csv not found: using the excerpt examples/query/cities-excerpt.csv)"
fi
echo "== geo knn: the ten places nearest to Paris on the WGS84 ellipsoid, in km"
# The query: Paris's own row (lon,lat are the first two fields).
awk -F, '$4 == "FR" && $5 == "\"Paris\"" { print $1 "," $2; exit }' "$cities" >"$out/paris.csv"
if ! "$cli" geo knn "$cities" "$out/paris.csv" -k 11 --keep point -o "$out/paris-knn.csv" \
  2>"$out/geo.err"; then
  cat "$out/geo.err"
  echo "(geodesic queries unavailable in this build)"
  exit 0
fi
# --keep point appended each place's own row (lon,lat,population,country,name) after
# query,rank,point,metres: the name is the rest of the line after the eighth comma.
# Rank 1 is Paris itself.
awk -F, 'NR > 1 && $2 > 1 { name = $0; for (i = 0; i < 8; i++) sub(/^[^,]*,/, "", name)
                            gsub(/"/, "", name)
                            printf "  %2d. %-28s %8.1f km\n", $2 - 1, name " (" $8 ")", $4 / 1000 }' \
  "$out/paris-knn.csv"
echo "   (CSV: $out/paris-knn.csv)"
echo "== geo radius: places within 1000 km of Paris"
"$cli" geo radius "$cities" "$out/paris.csv" -r 1000000 -o "$out/paris-1000km.csv"
echo "   $(($(wc -l <"$out/paris-1000km.csv") - 1)) places (CSV: $out/paris-1000km.csv)"
