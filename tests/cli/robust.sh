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

report
