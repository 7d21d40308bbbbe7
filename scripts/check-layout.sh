#!/usr/bin/env bash
# index/ owns the quadtree's layout (issue 11): outside index/, C sources reach nodes and
# points only through index/index_access.h. Fails, listing each offending line, when a
# .c/.h file outside index/ names a layout field (->nodes[, ->side[, ->px, ->py, ->pid),
# the node type qk__node_t, or includes index_internal.h. The layout-level prototypes
# under bench/proto/ (and bench/proto_*.c until they move there) are exempt: measuring
# layouts is what they are for. Then, at the compiler level, clang parses every .c file of
# query/, region/, collide/, mesh/, io/ and tools/ with the real build's flags and
# scripts/check_layout_ast.py lists each use of a field of struct qk_tree, qk__node or
# qk__block whose name is written outside index/, whatever the variable or macro (index/'s
# own inline accessors are allowed). Without clang (under CI as root: installed by
# install-deps.sh fuzz), cmake or python3 that part is skipped, and says so. It sees the
# code this machine compiles (x86-64, and again without SSE2): a branch for another
# processor (#if defined(__aarch64__)) is not parsed; offsetof() of a layout struct, which
# the syntax tree does not name by field, is caught by the grep pattern.
# Usage: scripts/check-layout.sh [source-dir]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "${1:-$here/..}"
# `->nodes[` and `->side[` count when the receiver is a tree (t, tree, or a name ending in
# "tree", as c->tree or g->tree): other structs have fields called side (a CLI option
# table, say). The point fields and the node type are specific enough to match anywhere.
pattern='(\bt|tree)->(nodes|side)\[|->(px|py|pid)\b|\bqk__node_t\b|index_internal\.h|offsetof[[:space:]]*\([[:space:]]*(struct[[:space:]]+)?(qk_tree|qk__node|qk__block)\b'
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

# The compiler-level check: exact where the patterns above are not (a field called count,
# depth or where exists in other structs too; `tr->n_nodes` passes them).
# (Under CI, as root, clang is installed as for the fuzzers; if it is still missing then,
# the check fails rather than pass unchecked.)
installed=""
if ! command -v clang >/dev/null 2>&1 && [ "${CI:-}" = true ] && [ "$(id -u)" -eq 0 ]; then
  bash "$here/install-deps.sh" fuzz
  installed=1
fi
for tool in clang cmake python3; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    if [ -n "$installed" ]; then
      echo "check-layout: $tool not found after install-deps.sh fuzz: compiler-level check not run" >&2
      exit 1
    fi
    echo "check-layout: grep checks OK, but the compiler-level check was SKIPPED, not passed:" \
      "$tool not found (bash scripts/install-deps.sh fuzz installs clang)" >&2
    exit 0
  fi
done
tmp=$(mktemp -d "${TMPDIR:-/tmp}/check-layout.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
# The build's own flags and defines (QK_HAVE_JSONC, QK_HAVE_GDAL, ... as found on this
# machine), from a configuration of its own: a build directory may be stale or absent.
if ! cmake -S "$PWD" -B "$tmp" -DCMAKE_C_COMPILER=clang -DCMAKE_EXPORT_COMPILE_COMMANDS=ON \
  -DQUADKIT_BUILD_TESTS=OFF -DQUADKIT_BUILD_BENCH=OFF >"$tmp/cmake.log" 2>&1; then
  echo "check-layout: cmake could not configure the build for the compiler-level check:" >&2
  cat "$tmp/cmake.log" >&2
  exit 1
fi
parsed=$(PYTHONDONTWRITEBYTECODE=1 python3 "$here/check_layout_ast.py" "$tmp/compile_commands.json" "$PWD" clang) || exit 1
echo "check-layout: OK (grep checks; clang: no field of index/'s layout used outside index/ in $parsed)"
