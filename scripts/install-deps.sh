#!/usr/bin/env bash
# Installs the Debian packages quadkit needs that are missing. Idempotent and quiet when
# everything is present. Usage: install-deps.sh [core|gdal|bench|fuzz|memcheck]...
# gdal: the optional OGR reader of region/ (every vector format GDAL reads); CMake compiles
# it in when it finds libgdal-dev, otherwise qk_region_read_ogr returns QK_ERR_UNSUPPORTED.
# It is large, so `make test` does not install it; CI (.ci/run) does, to build that path.
set -euo pipefail

want=(cmake make gcc g++ pkg-config libcmocka-dev libproj-dev libgmp-dev)
for set in "$@"; do
  case "$set" in
    core) want+=(libjson-c-dev) ;;
    gdal) want+=(libgdal-dev) ;;
    bench) want+=(libgeos-dev libs2-dev libgdal-dev libbox2d-dev libbullet-dev libflann-dev libnanoflann-dev libembree-dev libcgal-dev libp4est-dev libgmsh-dev libgeographiclib-dev gnuplot-nox liblz4-dev libhdf5-dev) ;;
    fuzz) want+=(clang libclang-rt-14-dev) ;;
    memcheck) want+=(valgrind) ;;
    *) echo "install-deps.sh: unknown set '$set'" >&2; exit 2 ;;
  esac
done

missing=()
for p in "${want[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "installing: ${missing[*]}" >&2
sudo=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null; then sudo=sudo; else
    echo "install-deps.sh: not root and no sudo; please install: ${missing[*]}" >&2; exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
if ! $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/tmp/quadkit-apt.log 2>&1; then
  $sudo apt-get update -qq >>/tmp/quadkit-apt.log 2>&1 || true
  if ! $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >>/tmp/quadkit-apt.log 2>&1; then
    echo "install-deps.sh: apt-get install failed (see /tmp/quadkit-apt.log)" >&2
    tail -n 20 /tmp/quadkit-apt.log >&2
    exit 1
  fi
fi
