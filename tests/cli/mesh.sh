#!/usr/bin/env bash
# CLI tests for `quadkit mesh`: outputs and their formats, --stats, exit codes, and bad
# input named by file and line with nothing written.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"
check() { # check DESCRIPTION -- command...: the command must succeed
  local what=$1
  shift 2
  if ! "$@" >/dev/null 2>&1; then
    fail "$what"
  else
    passes=$((passes + 1))
  fi
}

# The notes' example: every output, with the stats the issue lists.
expect 0 '"U": 16, "components": 1, .*"triangles": [0-9]+, .*"min_angle_deg": 45(\.0+)?, "max_angle_deg": 90(\.0+)?, "uniform_triangles": 512' -- \
  "$cli" mesh "$src/examples/mesh/notes.poly" --size 16 -o "$tmp/n" --svg "$tmp/n.svg" \
  --msh "$tmp/n.msh" --vtk "$tmp/n.vtu" --stats
for f in n.node n.ele n.svg n.msh n.vtu; do
  [ -s "$tmp/$f" ] || { echo "FAIL: $f not written"; fails=$((fails + 1)); }
done
ls "$tmp"/*.tmp.* >/dev/null 2>&1 && { echo "FAIL: temp file left"; fails=$((fails + 1)); }
# .node: first index 1 as in the input; .ele: counter-clockwise, one attribute.
check ".node header and first index" -- awk 'NR==1 { n=$1; if ($2 != 2) exit 1 } NR==2 { if ($1 != 1) exit 1 } END { if (NR != n + 1) exit 1 }' "$tmp/n.node"
check ".ele triangles counter-clockwise with a component attribute" -- awk '
  FNR==NR { if (FNR > 1) { x[$1]=$2; y[$1]=$3 }; next }
  FNR==1 { n=$1; if ($2 != 3 || $3 != 1) exit 1; next }
  { a=$2; b=$3; c=$4; cr=(x[b]-x[a])*(y[c]-y[a])-(y[b]-y[a])*(x[c]-x[a]); if (cr <= 0 || $5 < 0 || $5 > 1) exit 1; k++ }
  END { if (k != n) exit 1 }' "$tmp/n.node" "$tmp/n.ele"
check ".msh format" -- grep -q '^4.1 0 8$' "$tmp/n.msh"
check ".vtu cell data" -- grep -q 'Name="component"' "$tmp/n.vtu"
check "svg closed" -- grep -q '</svg>' "$tmp/n.svg"
# Default size: the smallest power of two >= every coordinate.
expect 0 '"U": 2,' -- "$cli" mesh "$src/examples/mesh/notes.poly" -o "$tmp/d" --stats
expect 0 '"U": 64, "components": 6' -- "$cli" mesh "$src/examples/mesh/richer.poly" -o "$tmp/r" --stats
# Input from standard input.
expect 0 '"components": 1' -- sh -c "\"$cli\" mesh - -o \"$tmp/s\" --stats < \"$src/examples/mesh/notes.poly\""

# Bad input: file:line: reason, exit 1, nothing written.
printf '4 2 0 0\n0 0 0\n1 3 0\n2 2 2\n3 0 2\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/angle.poly"
expect 1 'angle.poly:8: segment 1 .* is not at 0, 45, 90 or 135 degrees' -- "$cli" mesh "$tmp/angle.poly" --book -o "$tmp/bad" --svg "$tmp/bad.svg"
ls "$tmp"/bad* >/dev/null 2>&1 && { echo "FAIL: output written for bad input"; fails=$((fails + 1)); }
printf '4 2 0 0\n0 0 0\n1 2.5 0\n2 2 2\n3 0 2\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/frac.poly"
expect 1 'frac.poly:3: vertex 1: coordinates .* are not integers' -- "$cli" mesh "$tmp/frac.poly" --book -o "$tmp/bad"
printf '4 2 0 0\n0 0 0\n1 2 0\n2 2 2\n3 0 2\n4 0\n0 0 1\n' >"$tmp/trunc.poly"
expect 1 'trunc.poly:7: truncated input' -- "$cli" mesh "$tmp/trunc.poly" -o "$tmp/bad"
printf '4 2 0 0\n0 0 0\n1 2 0\n2 0 2\n3 2 2\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/bowtie.poly"
expect 1 'bowtie.poly:[0-9]+: component 1 intersects itself' -- "$cli" mesh "$tmp/bowtie.poly" -o "$tmp/bad"
printf '4 2 0 0\n0 0 0\n1 20 0\n2 20 2\n3 0 2\n4 0\n0 0 1\n1 1 2\n2 2 3\n3 3 0\n0\n' >"$tmp/out.poly"
expect 1 'out.poly:3: .*outside the domain \[0,16\]\^2' -- "$cli" mesh "$tmp/out.poly" --size 16 -o "$tmp/bad"
expect 1 'cannot open' -- "$cli" mesh "$tmp/missing.poly" -o "$tmp/bad"
ls "$tmp"/bad* >/dev/null 2>&1 && { echo "FAIL: output written for bad input"; fails=$((fails + 1)); }

# Real (dyadic) coordinates: the dyadic mode, input vertices bit-identical, markers.
printf '6 2 0 1\n0 -1.25 0.5 1\n1 2.75 0.5 1\n2 2.75 1.5 1\n3 1.75 1.5 2\n4 0.75 2.5 2\n5 -1.25 2.5 2\n6 1\n0 0 1 1\n1 1 2 2\n2 2 3 2\n3 3 4 3\n4 4 5 3\n5 5 0 3\n0\n1\n1 0 1 7\n' >"$tmp/real.poly"
expect 0 '"mode": "dyadic", "lattice_exponent": 2, .*"proven_min_angle_deg": 45, "proven_max_angle_deg": 90, "angle_histogram": \[0, ' -- \
  "$cli" mesh "$tmp/real.poly" -o "$tmp/real" --poly "$tmp/real.out.poly" --msh "$tmp/real.msh" --vtk "$tmp/real.vtu" --stats
check "input vertices bit-identical in the .node" -- awk 'NR > 1 { seen[$2 " " $3] = 1 } END { if (!(seen["-1.25 0.5"] && seen["2.75 1.5"] && seen["0.75 2.5"])) exit 1 }' "$tmp/real.node"
check ".node has the marker column" -- awk 'NR==1 { if ($4 != 1) exit 1 } NR > 1 && NF != 4 { exit 1 }' "$tmp/real.node"
check ".ele has the regional attribute" -- awk 'NR==1 { if ($3 != 2) exit 1 } NR > 1 && $6 == 7 { k++ } END { if (!k) exit 1 }' "$tmp/real.ele"
check ".poly of output segments with markers" -- awk 'NR==3 { n=$1; if ($2 != 1) exit 1 } NR > 3 && NF == 4 { k++; if ($4 < 1 || $4 > 3) exit 1 } END { if (k != n) exit 1 }' "$tmp/real.out.poly"
check ".msh marker groups" -- grep -q '^1 3 "marker_3"$' "$tmp/real.msh"
check ".vtu marker data" -- grep -q 'Name="marker"' "$tmp/real.vtu"
# --book insists; --max-size bounds every edge; --min-angle reports the bound.
expect 1 'real.poly:2: vertex 0: coordinates .* are not integers' -- "$cli" mesh "$tmp/real.poly" --book -o "$tmp/bad"
expect 0 '"triangles": 2048,' -- "$cli" mesh "$tmp/real.poly" -o "$tmp/h" --max-size 0.2 --stats
check "--max-size 0.2: every edge at most 0.2" -- awk '
  FNR==NR { if (FNR > 1) { x[$1]=$2; y[$1]=$3 }; next }
  FNR > 1 { for (i = 2; i <= 4; i++) { a=$i; b=$(i == 4 ? 2 : i + 1); d=(x[a]-x[b])^2+(y[a]-y[b])^2; if (d > 0.04 + 1e-12) exit 1 } }' "$tmp/h.node" "$tmp/h.ele"
expect 0 'dyadic mode: every angle in \[45, 90\] degrees \(proven' -- "$cli" mesh "$tmp/real.poly" -o "$tmp/h" --min-angle 30
expect 2 'must be above 0 and at most 45 degrees' -- "$cli" mesh "$tmp/real.poly" -o "$tmp/u" --min-angle 50
# 0 is refused: it read as the general mode's default (20) without a word
expect 2 'must be above 0 and at most 45 degrees' -- "$cli" mesh "$tmp/real.poly" -o "$tmp/u" --min-angle 0
expect 2 'exclude each other' -- "$cli" mesh "$tmp/real.poly" -o "$tmp/u" --book --dyadic
# The issue's coastline-like polygon in the dyadic mode: refused, naming the segment and
# the reason (without --dyadic the general mode meshes it: tests/cli/mesh_general.sh).
printf '3 2 0 0\n0 5 5\n1 30.5 3\n2 5 20\n3 0\n0 0 1\n1 1 2\n2 2 0\n0\n' >"$tmp/coast.poly"
expect 1 'coast.poly:6: segment 0 from \(5, 5\) to \(30.5, 3\) is not at 0, 45, 90 or 135 degrees \(the dyadic mode keeps' -- "$cli" mesh "$tmp/coast.poly" --dyadic -o "$tmp/bad"
ls "$tmp"/bad* >/dev/null 2>&1 && { echo "FAIL: output written for bad input"; fails=$((fails + 1)); }

# Usage errors.
expect 2 'power of two' -- "$cli" mesh "$src/examples/mesh/notes.poly" -o "$tmp/u" --size 12
expect 2 'whole number' -- "$cli" mesh "$src/examples/mesh/notes.poly" -o "$tmp/u" --size -4
expect 2 '-o PREFIX is required' -- "$cli" mesh "$src/examples/mesh/notes.poly"
expect 2 'unknown option' -- "$cli" mesh "$src/examples/mesh/notes.poly" -o "$tmp/u" --bogus
expect 2 'no input file' -- "$cli" mesh
expect 0 'usage: quadkit mesh' -- "$cli" mesh --help

report
