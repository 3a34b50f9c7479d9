#!/usr/bin/env bash
# Runs every test of the workspace, the firmware under QEMU included.
# Installs what the tests need when it is missing: the Cortex-M4F Rust target, the LLVM tools (for
# size figures), qemu-system-arm and GDAL's command-line tools (Debian/Ubuntu: apt-get).
set -euo pipefail
cd "$(dirname "$0")/.."

if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
    echo "installing the thumbv7em-none-eabihf target" >&2
    rustup target add thumbv7em-none-eabihf
fi
if ! rustup component list --installed | grep -q '^llvm-tools'; then
    echo "installing llvm-tools" >&2
    rustup component add llvm-tools
fi
if ! command -v qemu-system-arm >/dev/null 2>&1; then
    echo "installing qemu-system-arm" >&2
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq qemu-system-arm >/dev/null
fi

if ! command -v gdalinfo >/dev/null 2>&1 || ! command -v gdal_translate >/dev/null 2>&1; then
    # The map tests open their GeoTIFFs in GDAL and make the input layouts with it.
    echo "installing gdal-bin" >&2
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq gdal-bin >/dev/null
fi

# Release profile: the oracle tests run ten thousand spectra and the training tests train.
cargo test --workspace --release "$@"
