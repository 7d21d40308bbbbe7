#!/usr/bin/env bash
# index/ owns the quadtree's layout (issue 11): outside index/, C sources reach nodes and
# points only through index/index_access.h. Fails, listing each offending line, when a
# .c/.h file outside index/ names a layout field (->nodes[, ->side[, ->px, ->py, ->pid),
# the node type qk__node_t, or includes index_internal.h. The layout-level prototypes
# under bench/proto/ (and bench/proto_*.c until they move there) are exempt: measuring
# layouts is what they are for. Usage: scripts/check-layout.sh [source-dir]
set -euo pipefail
cd "${1:-$(dirname "$0")/..}"
# `->nodes[` and `->side[` count when the receiver is a tree (t, tree, or a name ending in
# "tree", as c->tree or g->tree): other structs have fields called side (a CLI option
# table, say). The point fields and the node type are specific enough to match anywhere.
pattern='(\bt|tree)->(nodes|side)\[|->(px|py|pid)\b|\bqk__node_t\b|index_internal\.h'
hits=$(git ls-files -co --exclude-standard -- '*.c' '*.h' 2>/dev/null ||
  find . -name '*.[ch]' -not -path './build*' | sed 's|^\./||')
bad=$(printf '%s\n' "$hits" | grep -v -E '^(index/|bench/proto/|bench/proto_[^/]*\.c$)' |
  while IFS= read -r f; do
    [ -f "$f" ] && grep -n -H -E -- "$pattern" "$f" || true
  done)
if [ -n "$bad" ]; then
  echo "check-layout: index/'s layout used outside index/ (use index/index_access.h):" >&2
  printf '%s\n' "$bad" >&2
  exit 1
fi
# The modules on index/ stand side by side: a source of query/, region/, collide/, mesh/
# or io/ includes headers of its own module, of index/ and the public ones (quadkit/)
# only. index/ includes none but its own and the public ones.
cross=$(printf '%s\n' "$hits" | grep -E '^(index|query|region|collide|mesh|io)/[^/]*\.[ch]$' |
  while IFS= read -r f; do
    [ -f "$f" ] || continue
    own=${f%%/*}
    allowed="$own|quadkit"
    [ "$own" = index ] || allowed="$allowed|index"
    grep -n -H -E '^[[:space:]]*#[[:space:]]*include[[:space:]]*"[a-z_]+/' "$f" |
      grep -v -E "#[[:space:]]*include[[:space:]]*\"($allowed)/" || true
  done)
if [ -n "$cross" ]; then
  echo "check-layout: a module includes another module's header (only its own, index/ and quadkit/):" >&2
  printf '%s\n' "$cross" >&2
  exit 1
fi
echo "check-layout: OK"
