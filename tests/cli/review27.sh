#!/usr/bin/env bash
# CLI regressions from the twenty-seventh session: GeoJSON, CSV and .poly from a pipe that
# never ends.
# The GeoJSON readers (join's, through the library, and the mesher's) keep the whole text,
# so an endless text grew until the machine ran out of memory (24 GiB here). Now a text
# whose first value is not an object is refused at that value after one read, and a
# stream is read to at most 2^31 - 1 bytes (exit 1, the limit named). Every command runs
# under `timeout` and an address-space limit, so that a reader without these guards fails
# here (out of memory, exit 3, or the timeout) instead of filling the machine.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# limited KB CMD...: run CMD (a function here) under an address-space limit of KB
# kilobytes (not with the sanitizers, whose shadow memory needs the address space); the
# functions run quadkit under a timeout of $secs seconds: 60, or 180 with the sanitizers,
# under which the mesher read 2^31 bytes of a FIFO in 32.5 s on the AMD guest of the
# twenty-eighth session (it had 20 s then, and CI's ASan run failed on it).
secs=60
[ "${QK_SANITIZE:-0}" = 1 ] && secs=180
# once CMD...: a read of 2^31 bytes to the limit; run in Release (make test, where every
# reader's path is read to its limit), skipped under the sanitizers: each such read took
# 30 s there, and they made this script one of the longest of CI's ASan run (five: 149 s
# of its 321; the last two, 60 s of 70, in the thirty-sixth session), while the reading
# loop they repeat billions of times is the one the short inputs above run under ASan too.
once() {
  if [ "${QK_SANITIZE:-0}" = 1 ]; then
    skip "under the sanitizers, a read to the limit: ${*: -1}"
  else
    "$@"
  fi
}
# repeat CMD...: a read to the limit by a reader path another read here already took
# there (a stream of blanks into join's GeoJSON reader; the mesher's .poly from a pipe,
# kept by the line reader as the tree's CSV is): run with QK_TEST_LONG=1 only (each read
# is 12-15 s in Release; CI has 20 minutes for everything).
repeat() {
  if [ "${QK_TEST_LONG:-0}" = 1 ]; then
    once "$@"
  else
    skip "a read to the limit by a path read to it above (QK_TEST_LONG=1 runs it): ${*: -1}"
  fi
}
limited() {
  local kb=$1
  shift
  (
    [ "${QK_SANITIZE:-0}" = 1 ] || ulimit -v "$kb"
    "$@"
  )
}

printf 'x,y\n0.5,0.5\n' >"$tmp/p.csv"
coll='{"type":"FeatureCollection","features":['
feat='{"type":"Feature","properties":{},"geometry":null},'
limit='GeoJSON text from a pipe or device longer than 2147483647 bytes, the limit for a stream \(a regular file has none\)$'
obj='expected a GeoJSON object with a string "type"$'

# ---- the first value is not an object: refused at once, where it is --------------------
# (100 MB of address space: the 64 KiB read and the program; before, `yes x` read until
# the limit and said "out of memory reading /dev/stdin", exit 3)
join_pipe() { # join_pipe WRITER-COMMAND: quadkit join /dev/stdin p.csv, fed by the writer
  bash -c "{ $1; }"' | timeout "$2" "$0" join /dev/stdin "$1"' "$cli" "$tmp/p.csv" "$secs"
}
expect 1 '^quadkit join: /dev/stdin:1:1: malformed JSON: unexpected character$' -- \
  limited 100000 join_pipe 'yes x'
expect 1 "^quadkit join: /dev/stdin:1:1: $obj" -- limited 100000 join_pipe "yes '[1,2]'"
expect 1 "^quadkit join: /dev/stdin:3:3: $obj" -- \
  limited 100000 join_pipe "printf '\\n\\n'; yes '  null'"
expect 1 '^quadkit join: /dev/stdin:1:2: malformed JSON: unexpected character$' -- \
  limited 100000 join_pipe "printf '\\xef\\xbb\\xbf '; yes '}'"
# The same short inputs from a file, read whole, give the same message and position
# (the whole reading placed "  x" one column early, at the blank).
printf '\n\n  x' >"$tmp/x.json"
expect 1 "^quadkit join: $tmp/x.json:3:3: malformed JSON: unexpected character$" -- \
  "$cli" join "$tmp/x.json" "$tmp/p.csv"

# The mesher reads GeoJSON by name: a FIFO named .geojson.
mkfifo "$tmp/f.geojson"
mesh_fifo() { # mesh_fifo WRITER-COMMAND: quadkit mesh f.geojson, the FIFO fed by the writer
  bash -c "$1" >"$tmp/f.geojson" &
  local writer=$! rc
  timeout "$secs" "$cli" mesh "$tmp/f.geojson" -o "$tmp/m"
  rc=$?
  kill "$writer" 2>/dev/null
  wait "$writer" 2>/dev/null
  return $rc
}
expect 1 "^quadkit mesh: $tmp/f.geojson:1:1: malformed JSON: unexpected character$" -- \
  limited 100000 mesh_fifo 'yes x'
expect 1 "^quadkit mesh: $tmp/f.geojson:1:1: $obj" -- limited 100000 mesh_fifo "yes '[1,2]'"

# ---- an endless text that may be GeoJSON: stopped at the limit for a stream -------------
# (2^31 - 1 bytes read, a few seconds; 4 GB of address space: the buffer and the one copy
# realloc may make. Before: memory filled until the limit, "out of memory", exit 3.)
once expect 1 "^quadkit join: /dev/stdin: $limit" -- \
  limited 4000000 join_pipe "printf '%s' '$coll'; yes '$feat'"
repeat expect 1 "^quadkit join: /dev/stdin: $limit" -- limited 4000000 join_pipe "yes ' '"
once expect 1 "^quadkit mesh: $tmp/f.geojson: $limit" -- \
  limited 4000000 mesh_fifo "printf '%s' '$coll'; yes '$feat'"
[ -e "$tmp/m.node" ] && fail "mesh: an output was written after the limit"

# ---- CSV and .poly from a pipe: the same limit ------------------------------------------
# The commands that read a whole CSV or .poly input keep a stream's bytes as read (the
# line reader's screen, tools/csv.c): an endless stream of short, valid lines grew until
# memory ran out ("out of memory reading the line", exit 3). join streams its points and
# answers as it reads, so it is not among them. (The mesher's .poly from stdin: `yes x`
# is bad at line 1, but the screen reads the whole input before the reader sees it.)
stream='input from a pipe or device longer than 2147483647 bytes, the limit for a stream \(a regular file has none\)$'
long=$(printf '%0200d' 0) # (long lines: fewer of them to read before the limit)
tree_pipe() { yes "0.5,0.5,$long" | timeout "$secs" "$cli" tree /dev/stdin; }
mesh_pipe() { yes "x $long" | timeout "$secs" "$cli" mesh - -o "$tmp/s"; }
once expect 1 "^quadkit: /dev/stdin: $stream" -- limited 4000000 tree_pipe
repeat expect 1 "^quadkit mesh: <stdin>: $stream" -- limited 4000000 mesh_pipe
[ -e "$tmp/s.node" ] && fail "mesh: an output was written after the limit"

# ---- a FIFO's text is not read twice ---------------------------------------------------
# The mesher found the position of a bad segment by reading the file again: a FIFO opened
# again waited for a writer forever (killed by the timeout, exit 124). Its text is kept.
cross='{"type":"Polygon","coordinates":[[[0,0],[2,2],[2,0],[0,2],[0,0]]]}'
printf '%s' "$cross" >"$tmp/cross.geojson"
at='1:35: segments 0 and 2 cross or overlap \(input segments feature 0, polygon 0, ring 0, position 0 and feature 0, polygon 0, ring 0, position 2, at 1:47\)$'
expect 1 "^quadkit mesh: $tmp/cross.geojson:$at" -- "$cli" mesh "$tmp/cross.geojson" -o "$tmp/c"
expect 1 "^quadkit mesh: $tmp/f.geojson:$at" -- limited 1000000 mesh_fifo "printf '%s' '$cross'"

report
