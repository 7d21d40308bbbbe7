#!/usr/bin/env bash
# CLI tests for `quadkit world` and `quadkit simulate`: a random scene of all four kinds
# (many touching on a coarse grid) replayed over frames, every pair of every frame and the
# began / ended sets checked against a brute force in exact rational arithmetic (Python's
# fractions); errors naming file and line; simulate's JSON and SVG.
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"
command -v python3 >/dev/null || { echo "SKIPPED: python3 not found (the brute force)"; exit 77; }

seed=${QK_SEED:-7}
python3 - "$tmp" "$seed" <<'EOF'
import random, sys
tmp, seed = sys.argv[1], int(sys.argv[2])
rnd = random.Random(seed)
def val():  # multiples of 1/4: many exact touches
    return rnd.randrange(0, 80) / 4
def shape(kind):
    x, y = val(), val()
    if kind == 'disc': return [x, y, rnd.randrange(0, 9) / 4]
    if kind == 'point': return [x, y]
    return [x, y, x + rnd.randrange(-8, 9) / 4, y + rnd.randrange(-8, 9) / 4]
kinds = ['disc', 'box', 'segment', 'point']
objs = {}
with open(f'{tmp}/objects.csv', 'w') as f:
    f.write('id,kind,x,y,a,b\n')
    for i in range(80):
        oid = 1000 - 7 * i
        k = kinds[i % 4]
        objs[oid] = (k, shape(k))
        f.write(f'{oid},{k},' + ','.join(map(str, objs[oid][1])) + '\n')
    # Exact touches: discs tangent along a 3-4-5 triangle, a disc tangent to a box side,
    # a segment ending on a circle, a point on a segment's interior, boxes sharing a corner.
    movers = sorted(objs)
    for i in range(12):
        x, y = val(), val()
        touch = [('disc', [x, y, 2.5]), ('disc', [x + 3, y + 4, 2.5]),
                 ('box', [x + 3 + 2.5, y + 4 - 1, x + 8, y + 6]),
                 ('segment', [x - 2.5, y - 6, x, y - 2.5]),
                 ('point', [x - 1.25, y - 4.25]),
                 ('box', [x + 8, y + 6, x + 9, y + 7])]
        for j, (k, v) in enumerate(touch):
            oid = 5000 + 10 * i + j
            objs[oid] = (k, v)
            f.write(f'{oid},{k},' + ','.join(map(str, v)) + '\n')
with open(f'{tmp}/moves.csv', 'w') as f:
    f.write('frame,id,x,y,a,b\n')
    for fr in range(12):
        for oid in rnd.sample(movers, 25):
            f.write(f'{fr},{oid},' + ','.join(map(str, shape(objs[oid][0]))) + '\n')
EOF

python3 - "$tmp" <<'EOF' || fail "oracle could not run"
# The brute force: exact closed overlap of every pair, in rationals.
import sys
from fractions import Fraction as F
tmp = sys.argv[1]
def rows(p):
    out = []
    for line in open(p):
        v = line.strip().split(',')
        if v[0].isdigit(): out.append(v)
    return out
def norm(k, v):
    v = [F(s) for s in v]
    if k == 'box': v = [min(v[0], v[2]), min(v[1], v[3]), max(v[0], v[2]), max(v[1], v[3])]
    return (k, v)
def orient(a, b, c): d = (b[0]-a[0])*(c[1]-a[1]) - (b[1]-a[1])*(c[0]-a[0]); return (d > 0) - (d < 0)
def onseg(p, a, b):
    return orient(a, b, p) == 0 and min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])
def segseg(a, b, c, d):
    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    if o1 * o2 < 0 and o3 * o4 < 0: return True
    return onseg(c, a, b) or onseg(d, a, b) or onseg(a, c, d) or onseg(b, c, d)
def d2seg(p, a, b):
    ux, uy = b[0]-a[0], b[1]-a[1]; uu = ux*ux + uy*uy
    t = 0 if uu == 0 else max(F(0), min(F(1), ((p[0]-a[0])*ux + (p[1]-a[1])*uy) / uu))
    dx, dy = p[0] - (a[0] + t*ux), p[1] - (a[1] + t*uy)
    return dx*dx + dy*dy
def inbox(p, b): return b[0] <= p[0] <= b[2] and b[1] <= p[1] <= b[3]
def bbox(s):  # floats are exact here (quarters and halves)
    k, v = s
    if k == 'disc': return (float(v[0] - v[2]), float(v[1] - v[2]), float(v[0] + v[2]), float(v[1] + v[2]))
    if k == 'point': return (float(v[0]), float(v[1]), float(v[0]), float(v[1]))
    return (float(min(v[0], v[2])), float(min(v[1], v[3])), float(max(v[0], v[2])), float(max(v[1], v[3])))
def overlap(s, t):
    a, b = bbox(s), bbox(t)
    if a[0] > b[2] or b[0] > a[2] or a[1] > b[3] or b[1] > a[3]: return False
    order = ['point', 'disc', 'box', 'segment']
    if order.index(s[0]) > order.index(t[0]): s, t = t, s
    (k, a), (m, b) = s, t
    if k == 'point':
        p = a[:2]
        if m == 'point': return p == b[:2]
        if m == 'disc': return (p[0]-b[0])**2 + (p[1]-b[1])**2 <= b[2]**2
        if m == 'box': return inbox(p, b)
        return onseg(p, b[:2], b[2:])
    if k == 'disc':
        c, r = a[:2], a[2]
        if m == 'disc': return (c[0]-b[0])**2 + (c[1]-b[1])**2 <= (r + b[2])**2
        if m == 'box':
            px, py = min(max(c[0], b[0]), b[2]), min(max(c[1], b[1]), b[3])
            return (c[0]-px)**2 + (c[1]-py)**2 <= r*r
        return d2seg(c, b[:2], b[2:]) <= r*r
    if k == 'box':
        if m == 'box': return a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]
        if inbox(b[:2], a) or inbox(b[2:], a): return True
        cs = [(a[0], a[1]), (a[2], a[1]), (a[2], a[3]), (a[0], a[3])]
        return any(segseg(cs[i], cs[(i+1) % 4], b[:2], b[2:]) for i in range(4))
    return segseg(a[:2], a[2:], b[:2], b[2:])
objs = {}
for v in rows(f'{tmp}/objects.csv'): objs[int(v[0])] = norm(v[1], v[2:])
moves = rows(f'{tmp}/moves.csv')
frames = int(moves[-1][0]) + 1 if moves else 1
out = {w: open(f'{tmp}/want-{w}', 'w') for w in ('all', 'began', 'ended')}
for o in out.values(): o.write('frame,a,b\n')
prev, mi = set(), 0
ids = sorted(objs)
for fr in range(frames):
    while mi < len(moves) and int(moves[mi][0]) == fr:
        oid = int(moves[mi][1]); objs[oid] = norm(objs[oid][0], moves[mi][2:]); mi += 1
    cur = set((a, b) for i, a in enumerate(ids) for b in ids[i+1:] if overlap(objs[a], objs[b]))
    for name, s in (('all', cur), ('began', cur - prev), ('ended', prev - cur)):
        for a, b in sorted(s): out[name].write(f'{fr},{a},{b}\n')
    prev = cur
EOF

for w in all began ended; do
  if "$cli" world "$tmp/objects.csv" "$tmp/moves.csv" --pairs "$w" -o "$tmp/got-$w" &&
    cmp -s "$tmp/got-$w" "$tmp/want-$w"; then
    passes=$((passes + 1))
  else
    fail "world --pairs $w differs from the brute force (seed $seed)"
    diff "$tmp/got-$w" "$tmp/want-$w" | head -5
  fi
done
[ "$(wc -l <"$tmp/want-all")" -gt 100 ] || fail "the scene has too few pairs to test anything"

# Errors name file and line; nothing is written on error.
printf 'id,kind,x,y,a,b\n1,disc,0,0,1\n2,blob,0,0,1\n' >"$tmp/badkind.csv"
expect 1 'badkind.csv:3:3: unknown kind .blob.' -- "$cli" world "$tmp/badkind.csv" "$tmp/moves.csv"
printf 'id,kind,x,y,a,b\n1,disc,0,0,1\n2,box,0,nan,1,1\n' >"$tmp/nan.csv"
expect 1 'nan.csv:3:9: coordinate is not finite' -- "$cli" world "$tmp/nan.csv" "$tmp/moves.csv"
printf 'id,kind,x,y,a,b\n1,disc,0,0,-1\n' >"$tmp/neg.csv"
expect 1 'neg.csv:2:12: disc radius is negative' -- "$cli" world "$tmp/neg.csv" "$tmp/moves.csv"
printf 'id,kind,x,y,a,b\n1,disc,0,0,1\n2,box,0,0,1,1\n1,point,0,0\n' >"$tmp/dup.csv"
expect 1 'dup.csv:4: id 1 appears twice \(also on line 2\)' -- "$cli" world "$tmp/dup.csv" "$tmp/moves.csv"
printf 'id,kind,x,y,a,b\n18446744073709551616,disc,0,0,1\n' >"$tmp/bigid.csv"
expect 1 'bigid.csv:2:1: id is above 2\^64 - 1' -- "$cli" world "$tmp/bigid.csv" "$tmp/moves.csv"
printf 'id,kind,x,y,a,b\n1,disc,0,0,1\n2,point,5,5\n' >"$tmp/two.csv"
printf 'frame,id,x,y,a,b\n0,1,1,1,1\n0,3,0,0\n' >"$tmp/unknown.csv"
expect 1 'unknown.csv:3:3: unknown id .3.' -- "$cli" world "$tmp/two.csv" "$tmp/unknown.csv"
printf 'frame,id,x,y,a,b\n2,1,1,1,1\n1,2,0,0\n' >"$tmp/order.csv"
expect 1 'order.csv:3:1: frames out of order' -- "$cli" world "$tmp/two.csv" "$tmp/order.csv"
printf 'frame,id,x,y,a,b\n0,1,1,inf,1\n' >"$tmp/inf.csv"
expect 1 'inf.csv:2:7: coordinate is not finite' -- "$cli" world "$tmp/two.csv" "$tmp/inf.csv"
# Unused fields may be empty or numbers, nothing else; a seventh field is an error, not dropped.
printf 'id,kind,x,y,a,b\n1,point,0,0,0,0\n2,disc,0,0,1,\n3,point,0,1,junk\n' >"$tmp/junk.csv"
expect 1 'junk.csv:4:13: field .junk. is not used' -- "$cli" world "$tmp/junk.csv" "$tmp/moves.csv"
printf 'id,kind,x,y,a,b\n1,disc,0,0,1,,7\n' >"$tmp/seven.csv"
expect 1 'seven.csv:2: expected id,kind,x,y' -- "$cli" world "$tmp/seven.csv" "$tmp/moves.csv"
printf 'frame,id,x,y,a,b\n0,1,1,1,1,,\n' >"$tmp/seven-moves.csv"
expect 1 'seven-moves.csv:2: expected frame,id,x,y' -- "$cli" world "$tmp/two.csv" "$tmp/seven-moves.csv"
printf 'frame,id,x,y,a,b\n0,1,1\n' >"$tmp/short.csv"
expect 1 'short.csv:2: ' -- "$cli" world "$tmp/two.csv" "$tmp/short.csv"
expect 1 'missing.csv' -- "$cli" world "$tmp/missing.csv" "$tmp/order.csv"
"$cli" world "$tmp/two.csv" "$tmp/order.csv" -o "$tmp/partial.csv" 2>/dev/null
[ ! -e "$tmp/partial.csv" ] && passes=$((passes + 1)) || fail "a failed run left an output file"
expect 2 'pairs must be all, began or ended' -- "$cli" world "$tmp/two.csv" "$tmp/two.csv" --pairs some
expect 2 'usage' -- "$cli" world "$tmp/two.csv"
expect 0 'usage: quadkit world' -- "$cli" world --help
# Huge coordinates with unit objects, and tiny with big ones, keep their pairs.
printf 'id,kind,x,y,a,b\n1,disc,1e9,1e9,0.5\n2,disc,1000000001,1e9,0.5\n3,box,-1e9,5,-999999999,6\n4,point,-1e9,6\n5,disc,0,0,1000\n6,disc,1000.0005,0,0.001\n' >"$tmp/huge.csv"
printf 'frame,id,x,y,a,b\n' >"$tmp/none.csv"
"$cli" world "$tmp/huge.csv" "$tmp/none.csv" >"$tmp/got"
printf 'frame,a,b\n0,1,2\n0,3,4\n0,5,6\n' >"$tmp/want"
cmp -s "$tmp/got" "$tmp/want" && passes=$((passes + 1)) || fail "huge world: $(cat "$tmp/got")"

# simulate: JSON with the per-frame counts, and an SVG.
expect 0 '"pairs": \[[0-9]+(, [0-9]+){4}\]' -- "$cli" simulate --n 300 --frames 5 --seed 3
"$cli" simulate --n 200 --frames 3 --svg "$tmp/s.svg" >/dev/null &&
  grep -q '#d62728' "$tmp/s.svg" && passes=$((passes + 1)) || fail "simulate --svg"
expect 2 'must be a whole number' -- "$cli" simulate --n 0
report
