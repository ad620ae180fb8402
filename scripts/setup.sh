#!/usr/bin/env bash
# Installs the Debian packages and npm modules hrad needs. Idempotent: does nothing when all are present.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
pkgs=(build-essential cmake pkg-config libembree-dev libtbb-dev libpng-dev gnuplot-nox
      valgrind chromium imagemagick assimp-testmodels libopenmpi-dev openmpi-bin
      libmetis-dev libassimp-dev libjpeg62-turbo-dev)
# `setup.sh --clang` (make fuzz, make test-ubsan): clang with libFuzzer and its OpenMP runtime.
[ "${1:-}" = --clang ] && pkgs+=(clang libclang-rt-dev libomp-dev)
# Node.js: any installed node with npm will do (nodesource's nodejs bundles npm and conflicts
# with Debian's npm package); otherwise take Debian's.
command -v node >/dev/null 2>&1 || pkgs+=(nodejs)
command -v npm >/dev/null 2>&1 || pkgs+=(npm)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}" >&2
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
# npm modules for the glTF validator test and the bundled viewer (versions pinned in package.json).
if [ ! -d "$here/node_modules/gltf-validator" ] || [ ! -d "$here/node_modules/three" ]; then
  echo "setup: npm install" >&2
  (cd "$here" && npm install --no-audit --no-fund --silent >/dev/null)
fi
