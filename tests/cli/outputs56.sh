#!/usr/bin/env bash
# CLI regressions from the fifty-sixth session's review of how outputs are written (each
# block failed before its fix): a name of an open descriptor (-o /dev/stdout) replaced the
# file the shell had redirected it to, the temporary beside an output was opened through
# whatever sat at its name, a replaced output lost its permissions, and two messages
# printed file names raw, and names and values in messages were cut inside a character.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

printf 'x,y\n0,0\n1,1\n' >"$tmp/p.csv"
printf '0.1,0.1\n' >"$tmp/q.csv"
row='0,1,0,0.14142135623730953'

# ---- -o /dev/stdout and its aliases: the descriptor, not the file it leads to ------------
# Resolved to the redirected file and replaced by a temporary, `-o /dev/stdout >> a.csv`
# lost a.csv's earlier lines, and in `{ echo; quadkit ...; echo; } > f` the lines before
# and after quadkit's went to the old, unlinked file.
for name in /dev/stdout /dev/fd/1 /proc/self/fd/1; do
  [ -e "$name" ] || {
    skip "$name does not exist here"
    continue
  }
  echo "earlier line" >"$tmp/a.csv"
  "$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 1 -o "$name" >>"$tmp/a.csv"
  same_text "-o $name >> file: appended" "$(tr '\n' '|' <"$tmp/a.csv")" \
    "earlier line|query,rank,point,distance|$row|"
  {
    echo before
    "$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 1 -o "$name"
    echo after
  } >"$tmp/b.csv"
  same_text "-o $name in a group: in order" "$(tr '\n' '|' <"$tmp/b.csv")" \
    "before|query,rank,point,distance|$row|after|"
done
echo "log line" >"$tmp/log.txt"
"$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 1 -o /dev/stderr 2>>"$tmp/log.txt"
same_text "-o /dev/stderr 2>> log: appended" "$(head -1 "$tmp/log.txt")|$(wc -l <"$tmp/log.txt" | tr -d ' ')" \
  "log line|3"
# (beside the command's own standard output it is still a second output into one stream,
# which passed before; a descriptor not open is an error naming it, which said "No such
# file or directory (creating the temporary file /dev/fd/9.tmp...)")
expect 2 "cannot write /dev/stdout: another output of this command writes that file too" -- \
  "$cli" tree "$tmp/p.csv" --svg /dev/stdout
expect 1 "cannot write /dev/fd/9: Bad file descriptor" -- \
  "$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 1 -o /dev/fd/9

# ---- the temporary is created new, never through what sits at its name -------------------
# A link planted at out.csv.tmp.PID.0 had its target overwritten, and out.csv became the
# link (sh execs quadkit, so the process number is the shell's).
echo "precious" >"$tmp/victim.txt"
(cd "$tmp" && sh -c 'ln -s victim.txt out.csv.tmp.$$.0; exec "$0" knn p.csv q.csv -k 1 -o out.csv' "$cli")
same_text "planted link: its target untouched" "$(cat "$tmp/victim.txt")" "precious"
same_text "planted link: the output a regular file" "$([ -f "$tmp/out.csv" ] && [ ! -L "$tmp/out.csv" ] && echo regular)" "regular"
same_text "planted link: the output written" "$(tail -1 "$tmp/out.csv")" "$row"
rm -f "$tmp"/out.csv.tmp.*

# ---- a replaced output keeps its permissions ----------------------------------------------
echo old >"$tmp/private.csv"
chmod 0600 "$tmp/private.csv"
"$cli" knn "$tmp/p.csv" "$tmp/q.csv" -k 1 -o "$tmp/private.csv"
same_text "0600 output replaced: still 0600" "$(stat -c %a "$tmp/private.csv")|$(tail -1 "$tmp/private.csv")" "600|$row"
echo old >"$tmp/group.csv"
chmod 0640 "$tmp/group.csv"
"$cli" tree "$tmp/p.csv" --svg "$tmp/group.csv" >/dev/null
same_text "0640 picture replaced: still 0640" "$(stat -c %a "$tmp/group.csv")" "640"

# ---- file names in messages: control characters escaped ------------------------------------
# Two messages printed the name with fprintf, so an escape sequence in a file name reached
# the terminal (every other message writes it as \x1B): world's "moves twice" and mesh's
# --round notes.
E=$(printf '\033')
printf '0,disc,0,0,1,0\n1,disc,5,5,1,0\n' >"$tmp/wo.csv"
printf '0,0,1,1,1,0\n0,0,2,2,1,0\n' >"$tmp/wm${E}[31m.csv"
msg=$("$cli" world "$tmp/wo.csv" "$tmp/wm${E}[31m.csv" 2>&1 >/dev/null)
same_text "world, moves twice: the name escaped" "$(grep -c "$E" <<<"$msg")|$(grep -c 'wm\\x1B\[31m.csv:2: id 0 moves twice' <<<"$msg")" "0|1"
printf '4 2 0 0\n0 0 0\n1 4.0000001 0\n2 4 4\n3 0 4\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/r${E}[31m.poly"
msg=$("$cli" mesh "$tmp/r${E}[31m.poly" -o "$tmp/rm" --round 0.5 2>&1 >/dev/null)
same_text "mesh --round: the name escaped" "$(grep -c "$E" <<<"$msg")|$(grep -c 'r\\x1B\[31m.poly moved to the grid' <<<"$msg")" "0|1"

# ---- names and values in messages: cut whole, marked ---------------------------------------
# A header name was cut at 47 bytes (mid-word, or inside a UTF-8 character, printed as
# \xC3), join cut a value at 40 bytes and a name at 63 the same way, and "no column named"
# overflowed the library's 256-byte message, losing its closing quote and parenthesis.
a46=$(printf 'a%.0s' $(seq 46))
printf 'x,%s\xc3\xa9\n1,abc\n' "$a46" >"$tmp/label.csv"
msg=$("$cli" tree "$tmp/label.csv" 2>&1 >/dev/null)
same_text "a long header name: cut whole, marked" "$(grep -c 'xC3' <<<"$msg")|$(grep -c "field 2 (${a46:0:44}\.\.\.) is not a number" <<<"$msg")" "0|1"
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},"geometry":{"type":"Polygon","coordinates":[[[0,0],[10,0],[10,10],[0,10],[0,0]]]}}]}' >"$tmp/sq.geojson"
printf 'x,y\n1,%s\xc3\xa9\n' "${a46:0:39}" >"$tmp/jv.csv"
msg=$("$cli" join "$tmp/sq.geojson" "$tmp/jv.csv" --planar 2>&1 >/dev/null)
same_text "join, a long value: cut whole, marked" "$(grep -c 'xC3' <<<"$msg")|$(grep -c "'${a46:0:39}\.\.\.'\$" <<<"$msg")" "0|1"
printf 'x,%s\xc3\xa9bbbbbbbbbbbbbbbbbbbbbbb\n1,abc\n' "$a46" >"$tmp/jl.csv"
msg=$("$cli" join "$tmp/sq.geojson" "$tmp/jl.csv" --planar 2>&1 >/dev/null)
same_text "join, a long name: cut whole, marked" "$(grep -c 'xC3' <<<"$msg")|$(grep -c "field 2 (${a46}\.\.\.) is not a finite number" <<<"$msg")" "0|1"
long=$(printf 'c%.0s' $(seq 150))
msg=$("$cli" tree "$tmp/p.csv" --xy "$long,y" 2>&1 >/dev/null)
same_text "no column named a long name: the message whole" "$(grep -c "no column named '${long:0:48}\.\.\.' in the header (2 fields: 'x,y')\$" <<<"$msg")" "1"

report
