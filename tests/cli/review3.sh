#!/usr/bin/env bash
# CLI regressions from a third review (one block per finding; each failed before its fix):
# lon/lat rings with an edge across the whole map (whole world, a polar cap, a band)
# enclosed nothing; locate, tree and regions printed a root corner of -0.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# ---- edges from -180 to 180 along one latitude: across the map, or a step (Fiji) -------
# The oracle: each feature is a latitude range (minus a hole), so the answer follows from
# a point's latitude alone.
printf '{"type":"FeatureCollection","features":[
{"type":"Feature","properties":{"n":"cap60"},"geometry":{"type":"Polygon","coordinates":[[[-180,60],[180,60],[180,90],[-180,90],[-180,60]]]}},
{"type":"Feature","properties":{"n":"world"},"geometry":{"type":"Polygon","coordinates":[[[-180,-90],[180,-90],[180,90],[-180,90],[-180,-90]],[[0,30],[10,30],[10,40],[0,40],[0,30]]]}},
{"type":"Feature","properties":{"n":"band"},"geometry":{"type":"Polygon","coordinates":[[[-180,-10],[180,-10],[180,0],[180,10],[-180,10],[-180,10],[-180,-10]]]}},
{"type":"Feature","properties":{"n":"circle"},"geometry":{"type":"Polygon","coordinates":[[[-180,-60],[-90,-60],[0,-60],[90,-60],[180,-60],[-180,-60]]]}},
{"type":"Feature","properties":{"n":"fiji"},"geometry":{"type":"Polygon","coordinates":[[[179,-17],[180,-17],[-180,-17],[-179,-17],[-179,-16],[-180,-16],[180,-16],[179,-16],[179,-17]]]}},
{"type":"Feature","properties":{"n":"ant10m"},"geometry":{"type":"Polygon","coordinates":[[[-180,-80],[-90,-75],[0,-70],[90,-75],[180,-80],[180,-90],[-180,-90],[-180,-80]]]}}]}\n' >"$tmp/wide.geojson"
printf 'lon,lat\n0,70\n-179.5,89\n179.5,61\n5,35\n5,45\n100,5\n-100,-5\n0,-65\n179.5,-16.5\n-179.5,-16.5\n0,-16.5\n0,-85\n' >"$tmp/wide.csv"
same_text "lon/lat edges across the whole map" \
  "$("$cli" join "$tmp/wide.geojson" "$tmp/wide.csv" --all --field n | tr '\n' ' ')" \
  "lon,lat,feature,n 0,70,0,cap60 0,70,1,world -179.5,89,0,cap60 -179.5,89,1,world 179.5,61,0,cap60 179.5,61,1,world 5,35,-1, 5,45,1,world 100,5,1,world 100,5,2,band -100,-5,1,world -100,-5,2,band 0,-65,1,world 0,-65,3,circle 179.5,-16.5,1,world 179.5,-16.5,4,fiji -179.5,-16.5,1,world -179.5,-16.5,4,fiji 0,-16.5,1,world 0,-85,1,world 0,-85,3,circle 0,-85,5,ant10m "
# a point on the band's edge along latitude 10 is on its ring: in under closed, out under open
printf 'lon,lat\n50,10\n' >"$tmp/edge.csv"
same_text "band edge closed" "$("$cli" join "$tmp/wide.geojson" "$tmp/edge.csv" --all --boundary closed | tail -n +2 | tr '\n' ' ')" \
  "50,10,1 50,10,2 "
same_text "band edge open" "$("$cli" join "$tmp/wide.geojson" "$tmp/edge.csv" --all --boundary open | tail -n +2 | tr '\n' ' ')" \
  "50,10,1 "

# Natural Earth (no such edge): points known to be in Antarctica, in Russia east of 180
# and in Fiji on both sides of it; the coarse 1:50m coast puts Uelen in the sea (checked
# with an even-odd count over the rings unwrapped across the antimeridian).
data=${QK_SHARED_DIR:-$src/../shared}/data/countries-50m.geojson
if [ -f "$data" ]; then
  printf 'lon,lat\n106.84,-78.46\n0,-85\n-173.2,64.42\n-169.8,66.16\n179.3,-16.5\n-179.95,-16.45\n' >"$tmp/known.csv"
  same_text "countries-50m across the antimeridian" \
    "$("$cli" join "$data" "$tmp/known.csv" --field name | tr '\n' ' ')" \
    "lon,lat,feature,name 106.84,-78.46,239,Antarctica 0,-85,239,Antarctica -173.2,64.42,75,Russia -169.8,66.16,-1, 179.3,-16.5,170,Fiji -179.95,-16.45,170,Fiji "
fi

# ---- a root at -0 is printed as 0 ------------------------------------------------------
printf 'x,y\n-0.0,-0\n1,1\n' >"$tmp/negz.csv"
same_text "locate: no -0" "$("$cli" locate "$tmp/negz.csv" "$tmp/negz.csv" | tr '\n' ' ')" \
  "query,xmin,ymin,side,depth,count 0,0,0,1,0,2 1,0,0,1,0,2 "
expect 0 '"root": \{"x": 0, "y": 0, "side": 1\}' -- "$cli" tree "$tmp/negz.csv"
printf '{"type":"Polygon","coordinates":[[[-0.0,-0.0],[1,0],[1,1],[0,1],[-0.0,-0.0]]]}\n' >"$tmp/negz.geojson"
expect 0 '"bbox": \[0, 0, 1, 1\]' -- "$cli" regions "$tmp/negz.geojson" --planar --stats

# ---- numbers are decimal: strtod's hexadecimal is refused, naming line and value ---------
printf 'x,y\n0x10,1\n2,3\n' >"$tmp/hex.csv"
expect 1 "hex.csv:2:1: field 1 \\(x\\) is not a decimal number: '0x10'" -- "$cli" tree "$tmp/hex.csv"
expect 1 "hex.csv:2:1: field 1 \\(x\\) is not a decimal number: '0x10'" -- "$cli" knn "$tmp/negz.csv" "$tmp/hex.csv" -k 1
printf 'x,y\n1,-0X1p-3\n' >"$tmp/hexf.csv"
expect 1 "hexf.csv:2:3: field 2 \\(y\\) is not a decimal number: '-0X1p-3'" -- "$cli" tree "$tmp/hexf.csv"
# a first line of hexadecimal numbers is data (an error), not a header dropped in silence
printf '0x1,0x2\n0.5,0.5\n' >"$tmp/hexh.csv"
expect 1 "hexh.csv:1:1: field 1 is not a decimal number: '0x1'" -- "$cli" tree "$tmp/hexh.csv"
expect 1 "hexh.csv:1:1: field 1 is not a finite number: '0x1'" -- "$cli" join "$tmp/negz.geojson" "$tmp/hexh.csv" --planar
expect 1 "hex.csv:2:1: field 1 \\(x\\) is not a finite number: '0x10'" -- "$cli" join "$tmp/negz.geojson" "$tmp/hex.csv" --planar
# with a sign too: a first line "-0x1,-0x2" is data, not a header dropped in silence
# (the io/ mutation sweep: cli_number testing s[-1] for the sign passed every test)
printf -- '-0x1,-0x2\n0.5,0.5\n' >"$tmp/hexn.csv"
expect 1 "hexn.csv:1:1: field 1 is not a finite number: '-0x1'" -- "$cli" join "$tmp/negz.geojson" "$tmp/hexn.csv" --planar
printf 'id,kind,x,y,a,b\n1,disc,0x1,0,1,\n' >"$tmp/hexo.csv"
printf 'frame,id,x,y\n' >"$tmp/nomoves.csv"
expect 1 "hexo.csv:2:8: not a decimal number: '0x1'" -- "$cli" world "$tmp/hexo.csv" "$tmp/nomoves.csv"
printf 'id,kind,x,y,a,b\n1,disc,1,0,1,0x3\n' >"$tmp/hexu.csv"
expect 1 "hexu.csv:2:14: field '0x3' is not used" -- "$cli" world "$tmp/hexu.csv" "$tmp/nomoves.csv"
expect 2 "-r must be a finite number, not '0x1'" -- "$cli" radius "$tmp/negz.csv" "$tmp/negz.csv" -r 0x1
printf '4 2 0 0\n0 0 0\n1 4 0\n2 4 4\n3 0 4\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/sq.poly"
expect 2 "--round 0x1p-4: the grid step must be a positive number" -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/r" --round 0x1p-4
# decimal forms strtod and CSV tools share still read: .5, 5., +1, exponents
printf 'x,y\n.5,5.\n+1,2e-1\n' >"$tmp/dec.csv"
same_text "decimal forms" "$("$cli" knn "$tmp/dec.csv" "$tmp/dec.csv" -k 1 | tr '\n' ' ')" \
  "query,rank,point,distance 0,1,0,0 1,1,1,0 "

# ---- GeoJSON: what json-c's strict mode lets through but RFC 8259 does not -------------
# A name twice in one object: json-c (like GDAL and Python) keeps the last, so the first
# polygon was dropped without a word; NaN, Infinity and "1." are not JSON numbers.
printf 'x,y\n0.5,0.5\n5.5,5.5\n' >"$tmp/two.csv"
printf '{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]],\n "coordinates":[[[5,5],[6,5],[6,6],[5,6],[5,5]]]}\n' >"$tmp/dupc.geojson"
expect 1 'dupc.geojson:2:2: duplicate name "coordinates" in one object \(first at line 1, column 19' -- "$cli" join "$tmp/dupc.geojson" "$tmp/two.csv" --planar
printf '{"type":"Feature","properties":{"s":"a \\"s\\": \\\\","s":1},"geometry":null}\n' >"$tmp/dupp.geojson"
expect 1 'dupp.geojson:1:51: duplicate name "s" in one object \(first at line 1, column 33' -- "$cli" join "$tmp/dupp.geojson" "$tmp/two.csv" --planar
expect 1 'dupc.geojson:2:2: duplicate name "coordinates"' -- "$cli" mesh "$tmp/dupc.geojson" -o "$tmp/m"
# the same name in different objects, and names inside strings, are fine
printf '{"type":"Feature","properties":{"a":{"a":1,"b":{"a":2}},"c":[{"a":1},{"a":1}],"t":"\\"a\\": 1, \\"a\\": 2"},"geometry":{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}}\n' >"$tmp/nodup.geojson"
same_text "same names in different objects" "$("$cli" join "$tmp/nodup.geojson" "$tmp/two.csv" --planar | tr '\n' ' ')" \
  "x,y,feature 0.5,0.5,0 5.5,5.5,-1 "
for v in NaN -Infinity Infinity; do
  printf '{"type":"Polygon","coordinates":[[[0,0],[%s,0],[1,1],[0,1],[0,0]]]}\n' "$v" >"$tmp/nan.geojson"
  expect 1 "nan.geojson:1:4[23]: malformed JSON: ${v#-} is not a JSON number" -- "$cli" join "$tmp/nan.geojson" "$tmp/two.csv" --planar
done
printf '{"type":"Feature","properties":{"v":NaN},"geometry":null}\n' >"$tmp/nanp.geojson"
expect 1 'nanp.geojson:1:37: malformed JSON: NaN is not a JSON number' -- "$cli" join "$tmp/nanp.geojson" "$tmp/two.csv" --planar
printf '{"type":"Polygon","coordinates":[[[0,0],[1.,0],[1,1],[0,1],[0,0]]]}\n' >"$tmp/dot.geojson"
expect 1 'dot.geojson:1:43: malformed JSON: a decimal point must be followed by digits' -- "$cli" join "$tmp/dot.geojson" "$tmp/two.csv" --planar

# ---- a device output that fails says so (it exited 3 without a word) ---------------------
if [ -w /dev/full ]; then
  expect 3 'quadkit knn: cannot write /dev/full: No space left on device' -- "$cli" knn "$tmp/two.csv" "$tmp/two.csv" -k 1 -o /dev/full
  expect 3 'quadkit tree: cannot write /dev/full' -- "$cli" tree "$tmp/two.csv" --svg /dev/full
  expect 3 'quadkit regions: cannot write /dev/full' -- "$cli" regions "$tmp/negz.geojson" --planar --svg /dev/full
  expect 3 'quadkit join: cannot write /dev/full' -- "$cli" join "$tmp/negz.geojson" "$tmp/two.csv" --planar -o /dev/full
  # join said "out of memory or write error" after the real reason
  out=$("$cli" join "$tmp/negz.geojson" "$tmp/two.csv" --planar 2>&1 >/dev/full)
  same_text "join to a full stdout: one message" "$out" "quadkit join: cannot write standard output: No space left on device"
fi

# ---- world keeps its own field splitter (ids are 64-bit, kinds are text): same quoting ---
printf 'id,kind,x,y,a,b\n"1", "disc" ,"0",0,"1",""\n2,disc,1.5,0,1,\n' >"$tmp/qo.csv"
printf 'frame,id,x,y,a\n' >"$tmp/mv0.csv"
same_text "world: quoted fields" "$("$cli" world "$tmp/qo.csv" "$tmp/mv0.csv" | tr '\n' ' ')" "frame,a,b 0,1,2 "
printf 'id,kind,x,y,a,b\n"1,disc,0,0,1,\n' >"$tmp/qo2.csv"
expect 1 'qo2.csv:2: unterminated quoted field' -- "$cli" world "$tmp/qo2.csv" "$tmp/mv0.csv"
printf 'id,kind,x,y,a,b\n"1"x,disc,0,0,1,\n' >"$tmp/qo3.csv"
expect 1 'qo3.csv:2: text after a closing quote' -- "$cli" world "$tmp/qo3.csv" "$tmp/mv0.csv"

# ---- join --help says what --threads 0 means (it was accepted, undocumented) -------------
expect 0 '--threads N answers on N threads' -- "$cli" join --help
# a bad --threads is a usage error (exit 2), not a message on a run that goes on and
# succeeds (the io/ mutation sweep: join without its rc = CLI_USAGE passed every test)
expect 2 "--threads must be a whole number from 0 to 256, not '999'" -- "$cli" join "$tmp/negz.geojson" "$tmp/negz.csv" --planar --threads 999
expect 0 '0: one per core' -- "$cli" join --help

# ---- knn beyond 2^510: the error before the header (it came after the header and rows) -
printf 'x,y\n0,0\n1,1\n' >"$tmp/sm.csv"
printf 'x,y\n0,0\n1e200,0\n' >"$tmp/far.csv"
expect 1 'far.csv:3: query \(9.9999999999999997e\+199, 0\) is beyond 2\^510' -- "$cli" knn "$tmp/sm.csv" "$tmp/far.csv" -k 1
same_text "knn beyond 2^510: nothing on stdout" "$("$cli" knn "$tmp/sm.csv" "$tmp/far.csv" -k 1 2>/dev/null)" ""
printf 'x,y\n1e300,-1e300\n1e300,-1e300\n' >"$tmp/farp.csv"
same_text "knn, points beyond 2^510: nothing on stdout" "$("$cli" knn "$tmp/farp.csv" "$tmp/sm.csv" -k 1 2>/dev/null)" ""
printf 'x,y\n3e153,0\n' >"$tmp/near.csv"
same_text "knn just inside 2^510" "$("$cli" knn "$tmp/near.csv" "$tmp/near.csv" -k 1 | tr '\n' ' ')" \
  "query,rank,point,distance 0,1,0,0 "

# ---- join --xy with a huge column number said it "must be at least 1" --------------------
expect 2 '--xy: column number 99999999999999999999 must be from 1 to 100000' -- "$cli" join "$tmp/negz.geojson" "$tmp/sm.csv" --planar --xy 99999999999999999999,1
expect 2 '--xy: column number 0 must be from 1 to 100000' -- "$cli" join "$tmp/negz.geojson" "$tmp/sm.csv" --planar --xy 0,1

# ---- .poly numbers are decimal too; a mesh vertex at -0 is written 0 -----------------------
printf '4 2 0 0\n0 0 0\n1 0x4 0\n2 4 4\n3 0 4\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/hx.poly"
expect 1 "hx.poly:3: vertex 1: bad x coordinate '0x4'" -- "$cli" mesh "$tmp/hx.poly" -o "$tmp/hxm"
[ ! -e "$tmp/hxm.node" ] || fail "hx.poly: a .node file was written"
printf '4 2 0 0\n0 -0 -0\n1 4 0\n2 4 4\n3 0 4\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/nz.poly"
expect 0 '' -- "$cli" mesh "$tmp/nz.poly" -o "$tmp/nzm"
same_text "mesh: no -0 in .node" "$(grep -c -- '-0\b' "$tmp/nzm.node")" "0"
same_text "mesh: the corner at 0 0" "$(awk 'NR > 1 && $2 == "0" && $3 == "0"' "$tmp/nzm.node" | wc -l)" "1"

# ---- raycast far from the origin: a unit disc hit from 1e300 away had t = inf ------------
printf 'x,y,r\n0,0,1\n' >"$tmp/d1.csv"
printf 'ox,oy,dx,dy\n1e300,1e300,-1e300,-1e300\n1e200,0,-1,0\n' >"$tmp/far_rays.csv"
same_text "raycast from far away" "$("$cli" raycast "$tmp/d1.csv" "$tmp/far_rays.csv" | tr '\n' ' ')" \
  "ray,disc,t 0,0,1 1,0,9.9999999999999997e+199 "

report
