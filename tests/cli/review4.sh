#!/usr/bin/env bash
# CLI regressions from a fourth review, on inputs not tried before (one block per finding;
# each failed before its fix): GeoJSON numbers json-c cannot read exactly, mesh -o paths.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- GeoJSON: an overflowing number is named as written (it said "(inf, 0)") -------------
printf 'x,y\n0.5,0.5\n' >"$tmp/half.csv"
printf '{"type":"Polygon","coordinates":[[[0,0],[2e308,0],[1,1],[0,1],[0,0]]]}\n' >"$tmp/ovf.geojson"
expect 1 'ovf.geojson:1:42: feature 0: coordinate 2e308 is beyond the largest double \(not finite\) at polygon 0, ring 0, position 1$' \
  -- "$cli" join "$tmp/ovf.geojson" "$tmp/half.csv" --planar
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,-1E+999],[0,1],[0,0]]]}\n' >"$tmp/ovf2.geojson"
expect 1 'ovf2.geojson:1:50: feature 0: coordinate -1E\+999 is beyond the largest double' \
  -- "$cli" mesh "$tmp/ovf2.geojson" -o "$tmp/ovf2"
[ ! -e "$tmp/ovf2.node" ] || fail "ovf2.geojson: a .node file was written"

# ---- GeoJSON: integers beyond 64 bits were clamped by json-c 0.16 without a word ---------
# [0, 1e20] x [0, 1] written with integers became [0, 2^64 - 1]: (5e19, 0.5) was outside.
printf '{"type":"Polygon","coordinates":[[[0,0],[100000000000000000000,0],[100000000000000000000,1],[0,1],[0,0]]]}\n' >"$tmp/bigint.geojson"
printf 'x,y\n5e19,0.5\n' >"$tmp/big.csv"
expect 1 'bigint.geojson:1:42: feature 0, polygon 0, ring 0, position 1: integer 100000000000000000000 is outside the 64-bit range json-c reads exactly' \
  -- "$cli" join "$tmp/bigint.geojson" "$tmp/big.csv" --planar
# A property is text: such an integer there is kept as written (robust24; it refused the
# whole file), in an object too.
printf '{"type":"Feature","properties":{"v":-9223372036854775809,"o":{"a":[200000000000000000000]}},"geometry":{"type":"Polygon","coordinates":[[[0,0],[1e20,0],[1e20,1],[0,1],[0,0]]]}}\n' >"$tmp/bigp.geojson"
same_text "a property beyond 64 bits" "$("$cli" join "$tmp/bigp.geojson" "$tmp/big.csv" --planar --field v --field o | tail -1)" \
  '5e19,0.5,0,-9223372036854775809,"{""a"":[200000000000000000000]}"'
# the same polygon with an exponent, and integers at the 64-bit limits, read exactly
sed 's/100000000000000000000/1e20/g' "$tmp/bigint.geojson" >"$tmp/bige.geojson"
same_text "1e20 with an exponent" "$("$cli" join "$tmp/bige.geojson" "$tmp/big.csv" --planar | tr '\n' ' ')" \
  "x,y,feature 5e19,0.5,0 "
printf '{"type":"Feature","properties":{"u":18446744073709551615,"v":-9223372036854775808,"w":-000000000000000000001,"f":1.00000000000000000000001},"geometry":{"type":"Polygon","coordinates":[[[0,0],[18446744073709551615,0],[18446744073709551615,1],[0,1],[0,0]]]}}\n' >"$tmp/lim.geojson"
printf 'x,y\n1.8e19,0.5\n1.9e19,0.5\n' >"$tmp/lim.csv"
same_text "integers at the 64-bit limits" \
  "$("$cli" join "$tmp/lim.geojson" "$tmp/lim.csv" --planar --field u --field v --field w | tr '\n' ' ')" \
  "x,y,feature,u,v,w 1.8e19,0.5,0,18446744073709551615,-9223372036854775808,-1 1.9e19,0.5,-1,,, "

# ---- mesh -o PREFIX: checked before any work; a prefix with no file name is refused -------
printf '4 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/sq.poly"
printf '4 2 0 0\n0 0 0\n1 4 0\n' >"$tmp/trunc.poly"
# a bad output path is named before the input is even read (it was found after meshing)
expect 1 "quadkit mesh: cannot write $tmp/no/such/m.node: No such file or directory" \
  -- "$cli" mesh "$tmp/trunc.poly" -o "$tmp/no/such/m"
touch "$tmp/plain"
expect 1 "cannot write $tmp/plain/m.node: Not a directory" -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/plain/m"
expect 1 "cannot write $tmp/no/x.svg" -- "$cli" mesh "$tmp/trunc.poly" -o "$tmp/m" --svg "$tmp/no/x.svg"
[ ! -e "$tmp/m.node" ] && [ -z "$(ls "$tmp" | grep '\.tmp\.')" ] || fail "mesh: an output or temporary was left"
mkdir "$tmp/d"
expect 2 "-o PREFIX names the files PREFIX.node and PREFIX.ele, so it needs a file name: '$tmp/d/' ends in '/'" \
  -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/d/"
mkdir "$tmp/e"
expect 2 "needs a file name: '' is empty" -- bash -c 'cd "$1" && "$2" mesh ../sq.poly -o ""' - "$tmp/e" "$cli"
same_text "mesh -o DIR/: nothing in DIR" "$(ls -A "$tmp/d" "$tmp/e")" "$(printf "%s:\n\n%s:" "$tmp/d" "$tmp/e")"
# a read-only directory (root writes there anyway, so only as another user)
mkdir "$tmp/ro" && chmod 555 "$tmp/ro"
if [ ! -w "$tmp/ro" ]; then
  expect 1 "cannot write $tmp/ro/m.node: Permission denied" -- "$cli" mesh "$tmp/trunc.poly" -o "$tmp/ro/m"
fi
chmod 755 "$tmp/ro"
# a good run still writes every output, and the help says PREFIX is a prefix
expect 0 '' -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/d/m" --svg "$tmp/d/m.svg"
same_text "mesh outputs" "$(ls "$tmp/d" | tr '\n' ' ')" "m.ele m.node m.svg "
expect 0 '-o out/m writes out/m.node and out/m.ele' -- "$cli" mesh --help

# ---- join reads quotes as every other command does: "0.5"x and an open quote were 0.5 -----
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}\n' >"$tmp/sq.geojson"
printf 'x,y\n0.5,"0.5"x\n' >"$tmp/q1.csv"
printf 'x,y\n0.5,0.5\n0.25,"0.5\n' >"$tmp/q2.csv"
printf 'a,b,x,y\n"n"x,2,0.5,0.5\n' >"$tmp/q3.csv"
printf '"0.5"x,"0.5"y\n0.5,0.5\n' >"$tmp/q4.csv"
expect 1 'q1.csv:2:5: field 2: text after a closing quote' -- "$cli" join "$tmp/sq.geojson" "$tmp/q1.csv" --planar
expect 1 'q2.csv:3:6: field 2: unterminated quoted field' -- "$cli" join "$tmp/sq.geojson" "$tmp/q2.csv" --planar
expect 1 'q3.csv:2:1: field 1: text after a closing quote' -- "$cli" join "$tmp/sq.geojson" "$tmp/q3.csv" --planar --xy x,y
expect 1 'q4.csv:1:1: field 1: text after a closing quote' -- "$cli" join "$tmp/sq.geojson" "$tmp/q4.csv" --planar
# the library's reader says the same
expect 1 'q1.csv:2:5: field 2: text after a closing quote' -- "$cli" knn "$tmp/q1.csv" "$tmp/q1.csv" -k 1
expect 1 'q2.csv:3:6: field 2: unterminated quoted field' -- "$cli" knn "$tmp/q2.csv" "$tmp/q2.csv" -k 1
expect 1 'q3.csv:2:1: field 1: text after a closing quote' -- "$cli" knn "$tmp/q3.csv" "$tmp/q3.csv" -k 1 --xy x,y
# blanks around quotes are fine, as in the library's reader; a quoted header name still matches
printf 'x,"y"\n "0.5" , 0.25\n"1.5",0.5\n' >"$tmp/q5.csv"
same_text "join: blanks around quotes" "$("$cli" join "$tmp/sq.geojson" "$tmp/q5.csv" --planar --xy x,y | tr '\n' ' ')" \
  'x,"y",feature  "0.5" , 0.25,0 "1.5",0.5,-1 '
same_text "knn: blanks around quotes" "$("$cli" knn "$tmp/q5.csv" "$tmp/q5.csv" -k 1 --xy x,y | tr '\n' ' ')" \
  'query,rank,point,distance 0,1,0,0 1,1,1,0 '

report
