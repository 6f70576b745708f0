#!/usr/bin/env bash
# Build Stage 4.3 (GPL-2, from ../shared/tools/stage) beside the project as a test tool, then
# sitgen's Stage controller plugin against it. Nothing here is linked into sitgen itself.
#
#   integrations/stage/build.sh [BUILD_DIR]     (default: target/stage)
#
# Prints the path of the built `stage` binary on its last line. Exits 3, with a one-line reason,
# where the Stage source or the build tools are absent (the cross-check tests then skip).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
out="${1:-$root/target/stage}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
tarball="${SITGEN_STAGE_SOURCE:-$root/../shared/tools/stage/Stage-281ed731.tar.gz}"
[ -f "$tarball" ] || { echo "skip: Stage source not found at $tarball" >&2; exit 3; }

# Debian packages Stage's build names (its README); installed only where missing.
pkgs=(cmake g++ pkg-config libfltk1.3-dev fluid libltdl-dev libpng-dev libjpeg-dev libglu1-mesa-dev nlohmann-json3-dev)
missing=()
for p in "${pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if [ "${#missing[@]}" -gt 0 ]; then
    sudo=""; [ "$(id -u)" -ne 0 ] && sudo="sudo"
    { $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null; } \
        || { echo "skip: could not install ${missing[*]} (apt-get failed)" >&2; exit 3; }
fi

# Stage itself is the same build for every checkout of the same source: it is kept in the user's
# cache, one folder per source tarball, and a new clone links to it instead of building it
# again (about 3 minutes). SITGEN_STAGE_CACHE=none builds it inside BUILD_DIR instead.
prefix="$out/prefix"
cache_root="${SITGEN_STAGE_CACHE:-${XDG_CACHE_HOME:-${HOME:-}/.cache}/sitgen}"
if [ "$cache_root" != "none" ] && [ -n "${HOME:-}${XDG_CACHE_HOME:-}${SITGEN_STAGE_CACHE:-}" ]; then
    built="$cache_root/stage-$(sha256sum "$tarball" | cut -c1-16)"
    if [ ! -x "$built/prefix/bin/stage" ]; then
        work="$(mktemp -d "${TMPDIR:-/tmp}/sitgen-stage.XXXXXX")"
        tar xzf "$tarball" -C "$work"
        src="$(find "$work" -maxdepth 2 -name CMakeLists.txt -printf '%h\n' | head -1)"
        cmake -S "$src" -B "$work/build" -DCMAKE_BUILD_TYPE=Release \
            -DCMAKE_INSTALL_PREFIX="$built/prefix" >/dev/null
        make -C "$work/build" -j"$(nproc)" install >/dev/null
        rm -rf "$work"
    fi
    [ -L "$prefix" ] || rm -rf "$prefix"
    ln -sfn "$built/prefix" "$prefix"
elif [ ! -x "$prefix/bin/stage" ]; then
    rm -rf "$out/src" "$out/build"
    mkdir -p "$out/src"
    tar xzf "$tarball" -C "$out/src"
    src="$(find "$out/src" -maxdepth 2 -name CMakeLists.txt -printf '%h\n' | head -1)"
    cmake -S "$src" -B "$out/build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX="$prefix" >/dev/null
    make -C "$out/build" -j"$(nproc)" install >/dev/null
fi

cmake -S "$here" -B "$out/plugin" -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH="$prefix" \
    -DCMAKE_INSTALL_PREFIX="$prefix" >/dev/null
make -C "$out/plugin" -j"$(nproc)" install >/dev/null
echo "$prefix/bin/stage"
