#!/usr/bin/env bash
# CLI regressions from a seventh review (sixteenth session), on hostile inputs not tried
# before (one block per finding; each failed before its fix).
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- radius: squared distances that overflow -------------------------------------------
# A query at 1e300 is 1.4e300 from every point, beyond -r 1e300; the squares overflowed to
# inf <= inf and every point was listed at distance inf. Now refused as knn refuses it.
printf 'x,y\n0,0\n1,1\n' >"$tmp/p.csv"
printf 'x,y\n1e300,1e300\n' >"$tmp/far.csv"
expect 1 "^quadkit: $tmp/far.csv:2: query \\(1.0000000000000001e\\+300, 1.0000000000000001e\\+300\\) is beyond 2\\^510" \
  -- "$cli" radius "$tmp/p.csv" "$tmp/far.csv" -r 1e300
same_text "radius: nothing on stdout for an overflowing query" \
  "$("$cli" radius "$tmp/p.csv" "$tmp/far.csv" -r 1e300 2>/dev/null)" ""
# points far out: the root square reaches beyond 2^510
printf 'x,y\n0,0\n-1e200,1e200\n' >"$tmp/pfar.csv"
printf 'x,y\n0,0\n' >"$tmp/q0.csv"
# (the point is named, by its file and line: the message named the first query, 0,0 here)
expect 1 "^quadkit: $tmp/pfar.csv:3: point \\(-9.9999999999999997e\\+199, 9.9999999999999997e\\+199\\) is beyond 2\\^510" \
  -- "$cli" radius "$tmp/pfar.csv" "$tmp/q0.csv" -r 1
expect 1 "^quadkit: $tmp/pfar.csv:3: point \\(-9.9999999999999997e\\+199, 9.9999999999999997e\\+199\\) is beyond 2\\^510" \
  -- "$cli" knn "$tmp/pfar.csv" "$tmp/q0.csv" -k 1
# within 2^510 an r whose square overflows holds every point, at finite distances
same_text "radius: huge r within 2^510" \
  "$("$cli" radius "$tmp/p.csv" "$tmp/q0.csv" -r 1e300 | tr '\n' ' ')" \
  "query,point,distance 0,0,0 0,1,1.4142135623730951 "

# ---- collide: disc squares that overflow or underflow ----------------------------------
# Disc 2 at (0, 1e300) is 1.4e300 from discs 0 and 1 (radius 1e300): the squares were
# inf <= inf and both pairs came out; two discs of radius 1e-170 whose centres are
# 2.8e-170 apart had squares 0 <= 0. Now refused, naming the row and field.
printf 'x,y,r\n1e300,0,1e300\n-1e300,0,1e300\n0,1e300,1\n' >"$tmp/dover.csv"
expect 1 "^quadkit: $tmp/dover.csv:2: field 1: 1.0000000000000001e\\+300 is outside \\[2\\^-200, 2\\^200\\] in magnitude, where the disc overlap test's squares overflow or underflow; scale the data by a power of two$" \
  -- "$cli" collide "$tmp/dover.csv"
printf 'x,y,r\n0,0,1e-170\n2e-170,2e-170,1e-170\n' >"$tmp/dunder.csv"
expect 1 "^quadkit: $tmp/dunder.csv:2: field 3: 9.9999999999999998e-171 is outside" -- "$cli" collide "$tmp/dunder.csv"
same_text "collide: nothing on stdout for overflowing discs" \
  "$("$cli" collide "$tmp/dover.csv" 2>/dev/null)" ""
# the same scene scaled into the range: one pair (0 and 1 touch at the origin), as the
# exact test says; zero values and boxes of any size stay accepted
printf 'x,y,r\n1e50,0,1e50\n-1e50,0,1e50\n0,1e50,1\n0,0,0\n' >"$tmp/dok.csv"
same_text "collide: scaled scene" "$("$cli" collide "$tmp/dok.csv" | tr '\n' ' ')" "a,b 0,1 0,3 1,3 "
printf 'x0,y0,x1,y1\n1e300,1e300,1e308,1e308\n-1e308,-1e308,1e300,1e300\n' >"$tmp/bbig.csv"
same_text "collide: huge boxes" "$("$cli" collide "$tmp/bbig.csv" --boxes | tr '\n' ' ')" "a,b 0,1 "

# ---- mesh --project equirect: edges across the whole map -------------------------------
# The whole world [-180, -90] .. [180, 90] and the band [-180, -10] .. [180, 10] (edges
# from -180 to 180 that run across the map, docs/region.md rule 6) had their negative
# longitudes moved up by 360 like Fiji's, every point went to longitude 180, and the
# mesher said "no ring with 3 distinct points". Now the map's full width, 2 x 20015114.4375
# m at the equator; Fiji's zero-length step still joins its two sides (its md5 unchanged).
printf '{"type":"Polygon","coordinates":[[[-180,-90],[180,-90],[180,90],[-180,90],[-180,-90]]]}\n' >"$tmp/world.geojson"
printf '{"type":"Polygon","coordinates":[[[-180,-10],[180,-10],[180,10],[-180,10],[-180,-10]]]}\n' >"$tmp/band.geojson"
for w in world band; do
  expect 0 "" -- "$cli" mesh "$tmp/$w.geojson" --project equirect --round 2^-4 -o "$tmp/$w"
  same_text "mesh --project: $w spans the map" \
    "$(awk 'NR > 1 && NF >= 3 {print $2}' "$tmp/$w.node" 2>/dev/null | sort -g | sed -n '1p;$p' | tr '\n' ' ')" \
    "-20015114.4375 20015114.4375 "
done
# a ring crossing the antimeridian and coming back by a step (as Fiji's) stays 2 degrees wide
# (179 to 181 times cos(-16.43 degrees) R pi / 180, rounded to 1/16)
printf '{"type":"Polygon","coordinates":[[[179,-17],[180,-17],[-179,-17],[-179,-16],[-180,-16],[180,-16],[179,-16],[179,-17]]]}\n' >"$tmp/step.geojson"
expect 0 "" -- "$cli" mesh "$tmp/step.geojson" --project equirect --round 2^-4 -o "$tmp/step"
same_text "mesh --project: a step across the antimeridian" \
  "$(awk 'NR > 1 && NF >= 3 {print $2}' "$tmp/step.node" 2>/dev/null | sort -g | sed -n '1p;$p' | tr '\n' ' ')" \
  "19091303.25 19304613.9375 "

# ---- mesh --round: exponents out of range ----------------------------------------------
# 2^-2000 was "expected 2^-q with an integer q" (it is one) and 2^-1000 "the grid step
# must be a positive number" (it is); both are below the smallest step taken, 1e-300.
printf '3 2 0 0\n1 0 0\n2 4 0\n3 0 4\n3 0\n1 1 2\n2 2 3\n3 3 1\n0\n' >"$tmp/tri.poly"
expect 2 "^quadkit mesh: --round 2\\^-2000: the exponent must be from -996 to 1000 \\(the grid step from about 1e-300 to 1e301\\)$" \
  -- "$cli" mesh "$tmp/tri.poly" -o "$tmp/tri" --round 2^-2000
expect 2 "^quadkit mesh: --round 2\\^-997: the exponent must be from -996" -- "$cli" mesh "$tmp/tri.poly" -o "$tmp/tri" --round 2^-997
expect 2 "^quadkit mesh: --round 1e-301: the grid step must be at least 1e-300$" -- "$cli" mesh "$tmp/tri.poly" -o "$tmp/tri" --round 1e-301
expect 0 "" -- "$cli" mesh "$tmp/tri.poly" -o "$tmp/tri" --round 2^-996

# ---- mesh --round on a .poly file: lines, numbers and markers kept ----------------------
# The input was rebuilt from arrays: "dup.poly: vertices 0 and 3 coincide" for the file's
# vertices 1 and 4 (line 5), and boundary markers and regional attributes were dropped.
printf '4 2 0 0\n1 0 0\n2 4 0\n3 0 4\n4 0.2 0\n3 0\n1 1 2\n2 2 3\n3 3 1\n0\n' >"$tmp/dup.poly"
expect 1 "^quadkit mesh: $tmp/dup.poly:5: vertices 1 and 4 coincide at \\(0, 0\\)$" \
  -- "$cli" mesh "$tmp/dup.poly" -o "$tmp/dup" --round 1
nothing_written "$tmp/dup"
printf '4 2 0 1\n1 0 0 5\n2 4.3 0 5\n3 4 4 6\n4 0 4 6\n4 1\n1 1 2 7\n2 2 3 7\n3 3 4 8\n4 4 1 8\n0\n' >"$tmp/mk.poly"
expect 0 "^quadkit mesh: --round 1: 1 coordinates of $tmp/mk.poly moved to the grid$" \
  -- "$cli" mesh "$tmp/mk.poly" -o "$tmp/mk" --round 1
same_text "mesh --round: markers kept" "$(head -n 1 "$tmp/mk.node" 2>/dev/null; awk 'NR > 1 && NF == 4 {print $4}' "$tmp/mk.node" 2>/dev/null | sort -un | tr '\n' ' ')" \
  "$(printf '25 2 0 1\n0 5 6 7 8 ')"
# a coordinate that rounds beyond the largest double: said, nothing written
printf '3 2 0 0\n1 0 0\n2 1.7976931348623157e308 0\n3 0 4\n3 0\n1 1 2\n2 2 3\n3 3 1\n0\n' >"$tmp/ovf.poly"
expect 1 "^quadkit mesh: $tmp/ovf.poly: --round 2\\^1000: a rounded coordinate is beyond the largest double$" \
  -- "$cli" mesh "$tmp/ovf.poly" -o "$tmp/ovf" --round 2^1000
nothing_written "$tmp/ovf"

# ---- join: rows wider or narrower than the header ---------------------------------------
# A row is copied as read and `feature` appended: a row with a third field put `feature`
# under another column than the header's. Now refused, naming line and counts.
printf '{"type":"Polygon","coordinates":[[[0,0],[4,0],[4,4],[0,4],[0,0]]]}\n' >"$tmp/sq.geojson"
printf '"x","y"\n"1","1"\n1,1,"a,b"\n' >"$tmp/wide.csv"
expect 1 "^quadkit join: $tmp/wide.csv:3: 3 fields where the header \\(line 1\\) has 2$" \
  -- "$cli" join "$tmp/sq.geojson" "$tmp/wide.csv" --planar
printf '\nx,y,name\n1,1,a\n2,2\n' >"$tmp/narrow.csv"
expect 1 "^quadkit join: $tmp/narrow.csv:4: 2 fields where the header \\(line 2\\) has 3$" \
  -- "$cli" join "$tmp/sq.geojson" "$tmp/narrow.csv" --planar -o "$tmp/narrow.out"
[ -e "$tmp/narrow.out" ] && fail "join: an output was left after an error"
printf 'x,y,name\n1,1,"a,b"\n5,5,c\n' >"$tmp/even.csv"
same_text "join: rows as wide as the header" \
  "$("$cli" join "$tmp/sq.geojson" "$tmp/even.csv" --planar | tr '\n' ' ')" \
  'x,y,name,feature 1,1,"a,b",0 5,5,c,-1 '
# without a header rows may differ (no columns to keep aligned)
printf '1,1\n5,5,c\n' >"$tmp/nohead.csv"
same_text "join: no header" "$("$cli" join "$tmp/sq.geojson" "$tmp/nohead.csv" --planar | tr '\n' ' ')" \
  '1,1,0 5,5,c,-1 '

# ---- raycast: a hit whose t overflows --------------------------------------------------
# Direction 1e-300 towards a disc 1e300 away: t = 1e600 printed as inf, the miss's mark.
printf 'x,y,r\n0,0,1\n' >"$tmp/disc.csv"
printf 'x,y,dx,dy\n-2,0,1,0\n-1e300,0,1e-300,0\n' >"$tmp/tinf.csv"
expect 1 "^quadkit: $tmp/tinf.csv:3: ray 1 hits 0 at a t beyond the largest double" \
  -- "$cli" raycast "$tmp/disc.csv" "$tmp/tinf.csv"
printf 'x,y,dx,dy\n-2,0,1,0\n-2,0,1e300,0\n-1e300,0,1,0\n' >"$tmp/tok.csv"
same_text "raycast: large but finite t" "$("$cli" raycast "$tmp/disc.csv" "$tmp/tok.csv" | tr '\n' ' ')" \
  "ray,disc,t 0,0,1 1,0,1e-300 2,0,1.0000000000000001e+300 "

report
