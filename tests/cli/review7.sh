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
expect 1 "^quadkit radius: $tmp/far.csv: query 0 \\(1.0000000000000001e\\+300, 1.0000000000000001e\\+300\\): the query or the points reach beyond 2\\^510" \
  -- "$cli" radius "$tmp/p.csv" "$tmp/far.csv" -r 1e300
same_text "radius: nothing on stdout for an overflowing query" \
  "$("$cli" radius "$tmp/p.csv" "$tmp/far.csv" -r 1e300 2>/dev/null)" ""
# points far out: the root square reaches beyond 2^510
printf 'x,y\n0,0\n-1e200,1e200\n' >"$tmp/pfar.csv"
printf 'x,y\n0,0\n' >"$tmp/q0.csv"
expect 1 "beyond 2\\^510" -- "$cli" radius "$tmp/pfar.csv" "$tmp/q0.csv" -r 1
# within 2^510 an r whose square overflows holds every point, at finite distances
same_text "radius: huge r within 2^510" \
  "$("$cli" radius "$tmp/p.csv" "$tmp/q0.csv" -r 1e300 | tr '\n' ' ')" \
  "query,point,distance 0,0,0 0,1,1.4142135623730951 "

report
