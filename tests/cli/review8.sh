#!/usr/bin/env bash
# CLI regressions from an eighth review (seventeenth session): a quoted field that holds
# line breaks, and hostile inputs on commands not reviewed recently (one block per
# finding; each failed before its fix).
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- a quoted field with line breaks (RFC 4180) -----------------------------------------
# The record spans lines 2-3; a break inside quotes in a column not read ended the record
# there, so "5,6," was read as a point the file does not have. Now the record is whole and
# every message names the physical line where its row starts.
printf 'x,y,note\n1,2,"a\n5,6,"\n3,4,ok\n' >"$tmp/ml.csv"
same_text "tree: a multi-line field" "$("$cli" tree "$tmp/ml.csv" | grep -o '"points": [0-9]*')" \
  '"points": 2'
printf 'x,y,note\n1,2,"a\n5,6,"\n3,4,ok\nnan,4,z\n' >"$tmp/ml-bad.csv"
expect 1 "^quadkit: $tmp/ml-bad.csv:5:1: field 1 \\(x\\) is not finite: 'nan'$" -- "$cli" tree "$tmp/ml-bad.csv"
# an error in a field that starts on the record's second line names that line and column
printf 'name,x,y\n"A\nB",1,zz\n' >"$tmp/ml-col.csv"
expect 1 "^quadkit: $tmp/ml-col.csv:3:6: field 3 \\(y\\) is not a number: 'zz'$" \
  -- "$cli" tree "$tmp/ml-col.csv" --xy x,y
# a quote left open in a column not read would take every later row: an error
printf '0,0,"open\n1,2,x\n3,4,y\n' >"$tmp/ml-open.csv"
expect 1 "^quadkit: $tmp/ml-open.csv:1:5: field 3: unterminated quoted field \\(it runs to the end of the file\\)$" \
  -- "$cli" tree "$tmp/ml-open.csv"
# --keep copies the record whole (a valid CSV field with its break)
printf 'x,y\n0,0\n' >"$tmp/q.csv"
same_text "knn --keep: a multi-line field" \
  "$("$cli" knn "$tmp/ml.csv" "$tmp/q.csv" -k 2 --keep point | tr '\n' '|')" \
  'query,rank,point,distance,point_x,point_y,point_note|0,1,0,2.2360679774997898,1,2,"a|5,6,"|0,2,1,5,3,4,ok|'
# join reads points with its own reader: the same records and line numbers
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"n":"A"},"geometry":{"type":"Polygon","coordinates":[[[0,0],[10,0],[10,10],[0,10],[0,0]]]}}]}\n' >"$tmp/sq.geojson"
same_text "join: a multi-line field" \
  "$("$cli" join "$tmp/sq.geojson" "$tmp/ml.csv" --field n | tr '\n' '|')" \
  'x,y,note,feature,n|1,2,"a|5,6,",0,A|3,4,ok,0,A|'
expect 1 "^quadkit join: $tmp/ml-bad.csv:5:1: field 1 \\(x\\) is not a finite number: 'nan'$" \
  -- "$cli" join "$tmp/sq.geojson" "$tmp/ml-bad.csv"
expect 1 "^quadkit join: $tmp/ml-open.csv:1:5: field 3: unterminated quoted field \\(it runs to the end of the file\\)$" \
  -- "$cli" join "$tmp/sq.geojson" "$tmp/ml-open.csv"
printf 'x,y\n1,1\n2,2\n3,"3\n' >"$tmp/ml-open2.csv"
expect 1 "^quadkit join: $tmp/ml-open2.csv:4:3: field 2: unterminated quoted field" -- "$cli" join "$tmp/sq.geojson" "$tmp/ml-open2.csv"
printf 'x,y,n\n1,1,"a\r\nb"\r\n2,2\x00,c\n' >"$tmp/ml-nul.csv"
expect 1 "^quadkit join: $tmp/ml-nul.csv:4:4: binary data \\(NUL byte\\) in a text file$" \
  -- "$cli" join "$tmp/sq.geojson" "$tmp/ml-nul.csv"

# ---- join --boundary open on the antimeridian -------------------------------------------
# The whole world's sides along -180 and +180 are one meridian on the sphere: a point on
# it is inside under `open` (it was in no feature).
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"n":"W"},"geometry":{"type":"Polygon","coordinates":[[[-180,-90],[180,-90],[180,90],[-180,90],[-180,-90]]]}}]}\n' >"$tmp/world.geojson"
printf 'x,y\n180,5\n-180,0\n540,-45\n0,0\n' >"$tmp/am.csv"
same_text "join --boundary open: the antimeridian in the whole world" \
  "$("$cli" join "$tmp/world.geojson" "$tmp/am.csv" --boundary open | tr '\n' ' ')" \
  "x,y,feature 180,5,0 -180,0,0 540,-45,0 0,0,0 "

report
