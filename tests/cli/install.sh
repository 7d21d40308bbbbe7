#!/usr/bin/env bash
# `cmake --install` gives a usable package: a consumer project finds quadkit with
# find_package() and links each of the three targets (quadkit::quadkit, the shared
# library; quadkit::quadkit_shared; quadkit::quadkit_static), a consumer built with
# pkg-config links it shared and static, and every program runs. The ldconfig step runs
# only for a system prefix (checked with a stand-in ldconfig and a stand-in prefix list,
# so nothing outside the temporary directory is touched).
# shellcheck source=lib/common.bash
source "$(dirname "${BASH_SOURCE[0]}")/lib/common.bash" "$@"
build=$(dirname "$cli")
if ! cmake --install "$build" --prefix "$tmp/prefix" >"$tmp/install.log" 2>&1; then
  fail "cmake --install: $(cat "$tmp/install.log")"
  report
  exit
fi
grep -q 'ldconfig' "$tmp/install.log" && fail "ldconfig mentioned for a private prefix: $(cat "$tmp/install.log")"
# A sanitized library needs its runtime in the consumer too.
san=""
if [ "${QK_SANITIZE:-0}" = 1 ]; then san="-fsanitize=address,undefined"; fi
mkdir -p "$tmp/app"
cat >"$tmp/app/main.c" <<'C'
#include <quadkit/quadkit.h>
#include <stdio.h>
int main(void) {
  qk_point_t p[3] = {{0, 0}, {1, 1}, {0.25, 0.75}};
  qk_tree_t *t;
  if (qk_tree_build(p, 3, NULL, &t) != QK_OK) return 1;
  qk_tree_stats_t s;
  qk_tree_stats(t, &s);
  printf("leaves %zu\n", s.leaves);
  qk_tree_free(t);
  return s.leaves == 4 ? 0 : 1;
}
C
cat >"$tmp/app/CMakeLists.txt" <<'C'
cmake_minimum_required(VERSION 3.25)
project(app C)
find_package(quadkit REQUIRED)
add_executable(app main.c)
target_link_libraries(app PRIVATE ${QK_TARGET})
C
for target in quadkit::quadkit quadkit::quadkit_shared quadkit::quadkit_static; do
  b="$tmp/app/build-${target#quadkit::}"
  if cmake -S "$tmp/app" -B "$b" -DCMAKE_PREFIX_PATH="$tmp/prefix" -DQK_TARGET="$target" \
    -DCMAKE_C_FLAGS="$san" -DCMAKE_EXE_LINKER_FLAGS="$san" >"$b.log" 2>&1 &&
    cmake --build "$b" >>"$b.log" 2>&1; then
    # No LD_LIBRARY_PATH: CMake gives the program a run path to the shared library.
    expect 0 '^leaves 4$' -- "$b/app"
    if [ "$target" = quadkit::quadkit_static ]; then
      ldd "$b/app" | grep -q libquadkit && fail "$target: the program needs libquadkit.so"
    else
      ldd "$b/app" | grep -q "$tmp/prefix/.*libquadkit.so" || fail "$target: not linked to the installed libquadkit.so"
    fi
  else
    fail "consumer linking $target did not build: $(tail -20 "$b.log")"
  fi
done
libdir=$(find "$tmp/prefix" -name quadkit.pc -printf '%h\n' | head -1)
export PKG_CONFIG_PATH=$libdir
# Shared, as a user would for a private prefix (a run path to pkg-config's libdir).
# shellcheck disable=SC2046
if cc $san "$tmp/app/main.c" -o "$tmp/app/app-pc" $(pkg-config --cflags quadkit) \
  $(pkg-config --libs quadkit) -Wl,-rpath,"$(pkg-config --variable=libdir quadkit)"; then
  expect 0 '^leaves 4$' -- "$tmp/app/app-pc"
else
  fail "pkg-config shared consumer did not build"
fi
# Static.
# shellcheck disable=SC2046
if cc $san "$tmp/app/main.c" -o "$tmp/app/app-pcs" $(pkg-config --cflags quadkit) \
  "$(pkg-config --variable=libdir quadkit)/libquadkit.a" \
  $(pkg-config --libs-only-l --static quadkit | sed 's/-lquadkit//'); then
  expect 0 '^leaves 4$' -- "$tmp/app/app-pcs"
else
  fail "pkg-config static consumer did not build"
fi
unset PKG_CONFIG_PATH

# The ldconfig step: run for a prefix in the system list, as root, without DESTDIR.
printf '#!/bin/sh\necho ran >"%s/ldconfig-ran"\n' "$tmp" >"$tmp/fake-ldconfig"
chmod +x "$tmp/fake-ldconfig"
install_with() { # install_with PREFIX-LIST: cmake_install.cmake with the stand-ins
  rm -f "$tmp/ldconfig-ran"
  cmake -DCMAKE_INSTALL_PREFIX="$tmp/prefix2" -DQK_LDCONFIG="$tmp/fake-ldconfig" \
    -DQK_LDCONFIG_PREFIXES="$1" -P "$build/cmake_install.cmake" >"$tmp/install2.log" 2>&1 ||
    fail "install into prefix2: $(cat "$tmp/install2.log")"
}
install_with "/usr;/usr/local"
[ -e "$tmp/ldconfig-ran" ] && fail "ldconfig ran for a prefix that is not a system one"
install_with "$tmp/prefix2"
if [ "$(id -u)" = 0 ]; then
  [ -e "$tmp/ldconfig-ran" ] && passes=$((passes + 1)) || fail "ldconfig did not run for a system prefix"
  DESTDIR="$tmp/stage" install_with "$tmp/prefix2"
  [ -e "$tmp/ldconfig-ran" ] && fail "ldconfig ran under DESTDIR"
else
  [ -e "$tmp/ldconfig-ran" ] && fail "ldconfig ran without root"
  grep -q 'run ldconfig' "$tmp/install2.log" && passes=$((passes + 1)) ||
    fail "no hint to run ldconfig: $(cat "$tmp/install2.log")"
fi
report
