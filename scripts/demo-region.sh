#!/usr/bin/env bash
# `make demo`, region part: the country of every place of ../shared/data/cities.csv from
# countries-50m.geojson (top ten countries by number of places) and an SVG of the layer's
# index; without ../shared, the same on the small hand-made layer of examples/region.
# Usage: scripts/demo-region.sh CLI [OUTDIR]
set -euo pipefail
cli=${1:-build/quadkit}
out=${2:-out/demo}
root=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$out"
data=$root/../shared/data
if [ -f "$data/cities.csv" ] && [ -f "$data/countries-50m.geojson" ]; then
  layer=$data/countries-50m.geojson
  points=$data/cities.csv
else
  echo "(../shared/data not found: using examples/region)"
  layer=$root/examples/region/islands.geojson
  points=$root/examples/region/places.csv
fi
echo "== join: the country of each place of $(basename "$points") ($(basename "$layer"))"
"$cli" regions "$layer" --svg "$out/regions.svg" >"$out/regions.json"
"$cli" join "$layer" "$points" --xy lon,lat --field name -o "$out/join.csv"
echo "   top ten by number of places (feature -1: in none, e.g. on the coast at this scale):"
# the last field is the name, the one before it the feature index
awk -F, 'NR > 1 { n = $NF; if ($(NF - 1) == -1) n = "(none)"; c[n]++ }
         END { for (k in c) print c[k] "\t" k }' "$out/join.csv" | sort -rn | head -10 |
  awk -F'\t' '{ printf "  %7d  %s\n", $1, $2 }'
echo "   (CSV: $out/join.csv; index picture: $out/regions.svg)"
