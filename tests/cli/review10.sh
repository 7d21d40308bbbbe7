#!/usr/bin/env bash
# CLI regressions from a tenth review (twenty-third session): hostile input files (one
# block per finding; each failed before its fix, the guards of a new path say so).
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"

# limited CMD...: run under a 1 GB address-space limit, so that a reader that takes an
# endless line into memory fails here in seconds instead of filling the machine (not with
# the sanitizers, whose shadow memory needs the address space).
limited() {
  if [ "${QK_SANITIZE:-0}" = 1 ]; then
    timeout 60 "$@"
  else
    (
      ulimit -v 1000000
      exec timeout 60 "$@"
    )
  fi
}

sq='{"type":"Polygon","coordinates":[[[0,0],[4,0],[4,4],[0,4],[0,0]]]}'
printf '%s\n' "$sq" >"$tmp/sq.json"
printf 'x,y\n1,1\n3,3\n' >"$tmp/p.csv"
printf 'x,y,r\n1,1,1\n' >"$tmp/d.csv"
printf '1,disc,0,0,1\n' >"$tmp/obj.csv"

# ---- /dev/zero and files of NUL bytes: read into memory until it ran out ----------------
# The readers of the CSV commands took a whole line into memory before they looked at
# it: /dev/zero (no line break ever) grew the process to gigabytes, then "out of memory",
# exit 3. The tool's line reader stops at the first NUL byte, exit 1, in milliseconds.
nul='binary data \(NUL byte\) in a text file$'
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" tree /dev/zero
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" knn "$tmp/p.csv" /dev/zero -k 1
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" knn /dev/zero "$tmp/p.csv" -k 1
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" range "$tmp/p.csv" /dev/zero
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" radius "$tmp/p.csv" /dev/zero -r 1
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" locate "$tmp/p.csv" /dev/zero
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" collide /dev/zero
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" raycast "$tmp/d.csv" /dev/zero
expect 1 "^quadkit: /dev/zero:1:1: $nul" -- limited "$cli" geo knn /dev/zero "$tmp/p.csv" -k 1
expect 1 "^quadkit join: /dev/zero:1:1: $nul" -- limited "$cli" join "$tmp/sq.json" /dev/zero --planar
expect 1 "^quadkit world: /dev/zero:1:1: $nul" -- limited "$cli" world /dev/zero "$tmp/obj.csv"
# a NUL byte after a 2 MB line without a line break: the line limit speaks first
{ printf 'x,y\n1,'; head -c 2000000 /dev/zero | tr '\0' 1; printf '\0\n'; } >"$tmp/long-nul.csv"
expect 1 "^quadkit: $tmp/long-nul.csv:2: line longer than 1048576 bytes \\(1 MiB\\), the limit for a line of text input$" \
  -- limited "$cli" tree "$tmp/long-nul.csv"

# ---- an endless line without a NUL byte: a documented limit of 1 MiB per line -----------
# A pipe of text without line breaks (a wrong file, `yes | tr -d '\n'`) grew memory the
# same way. A line past 1 MiB is refused with its line number and the limit, exit 1.
long='line longer than 1048576 bytes \(1 MiB\), the limit for a line of text input$'
endless() { yes 1 | tr -d '\n'; }
expect 1 "^quadkit: /dev/stdin:1: $long" -- limited bash -c "$(declare -f endless); endless | \"\$1\" tree /dev/stdin" - "$cli"
expect 1 "^quadkit join: /dev/stdin:1: $long" -- limited bash -c "$(declare -f endless); endless | \"\$1\" join \"\$2\" /dev/stdin --planar" - "$cli" "$tmp/sq.json"
expect 1 "^quadkit world: /dev/stdin:1: $long" -- limited bash -c "$(declare -f endless); endless | \"\$1\" world \"\$2\" /dev/stdin" - "$cli" "$tmp/obj.csv"
# the limit exactly: a line of 1048576 bytes (a point and blanks) is read (a guard: it
# passed before), one more is not
{ printf 'x,y\n1,2'; printf '%1048573s\n' ''; } >"$tmp/max.csv"
{ printf 'x,y\n1,2'; printf '%1048574s\n' ''; } >"$tmp/over.csv"
expect 0 '"points": 1,' -- "$cli" tree "$tmp/max.csv"
expect 1 "^quadkit: $tmp/over.csv:2: $long" -- "$cli" tree "$tmp/over.csv"
expect 1 "^quadkit join: $tmp/over.csv:2: $long" -- "$cli" join "$tmp/sq.json" "$tmp/over.csv" --planar
{ printf '1,disc,0,0,1'; printf '%1048575s\n' ''; } >"$tmp/over-obj.csv"
expect 1 "^quadkit world: $tmp/over-obj.csv:1: $long" -- "$cli" world "$tmp/over-obj.csv" "$tmp/obj.csv"
# a file with CR line ends is one long line (2.4 MB): the CR is named, not the length (a
# guard: the library's reader named it before, once it had the whole line in memory)
{ for i in $(seq 1 200000); do printf '%d,%d\r' "$i" "$i"; done; } >"$tmp/cr.csv"
expect 1 "^quadkit: $tmp/cr.csv:1:4: a carriage return inside the line" -- "$cli" tree "$tmp/cr.csv"

# guard of the new path (passed before): from a pipe the screened bytes are what the
# library reads, every row of them
same_text "knn, points from a pipe" \
  "$(cat "$tmp/p.csv" | "$cli" knn /dev/stdin "$tmp/p.csv" -k 1 | tr '\n' ' ')" \
  "$("$cli" knn "$tmp/p.csv" "$tmp/p.csv" -k 1 | tr '\n' ' ')"

# ---- mesh: a .poly file is screened the same way -----------------------------------------
# The .poly reader took an endless line from a pipe into memory too ("out of memory",
# exit 3, after 1 GB under this limit).
expect 1 "^quadkit mesh: <stdin>:1: $long" -- limited bash -c "$(declare -f endless); endless | \"\$1\" mesh - -o \"\$2\"" - "$cli" "$tmp/pm"
nothing_written "$tmp/pm"
printf '4 2 0 0\n1 0 0\n2 1 0\n3 1 1\n4 0 1\n4 0\n1 1 2\n2 2 3\n3 3 4\n4 4 1\n0\n' >"$tmp/sq.poly"
# (a guard of the new path, which passed before: a .poly from a pipe is still meshed)
expect 0 '' -- bash -c 'cat "$2" | "$1" mesh - -o "$3"' - "$cli" "$tmp/sq.poly" "$tmp/pm2"
[ -s "$tmp/pm2.ele" ] && passes=$((passes + 1)) || fail "mesh from a pipe wrote no $tmp/pm2.ele"

# ---- join: a bad number named its field but not its column ------------------------------
# "FILE:LINE: field 2 is not a finite number" where the other commands say
# FILE:LINE:COLUMN and the header's name of the field.
printf 'id,x,y\n7,1,abc\n' >"$tmp/bad2.csv"
expect 1 "^quadkit join: $tmp/bad2.csv:2:5: field 3 \\(y\\) is not a finite number: 'abc'$" \
  -- "$cli" join "$tmp/sq.json" "$tmp/bad2.csv" --planar --xy x,y
# (the other commands' wording, which passed before: the reference)
expect 1 "^quadkit: $tmp/bad2.csv:2:5: field 3 \\(y\\) is not a number: 'abc'$" \
  -- "$cli" tree "$tmp/bad2.csv" --xy x,y
# in a record that a quoted field spreads over two lines: the field's own line and column
printf 'n,x,y\n"a\nb",1,nan\n' >"$tmp/bad3.csv"
expect 1 "^quadkit join: $tmp/bad3.csv:3:6: field 3 \\(y\\) is not a finite number: 'nan'$" \
  -- "$cli" join "$tmp/sq.json" "$tmp/bad3.csv" --planar --xy x,y

# the same for a malformed quote, which join named by field alone: now the line and
# column where the field starts, as tree says it (a byte order mark counted on line 1)
printf '\xef\xbb\xbfx,"y"z\n1,1\n' >"$tmp/bq.csv"
expect 1 "^quadkit join: $tmp/bq.csv:1:6: field 2: text after a closing quote$" -- "$cli" join "$tmp/sq.json" "$tmp/bq.csv" --planar
expect 1 "^quadkit: $tmp/bq.csv:1:6: field 2: text after a closing quote$" -- "$cli" tree "$tmp/bq.csv"
printf 'x,y,n\n1,1,1\n2,2,"open\n3,3\n' >"$tmp/mlo.csv"
expect 1 "^quadkit join: $tmp/mlo.csv:3:5: field 3: unterminated quoted field \\(it runs to the end of the file\\)$" -- "$cli" join "$tmp/sq.json" "$tmp/mlo.csv" --planar

# ---- join: a header of many names took minutes ------------------------------------------
# Looking for a name among the header's fields read the header from its start for every
# field (quadratic): 100,000 names (890 KB, under the line limit) kept join busy past 100
# s before its first row. Linear now: well under a second.
{ seq -f 'c%g' 100000 | paste -sd, | sed 's/$/,x,y/'; seq 100002 | sed 's/.*/1/' | paste -sd,; } >"$tmp/wide.csv"
expect 0 '^c1,c2,c3,' -- timeout 30 "$cli" join "$tmp/sq.json" "$tmp/wide.csv" --planar --xy x,y
expect 0 '^1,1,1,' -- timeout 30 "$cli" join "$tmp/sq.json" "$tmp/wide.csv" --planar

# ---- UTF-16 text (Windows "Unicode"): named, not "binary data" -------------------------
printf 'x,y\n1,1\n' | iconv -f UTF-8 -t UTF-16 >"$tmp/u16.csv"
u16='UTF-16 text \(a UTF-16 byte order mark\): text input must be UTF-8 or ASCII; convert it first \(iconv -f UTF-16 -t UTF-8\)$'
expect 1 "^quadkit: $tmp/u16.csv:1:1: $u16" -- "$cli" tree "$tmp/u16.csv"
expect 1 "^quadkit join: $tmp/u16.csv:1:1: $u16" -- "$cli" join "$tmp/sq.json" "$tmp/u16.csv" --planar
expect 1 "^quadkit world: $tmp/u16.csv:1:1: $u16" -- "$cli" world "$tmp/u16.csv" "$tmp/obj.csv"

# ---- world: a row of the wrong width said what it expected, not what it found ----------
printf '1,disc\n' >"$tmp/narrow.csv"
expect 1 "^quadkit world: $tmp/narrow.csv:1: expected id,kind,x,y\\[,a,b\\]: the line has 2 fields$" \
  -- "$cli" world "$tmp/narrow.csv" "$tmp/obj.csv"
printf '0,1,0,0,1,2,3\n' >"$tmp/wide.csv"
expect 1 "^quadkit world: $tmp/wide.csv:1: expected frame,id,x,y\\[,a,b\\]: the line has more than 6 fields$" \
  -- "$cli" world "$tmp/obj.csv" "$tmp/wide.csv"

report
