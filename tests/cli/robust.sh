#!/usr/bin/env bash
# CLI tests with hostile input and output paths, one regression per gap the twenty-fourth
# session's robustness sweep found: an output prefix that would make files in /dev or
# beside a device or FIFO, ... Every error must exit with its code (1 bad input, 2 usage,
# 3 internal) and leave nothing behind.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

printf '4 2 0 0\n1 0 0\n2 1 0\n3 1 1\n4 0 1\n4 0\n1 1 2\n2 2 3\n3 3 4\n4 4 1\n0\n' >"$tmp/sq.poly"

# ---- mesh -o PREFIX: PREFIX.node and PREFIX.ele are made beside PREFIX -----------------
# -o /dev/full left /dev/full.node and /dev/full.ele, regular files in /dev; a FIFO as
# the prefix left FIFO.node beside it. Both are usage errors before any work.
mkfifo "$tmp/fifo"
expect 2 "'[^']*fifo' is a FIFO, where they must not be made" -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/fifo"
nothing_written "$tmp/fifo"
had_node=0
[ -e /dev/full.node ] && had_node=1
expect 2 "'/dev/full' is a character device" -- "$cli" mesh "$tmp/sq.poly" -o /dev/full
if [ "$had_node" = 0 ] && [ -e /dev/full.node ]; then
  fail "mesh -o /dev/full made /dev/full.node"
else
  passes=$((passes + 1))
fi
# The rule is the directory /dev, not a path that starts with it.
expect 0 '' -- "$cli" mesh "$tmp/sq.poly" -o "$tmp/ok"
[ -s "$tmp/ok.node" ] && [ -s "$tmp/ok.ele" ] || fail "mesh -o $tmp/ok wrote no mesh"

# ---- join: a NUL byte or a lone CR in the points is named with its column --------------
sq='{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}'
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"name":"sq"},"geometry":%s}]}\n' "$sq" >"$tmp/sq.geojson"
printf 'x,y\n0.5,0\0000.5\n' >"$tmp/nul.csv"
expect 1 'nul.csv:2:6: binary data \(NUL byte\)' -- "$cli" join "$tmp/sq.geojson" "$tmp/nul.csv"
printf 'x,y\n0.5,0.5\n0.25,0.5\r0.5\n' >"$tmp/cr.csv"
expect 1 'cr.csv:3:9: a carriage return inside the line' -- "$cli" join "$tmp/sq.geojson" "$tmp/cr.csv"
# ... in a quoted field's second line: the column on that physical line
printf 'n,x,y\n"a\nbb\rb",0.5,0.5\n' >"$tmp/cr2.csv"
expect 1 'cr2.csv:3:3: a carriage return inside the line' -- "$cli" join "$tmp/sq.geojson" "$tmp/cr2.csv" --xy x,y

# ---- GeoJSON whose document is null or a bare number ----------------------------------
# json-c gives null as no object and waits for more after a number at the very end: the
# messages were "unexpected end of input" and "malformed JSON: success".
printf 'x,y\n0.5,0.5\n' >"$tmp/p.csv"
printf 'null' >"$tmp/null.geojson"
expect 1 'null.geojson:1:1: expected a GeoJSON object with a string "type", found null$' -- "$cli" regions "$tmp/null.geojson"
printf '  null\n' >"$tmp/null2.geojson"
expect 1 'null2.geojson:1:3: expected a GeoJSON object with a string "type", found null$' -- "$cli" join "$tmp/null2.geojson" "$tmp/p.csv"
printf '42' >"$tmp/num.geojson"
expect 1 'num.geojson:1:1: expected a GeoJSON object with a string "type"$' -- "$cli" regions "$tmp/num.geojson"
printf '[1' >"$tmp/open.geojson"
expect 1 'open.geojson:1:3: unexpected end of input$' -- "$cli" regions "$tmp/open.geojson"

# ---- mesh --field: every match counted; null reads as empty text ----------------------
sq2='{"type":"Polygon","coordinates":[[[2,0],[3,0],[3,1],[2,1],[2,0]]]}'
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"name":null},"geometry":%s},{"type":"Feature","properties":{"name":""},"geometry":%s}]}\n' "$sq" "$sq2" >"$tmp/two.geojson"
expect 0 '^quadkit mesh: --field name=: 2 features match; meshing the first, feature 0 \(--feature N takes another\)$' -- \
  "$cli" mesh "$tmp/two.geojson" --field name= -o "$tmp/two"
expect 0 '"features": 1' -- "$cli" mesh "$tmp/two.geojson" --field name= -o "$tmp/two" --stats
out=$("$cli" mesh "$tmp/sq.geojson" --field name=sq -o "$tmp/one" 2>&1)
same_text "mesh --field: one match, no note" "$out" ""

# ---- a signal that ends the process removes the temporaries ----------------------------
# Outputs are opened before the work (an unwritable path fails at once): a mesh killed
# while it waited for its input (here a FIFO nobody writes) left m.node.tmp.PID.0,
# m.ele.tmp.PID.1 and m.svg.tmp.PID.2 behind.
mkfifo "$tmp/wait.poly"
mkdir "$tmp/kill"
for sig in TERM INT HUP; do
  timeout -s "$sig" 1 "$cli" mesh "$tmp/wait.poly" -o "$tmp/kill/m" --svg "$tmp/kill/m.svg"
  left=$(ls "$tmp/kill")
  same_text "SIG$sig: nothing left in the output directory" "$left" ""
  rm -f "$tmp/kill/"*
done

# ---- join: a layer that runs out of memory is said once, naming the file ---------------
# An endless GeoJSON from a pipe (a FIFO named .geojson) under a 1 GB address-space limit:
# "quadkit join: FILE: out of memory reading FILE" was followed by a bare "quadkit join:
# out of memory". (Not under the sanitizers, which reserve more than the limit.) The text
# opens an object: one that does not is now refused at its first byte (review27.sh), and
# the 1 GB limit is reached before the reader's 2 GiB limit for a stream.
if [ "${QK_SANITIZE:-0}" != 1 ]; then
  mkfifo "$tmp/endless.geojson"
  printf 'x,y\n0.5,0.5\n' >"$tmp/p1.csv"
  (
    printf '{"type":"FeatureCollection","features":['
    yes '[0,0],'
  ) >"$tmp/endless.geojson" &
  writer=$!
  err=$(
    ulimit -v 1000000
    timeout 60 "$cli" join "$tmp/endless.geojson" "$tmp/p1.csv" 2>&1 >/dev/null
    echo "exit $?"
  )
  kill "$writer" 2>/dev/null
  wait "$writer" 2>/dev/null
  same_text "join: endless GeoJSON, out of memory said once" \
    "$(sed "s|$tmp/||g" <<<"$err" | tr '\n' '|')" \
    "quadkit join: endless.geojson: out of memory reading endless.geojson|exit 3|"
fi

report
