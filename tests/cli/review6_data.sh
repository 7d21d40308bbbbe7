#!/usr/bin/env bash
# The sixth review's findings on the shared real data (review6.sh has the rest): Antarctica
# in countries-50m, a ring round the south pole, said "no point found strictly inside the
# hole ring through (-180, -84.35...)" or, projected, "segments 1853 and 1857 cross or
# overlap". Skipped (exit 77) without ../shared/data.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"
data="${QK_SHARED_DIR:-$src/../shared}/data/countries-50m.geojson"
if [ ! -f "$data" ]; then
  echo "SKIPPED: $data not found (set QK_SHARED_DIR to the directory holding data/)"
  exit 77
fi

ant='countries-50m.geojson:1:3746783: feature 239, polygon 2, ring 0 goes round the south pole'
expect 1 "^quadkit mesh: .*$ant \\(its longitudes wind once round the globe, across the antimeridian\\): --project equirect cannot" \
  -- "$cli" mesh "$data" --field name=Antarctica --project equirect --round 2^-4 -o "$tmp/ant"
expect 1 "^quadkit mesh: .*countries-50m.geojson:1:3754183: feature 239, polygon 2, ring 1: no point found strictly inside this hole ring .* \\(feature 239, polygon 2, ring 0 goes round the south pole: its longitudes wind once round the globe, across the antimeridian, which no planar map of lon/lat closes; cut it" \
  -- "$cli" mesh "$data" --field name=Antarctica -o "$tmp/ant"
same_text "Antarctica: nothing written" "$(ls -A "$tmp")" ""
# the features cut at the antimeridian (Fiji, Russia) still mesh projected
for c in Fiji Russia; do
  expect 0 '"triangles": [1-9]' -- "$cli" mesh "$data" --field name=$c --project equirect --round 2^-4 -o "$tmp/$c" --stats
done

# At an unproven --min-angle a split refusal says the angle may be why (the advice was only
# a coarser grid, and each coarser grid asked for a point finer by its factor).
states="$(dirname "$data")/us-states-10m.geojson"
if [ -f "$states" ]; then
  expect 1 'needs a split point.*Round the input to a coarser grid than --round 2\^-2; above 20\.7 degrees \(--min-angle 34\) the bound is tried, not proven, and can need splits finer than any grid: the proven 20 may mesh it' \
    -- "$cli" mesh "$states" --feature 0 --project equirect --round 2^-2 --min-angle 34 -o "$tmp/al"
  expect 0 '"triangles": [1-9]' -- "$cli" mesh "$states" --feature 0 --project equirect --round 2^-2 -o "$tmp/al" --stats
else
  skip "$states not found"
fi

report
