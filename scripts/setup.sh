#!/usr/bin/env bash
# Installs every Debian 12 package twinforge needs to build, test and run.
# Non-interactive and idempotent: packages already present are left as they are.
# Nothing is downloaded from anywhere but Debian's package archive.
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake ninja-build pkg-config git clang-format
  # core
  libeigen3-dev nlohmann-json3-dev libyaml-cpp-dev libhdf5-dev libcli11-dev libspdlog-dev libfmt-dev
  # sim (MuJoCo's CMake config needs qhull)
  libmujoco-dev libqhull-dev libpng-dev libtinyxml2-dev
  # learn (LibTorch links libblas.so.3: OpenBLAS must be the one it resolves)
  libtorch-dev libopenblas0-pthread
  # real2sim
  libopen3d-dev libembree-dev
  # reference BLAS: only so a test can prove doctor rejects it
  libblas3
  # reality bridge
  libzmq3-dev cppzmq-dev libmsgpack-dev
  # twin editor: HTTP server; Chromium drives its page in the browser test
  libcpp-httplib-dev chromium
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
)

# The editor's page is bundled from npm packages: Debian's Node.js unless the machine has one.
command -v npm >/dev/null 2>&1 || packages+=(nodejs npm)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"

if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "setup: all ${#packages[@]} Debian packages already installed"
fi

# LibTorch must resolve libblas.so.3 to OpenBLAS, not the ~14x slower reference BLAS.
blas=$(update-alternatives --list libblas.so.3-x86_64-linux-gnu 2>/dev/null | grep -m1 openblas-pthread || true)
if [ -n "$blas" ]; then
  $sudo update-alternatives --set libblas.so.3-x86_64-linux-gnu "$blas" >/dev/null
fi
lapack=$(update-alternatives --list liblapack.so.3-x86_64-linux-gnu 2>/dev/null | grep -m1 openblas-pthread || true)
if [ -n "$lapack" ]; then
  $sudo update-alternatives --set liblapack.so.3-x86_64-linux-gnu "$lapack" >/dev/null
fi
# The editor's npm packages (three.js, esbuild, Playwright's driver without its browsers), exactly
# as web/package-lock.json pins them; skipped when node_modules is newer than the lock file.
web="$(dirname "$0")/../web"
if [ ! "$web/node_modules/.package-lock.json" -nt "$web/package-lock.json" ]; then
  echo "setup: installing the twin editor's npm packages (web/package-lock.json)"
  (cd "$web" && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error)
fi
echo "setup: done"
