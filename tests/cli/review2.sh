#!/usr/bin/env bash
# CLI regressions from a second review hunting wrong answers (one block per finding):
# `join --boundary closed|open` on the antimeridian missed the rings that end at longitude
# 180 (queries map 180 to -180); a points file with a byte order mark, CRLF line ends and
# trailing empty lines answers as the plain file does.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- the antimeridian under closed and open: E = [170, 180] x [0, 10], W = its mirror ----
printf '{"type":"FeatureCollection","features":[
{"type":"Feature","properties":{"n":"E"},"geometry":{"type":"Polygon","coordinates":[[[170,0],[180,0],[180,10],[170,10],[170,0]]]}},
{"type":"Feature","properties":{"n":"W"},"geometry":{"type":"Polygon","coordinates":[[[-180,0],[-170,0],[-170,10],[-180,10],[-180,0]]]}}]}\n' >"$tmp/am.geojson"
printf 'lon,lat\n180,5\n-180,5\n175,5\n180,15\n' >"$tmp/am.csv"
same_text "join closed on the antimeridian" \
  "$("$cli" join "$tmp/am.geojson" "$tmp/am.csv" --boundary closed --all --field n | tr '\n' ' ')" \
  "lon,lat,feature,n 180,5,0,E 180,5,1,W -180,5,0,E -180,5,1,W 175,5,0,E 180,15,-1, "
same_text "join open on the antimeridian" \
  "$("$cli" join "$tmp/am.geojson" "$tmp/am.csv" --boundary open --field n | tr '\n' ' ')" \
  "lon,lat,feature,n 180,5,-1, -180,5,-1, 175,5,0,E 180,15,-1, "
same_text "join semi-open on the antimeridian" \
  "$("$cli" join "$tmp/am.geojson" "$tmp/am.csv" --field n | tr '\n' ' ')" \
  "lon,lat,feature,n 180,5,1,W -180,5,1,W 175,5,0,E 180,15,-1, "

# ---- BOM, CRLF and trailing empty lines: the same answers as the plain file ------------
printf 'x,y\n0.5,0.5\n1,1\n-0.0,0.25\n' >"$tmp/plain.csv"
printf '\xef\xbb\xbfx,y\r\n0.5,0.5\r\n1,1\r\n-0.0,0.25\r\n\r\n\r\n' >"$tmp/dos.csv"
for c in "locate" "knn -k 2" "radius -r 0.5"; do
  # shellcheck disable=SC2086
  same_text "$c: BOM and CRLF" "$("$cli" $c "$tmp/dos.csv" "$tmp/dos.csv")" \
    "$("$cli" $c "$tmp/plain.csv" "$tmp/plain.csv")"
done
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}\n' >"$tmp/sq.geojson"
same_text "join: BOM and CRLF" "$("$cli" join "$tmp/sq.geojson" "$tmp/dos.csv" --planar | tr '\n' ' ')" \
  "x,y,feature 0.5,0.5,0 1,1,-1 -0.0,0.25,0 "
printf 'x,y\n0,0\nnan,1\n' >"$tmp/bad.csv"
expect 1 'bad.csv:3:1: field 1 \(x\) is not a finite number' -- "$cli" join "$tmp/sq.geojson" "$tmp/bad.csv" --planar
# standard output cannot be taken back: a bad line stops join before the header or any row
same_text "join: nothing on stdout before a bad line" \
  "$("$cli" join "$tmp/sq.geojson" "$tmp/bad.csv" --planar 2>/dev/null)" ""
printf 'x,y\n0.5,0.5\n' >"$tmp/good.csv"
same_text "join: a good file after the check" \
  "$("$cli" join "$tmp/sq.geojson" "$tmp/good.csv" --planar | tr '\n' ' ')" "x,y,feature 0.5,0.5,0 "
same_text "join: from a pipe" \
  "$(cat "$tmp/good.csv" | "$cli" join "$tmp/sq.geojson" /dev/stdin --planar | tr '\n' ' ')" "x,y,feature 0.5,0.5,0 "

report
