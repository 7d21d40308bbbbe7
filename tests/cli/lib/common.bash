# Shared by the CLI test scripts (sourced; not a test itself, so it lives outside the
# tests/cli/*.sh glob). Usage: source it with the CLI binary and source dir as $1 and $2.
# Sets cli, src, a temporary directory tmp (removed at exit), and the counters.
set -u
cli=$1
src=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fails=0
passes=0
skips=0

fail() { # fail MESSAGE: count a failure and say what it was
  echo "FAIL: $*"
  fails=$((fails + 1))
}

expect() { # expect CODE PATTERN -- command...: exit status and a line matching PATTERN
  local code=$1 pat=$2
  shift 3
  local out rc
  out=$("$@" 2>&1)
  rc=$?
  if [ "$rc" -ne "$code" ] || ! grep -qE -- "$pat" <<<"$out"; then
    fail "$* -> exit $rc (want $code), output: $out (want /$pat/)"
  else
    passes=$((passes + 1))
  fi
}

same_text() { # same_text NAME GOT WANT: two strings are equal
  if [ "$2" = "$3" ]; then
    passes=$((passes + 1))
  else
    fail "$1: got '$2', want '$3'"
  fi
}

nothing_written() { # nothing_written PREFIX: no PREFIX.node / .ele, no temporary beside it
  local d
  d=$(dirname "$1")
  if [ -e "$1.node" ] || [ -e "$1.ele" ] || ls "$d" | grep -q '\.tmp\.'; then
    fail "$1: an output or a temporary was left after an error"
  else
    passes=$((passes + 1))
  fi
}

skip() { # skip REASON: a check not run here, said so (never counted as passed)
  echo "SKIP: $*"
  skips=$((skips + 1))
}

report() { # the closing line ctest and CI read, and the script's status
  if [ "$skips" -gt 0 ]; then
    echo "$passes passed, $fails failed, $skips skipped"
  else
    echo "$passes passed, $fails failed"
  fi
  [ "$fails" -eq 0 ]
}
