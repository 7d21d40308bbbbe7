#!/usr/bin/env bash
# CLI tests for the query commands (knn, range, radius, locate, collide, raycast, geo):
# exact output on small hand-checked inputs, kNN and radius against a brute-force awk
# oracle on random data, exit codes, and errors naming file and line.
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

printf 'x,y\n0,0\n1,0\n0,1\n1,1\n0.5,0.5\n' >"$tmp/p.csv"
printf '0.1,0.1\n0.9,0.8\n' >"$tmp/q.csv"

# knn: exact output.
"$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 2 >"$tmp/got" 2>&1
cat >"$tmp/want" <<'EOF'
query,rank,point,distance
0,1,0,0.14142135623730953
0,2,4,0.56568542494923812
1,1,3,0.22360679774997891
1,2,4,0.5
EOF
same "knn small" "$tmp/got" "$tmp/want"
# k larger than n gives n rows; a cap gives fewer.
expect 0 '^1,5,' -- "$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 9
"$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 5 --max-dist 0.5 >"$tmp/got"
# (point 4 is 0.5 from query 1 only up to rounding: its squared distance exceeds 0.25.)
printf 'query,rank,point,distance\n0,1,0,0.14142135623730953\n1,1,3,0.22360679774997891\n' >"$tmp/want"
same "knn capped" "$tmp/got" "$tmp/want"

# range: sorted by box then point; inclusive edges.
printf 'xmin,ymin,xmax,ymax\n0,0,0.5,0.5\n0.5,0.5,1,1\n2,2,3,3\n' >"$tmp/b.csv"
"$cli" range "$tmp/p.csv" "$tmp/b.csv" >"$tmp/got"
printf 'box,point\n0,0\n0,4\n1,3\n1,4\n' >"$tmp/want"
same "range" "$tmp/got" "$tmp/want"
printf '0,0,1,1\n1,0,0,1\n' >"$tmp/inv.csv"
expect 1 'inv.csv:2: box has xmin > xmax' -- "$cli" range "$tmp/p.csv" "$tmp/inv.csv"

# radius: sorted by query then point.
"$cli" radius "$tmp/p.csv" "$tmp/q.csv" -r 0.6 >"$tmp/got"
printf 'query,point,distance\n0,0,0.14142135623730953\n0,4,0.56568542494923812\n1,3,0.22360679774997891\n1,4,0.5\n' >"$tmp/want"
same "radius" "$tmp/got" "$tmp/want"

# locate: the leaf square of each query; outside the root gets nan.
printf '0.1,0.1\n0.5,0.5\n7,7\n' >"$tmp/lq.csv"
"$cli" locate "$tmp/p.csv" "$tmp/lq.csv" --capacity 1 >"$tmp/got"
printf 'query,xmin,ymin,side,depth,count\n0,0,0,0.25,2,1\n1,0.25,0.25,0.25,2,1\n2,nan,nan,nan,-1,0\n' >"$tmp/want"
same "locate" "$tmp/got" "$tmp/want"

# collide: tangent discs touch; pairs sorted.
printf 'x,y,r\n0,0,1\n2,0,1\n5,5,0.5\n5.5,5,0.1\n' >"$tmp/d.csv"
"$cli" collide "$tmp/d.csv" >"$tmp/got"
printf 'a,b\n0,1\n2,3\n' >"$tmp/want"
same "collide" "$tmp/got" "$tmp/want"
printf '0,0,1,1\n1,1,2,2\n3,3,4,4\n' >"$tmp/boxes.csv"
"$cli" collide "$tmp/boxes.csv" --boxes >"$tmp/got"
printf 'a,b\n0,1\n' >"$tmp/want"
same "collide boxes" "$tmp/got" "$tmp/want"
printf 'x,y,r\n0,0,1\n\n2,0,-1\n' >"$tmp/negr.csv"
expect 1 'negr.csv:4: disc radius is negative' -- "$cli" collide "$tmp/negr.csv"

# raycast: first hit, t = 0 inside, segments via tmax, misses.
printf 'ox,oy,dx,dy,tmax\n-5,0,1,0\n5,5,0,1\n5,3,0,1,1\n5,3,0,1,2\n0,9,1,0\n' >"$tmp/r.csv"
"$cli" raycast "$tmp/d.csv" "$tmp/r.csv" >"$tmp/got"
printf 'ray,disc,t\n0,0,4\n1,2,0\n2,-1,inf\n3,2,1.5\n4,-1,inf\n' >"$tmp/want"
same "raycast" "$tmp/got" "$tmp/want"
printf '0,0,1,0,-1\n' >"$tmp/negt.csv"
expect 1 'negt.csv:1: tmax is negative' -- "$cli" raycast "$tmp/d.csv" "$tmp/negt.csv"

# kNN and radius against a brute-force oracle on random points with duplicates.
awk 'BEGIN { srand(7); print "x,y"; for (i = 0; i < 400; i++) {
  if (i % 10 == 3) printf "%.17g,%.17g\n", 0.5, 0.25; else printf "%.17g,%.17g\n", rand(), rand() } }' >"$tmp/rp.csv"
awk 'BEGIN { srand(11); for (i = 0; i < 30; i++) printf "%.17g,%.17g\n", rand() * 1.2 - 0.1, rand() }' >"$tmp/rq.csv"
awk -F, 'BEGIN { n = 0 } NR == FNR { if (FNR > 1) { px[n] = $1; py[n] = $2; n++ } next }
  { for (i = 0; i < n; i++) { dx = px[i] - $1; dy = py[i] - $2; printf "%d,%.17g,%d\n", FNR - 1, dx * dx + dy * dy, i } }' \
  "$tmp/rp.csv" "$tmp/rq.csv" | sort -t, -k1,1n -k2,2g -k3,3n |
  awk -F, 'BEGIN { print "query,rank,point,distance" }
    { if ($1 != q) { q = $1; r = 0 } if (++r <= 7) printf "%d,%d,%d,%.17g\n", $1, r, $3, sqrt($2) }' >"$tmp/want"
"$cli" knn "$tmp/rp.csv" "$tmp/rq.csv" -k 7 --capacity 4 >"$tmp/got"
same "knn vs brute force" "$tmp/got" "$tmp/want"
awk -F, 'BEGIN { n = 0 } NR == FNR { if (FNR > 1) { px[n] = $1; py[n] = $2; n++ } next }
  { for (i = 0; i < n; i++) { dx = px[i] - $1; dy = py[i] - $2; d2 = dx * dx + dy * dy
      if (d2 <= 0.15 * 0.15) printf "%d,%d,%.17g\n", FNR - 1, i, sqrt(d2) } }' \
  "$tmp/rp.csv" "$tmp/rq.csv" | sort -t, -k1,1n -k2,2n | sed '1i query,point,distance' >"$tmp/want"
"$cli" radius "$tmp/rp.csv" "$tmp/rq.csv" -r 0.15 --capacity 2 >"$tmp/got"
same "radius vs brute force" "$tmp/got" "$tmp/want"

# geo: across the antimeridian, one degree on the equator is a * pi / 180 metres.
printf 'lon,lat\n179.5,0\n-179.5,0\n0,89.99\n10,0\n' >"$tmp/g.csv"
printf '180,0\n' >"$tmp/gq.csv"
"$cli" geo knn "$tmp/g.csv" "$tmp/gq.csv" -k 2 >"$tmp/got" 2>&1
rc=$?
if [ "$rc" -eq 3 ] && grep -q 'not supported' "$tmp/got"; then
  echo "geo: built without geodesic support; checking only the error"
  passes=$((passes + 1))
else
  printf 'query,rank,point,metres\n0,1,0,55659.745396636783\n0,2,1,55659.745396636783\n' >"$tmp/want"
  same "geo knn" "$tmp/got" "$tmp/want"
  "$cli" geo radius "$tmp/g.csv" "$tmp/gq.csv" -r 60000 >"$tmp/got"
  printf 'query,point,metres\n0,0,55659.745396636783\n0,1,55659.745396636783\n' >"$tmp/want"
  same "geo radius" "$tmp/got" "$tmp/want"
  printf '0,91\n' >"$tmp/lat.csv"
  expect 1 'lat.csv:1: latitude 91 is outside' -- "$cli" geo knn "$tmp/g.csv" "$tmp/lat.csv" -k 1
fi
expect 2 'unknown geo query' -- "$cli" geo nearest "$tmp/g.csv" "$tmp/gq.csv"
expect 2 '-r R is required' -- "$cli" geo radius "$tmp/g.csv" "$tmp/gq.csv"

# Usage errors, --help, bad input, output files.
for c in knn range radius locate collide raycast geo; do
  expect 0 "usage: quadkit $c" -- "$cli" $c --help
done
# no wider than knn's (raycast's --keep line ran to 101 columns once it named box)
same_text "raycast --help width" "$("$cli" raycast --help | awk 'length > 85')" ""
expect 2 '-k K is required' -- "$cli" knn "$tmp/p.csv" "$tmp/q.csv"
expect 2 'must be a whole number' -- "$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 0
expect 2 'must not be negative' -- "$cli" radius "$tmp/p.csv" "$tmp/q.csv" -r -1
expect 2 'unknown option' -- "$cli" range "$tmp/p.csv" "$tmp/b.csv" --bogus
expect 2 'usage' -- "$cli" radius "$tmp/p.csv"
printf '0,0\n1,oops\n' >"$tmp/bad.csv"
expect 1 'bad.csv:2:3: field 2 is not a number' -- "$cli" knn "$tmp/p.csv" "$tmp/bad.csv" -k 1
expect 1 'cannot open' -- "$cli" locate "$tmp/p.csv" "$tmp/missing.csv"
expect 0 '' -- "$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 1 -o "$tmp/out.csv"
grep -q '^1,1,3,' "$tmp/out.csv" && passes=$((passes + 1)) ||
  { echo "FAIL: -o file"; fails=$((fails + 1)); }
expect 1 'cannot write' -- "$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 1 -o "$tmp/no/dir/x.csv"
# whole numbers are digits only (a leading blank or a sign was taken, a trailing blank not)
for v in ' 3' '+3' '3 '; do
  expect 2 '--capacity must be a whole number from 1 to 4294967295' -- "$cli" locate "$tmp/p.csv" "$tmp/q.csv" --capacity "$v"
done
# a path that exists but whose directory takes no new file: the message says which file failed
if [ -f /proc/version ]; then
  expect 1 'cannot write /proc/version: .*temporary file /proc/version[.]tmp' -- "$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 1 -o /proc/version
fi

# --xy by name and number, --query-xy, and --keep joining the input rows.
printf 'name,lat,lon\nParis,48.85,2.35\n"Rome, Lazio",41.9,12.5\nOslo,59.91,10.75\n' >"$tmp/c.csv"
printf 'lon,lat,tag\n12,42,a\n3,49,b\n' >"$tmp/cq.csv"
"$cli" knn "$tmp/c.csv" "$tmp/cq.csv" -k 1 --xy lon,lat --keep both >"$tmp/got"
cat >"$tmp/want" <<'EOF'
query,rank,point,distance,query_lon,query_lat,query_tag,point_name,point_lat,point_lon
0,1,1,0.50990195135927874,12,42,a,"Rome, Lazio",41.9,12.5
1,1,0,0.66708320320631631,3,49,b,Paris,48.85,2.35
EOF
same "knn --xy --keep both" "$tmp/got" "$tmp/want"
"$cli" knn "$tmp/c.csv" "$tmp/cq.csv" -k 1 --xy 3,2 --query-xy 1,2 --keep point >"$tmp/got"
printf 'query,rank,point,distance,point_name,point_lat,point_lon\n0,1,1,0.50990195135927874,"Rome, Lazio",41.9,12.5\n1,1,0,0.66708320320631631,Paris,48.85,2.35\n' >"$tmp/want"
same "knn --xy numbers --query-xy --keep point" "$tmp/got" "$tmp/want"
# Rows of different widths are padded; files without a header get numbered names.
printf '0,0,x\n1,1\n' >"$tmp/np.csv"
printf '0.9,0.9\n' >"$tmp/nq.csv"
"$cli" radius "$tmp/np.csv" "$tmp/nq.csv" -r 2 --keep both >"$tmp/got"
printf 'query,point,distance,query_1,query_2,point_1,point_2,point_3\n0,0,1.2727922061357855,0.9,0.9,0,0,x\n0,1,0.14142135623730948,0.9,0.9,1,1,\n' >"$tmp/want"
same "radius --keep both, no header" "$tmp/got" "$tmp/want"
printf 'xmin,ymin,xmax,ymax\n0,40,13,45\n' >"$tmp/b2.csv"
"$cli" range "$tmp/c.csv" "$tmp/b2.csv" --xy lon,lat --keep both >"$tmp/got"
printf 'box,point,box_xmin,box_ymin,box_xmax,box_ymax,point_name,point_lat,point_lon\n0,1,0,40,13,45,"Rome, Lazio",41.9,12.5\n' >"$tmp/want"
same "range --keep both" "$tmp/got" "$tmp/want"
"$cli" locate "$tmp/c.csv" "$tmp/cq.csv" --xy lon,lat --keep query >"$tmp/got"
if grep -q '^query,xmin,ymin,side,depth,count,query_lon,query_lat,query_tag$' "$tmp/got" &&
  grep -q ',12,42,a$' "$tmp/got"; then passes=$((passes + 1)); else fail "locate --keep query: $(cat "$tmp/got")"; fi
"$cli" raycast "$tmp/d.csv" "$tmp/r.csv" --keep ray >"$tmp/got"
if grep -q '^ray,disc,t,ray_ox,ray_oy,ray_dx,ray_dy,ray_tmax$' "$tmp/got" &&
  grep -q '^2,-1,inf,5,3,0,1,1$' "$tmp/got"; then passes=$((passes + 1)); else fail "raycast --keep ray: $(cat "$tmp/got")"; fi
printf 'xmin,ymin,xmax,ymax\n4,-1,6,1\n' >"$tmp/rb.csv"
printf 'ox,oy,dx,dy\n0,0,1,0\n' >"$tmp/rr.csv"
"$cli" raycast "$tmp/rb.csv" "$tmp/rr.csv" --boxes --keep box >"$tmp/got"
printf 'ray,box,t,box_xmin,box_ymin,box_xmax,box_ymax\n0,0,4,4,-1,6,1\n' >"$tmp/want"
same "raycast --boxes --keep box" "$tmp/got" "$tmp/want"
expect 2 "--keep takes ray, box or both, not 'disc'" -- "$cli" raycast "$tmp/rb.csv" "$tmp/rr.csv" --boxes --keep disc
"$cli" collide "$tmp/d.csv" --keep both >"$tmp/got"
if grep -q '^0,1,0,0,1,2,0,1$' "$tmp/got"; then passes=$((passes + 1)); else fail "collide --keep both: $(cat "$tmp/got")"; fi
expect 2 "--keep takes query, point or both, not 'box'" -- "$cli" knn "$tmp/c.csv" "$tmp/cq.csv" -k 1 --keep box
expect 2 "--keep takes query, not 'point'" -- "$cli" locate "$tmp/c.csv" "$tmp/cq.csv" --keep point
expect 1 "c.csv:1: no column named 'x'" -- "$cli" knn "$tmp/c.csv" "$tmp/cq.csv" -k 1 --xy x,y
expect 2 "unknown option '--xy'" -- "$cli" collide "$tmp/d.csv" --xy 1,2
expect 2 "unknown option '--query-xy'" -- "$cli" range "$tmp/c.csv" "$tmp/b2.csv" --query-xy 1,2

# kNN where squared distances would overflow: refused, naming the point, not answered wrong.
printf '3e154,0\n2e154,0\n' >"$tmp/bigp.csv"
printf '0,0\n' >"$tmp/bigq.csv"
expect 1 "bigp.csv:1: point \\(3.0000000000000003e\\+154, 0\\) is beyond 2\\^510" -- \
  "$cli" knn "$tmp/bigp.csv" "$tmp/bigq.csv" -k 1
printf '3e150,0\n2e150,0\n' >"$tmp/bigp.csv"
expect 0 '^0,1,1,2e\+150$' -- "$cli" knn "$tmp/bigp.csv" "$tmp/bigq.csv" -k 1

# An empty or header-only file of queries is an empty batch for every query command: the
# header line alone, exit 0. An empty file of points is an error.
: >"$tmp/noq.csv"
printf 'x,y\n' >"$tmp/hdrq.csv"
for f in noq hdrq; do
  for opts in "knn -k 1" "radius -r 1" "locate"; do
    read -r -a args <<<"$opts"
    "$cli" "${args[0]}" "$tmp/p.csv" "$tmp/$f.csv" "${args[@]:1}" >"$tmp/got" 2>&1
    rc=$?
    if [ "$rc" -ne 0 ] || [ "$(wc -l <"$tmp/got")" -ne 1 ]; then
      fail "$opts on $f.csv: exit $rc, output $(cat "$tmp/got") (want the header alone)"
    else
      passes=$((passes + 1))
    fi
  done
done
expect 1 'noq.csv: no data rows' -- "$cli" knn "$tmp/noq.csv" "$tmp/q.csv" -k 1

report
