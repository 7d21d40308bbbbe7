#!/usr/bin/env bash
# `cmake --install` gives a usable package: a consumer project finds quadkit with
# find_package() and with pkg-config, links it, and runs.
set -eu
cli=$1
build=$(dirname "$cli")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cmake --install "$build" --prefix "$tmp/prefix" >/dev/null
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
target_link_libraries(app PRIVATE quadkit::quadkit_static)
C
cmake -S "$tmp/app" -B "$tmp/app/build" -DCMAKE_PREFIX_PATH="$tmp/prefix" \
  -DCMAKE_C_FLAGS="$san" -DCMAKE_EXE_LINKER_FLAGS="$san" >/dev/null
cmake --build "$tmp/app/build" >/dev/null
"$tmp/app/build/app"
libdir=$(find "$tmp/prefix" -name quadkit.pc -printf '%h\n' | head -1)
PKG_CONFIG_PATH=$libdir cc $san "$tmp/app/main.c" -o "$tmp/app/app-pc" \
  $(PKG_CONFIG_PATH=$libdir pkg-config --cflags quadkit) \
  $(PKG_CONFIG_PATH=$libdir pkg-config --libs --static quadkit)
LD_LIBRARY_PATH=$(dirname "$libdir") "$tmp/app/app-pc"
echo "2 passed, 0 failed"
