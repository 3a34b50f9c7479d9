#!/usr/bin/env bash
# Runs every test of the workspace, the firmware under QEMU included, then the Python package's
# pytest suite.
# Installs what the tests need when it is missing: the Cortex-M4F Rust target, the LLVM tools (for
# size figures), qemu-system-arm and GDAL's command-line tools (Debian/Ubuntu: apt-get); and what
# the Python package needs (pip): maturin, pytest, numpy, xarray, dask, distributed, zarr.
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

PYTHON="${PYTHON:-python3}"
missing=()
for pkg in maturin pytest numpy xarray dask distributed zarr; do
    if ! "$PYTHON" -c "import $pkg" >/dev/null 2>&1; then missing+=("$pkg"); fi
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "installing ${missing[*]} (pip)" >&2
    "$PYTHON" -m pip install --quiet "${missing[@]}"
fi

# Release profile: the oracle tests run ten thousand spectra and the training tests train.
cargo test --workspace --release "$@"

# The Python package: the wheel (built in the workspace's target directory), installed, and its
# tests, which train tiny models with the `magic` binary and compare against it.
cargo build --release -p magic-train --bin magic
wheels=target/wheels/magic-py
rm -rf "$wheels"
"$PYTHON" -m maturin build --release --manifest-path magic-py/Cargo.toml --out "$wheels"
"$PYTHON" -m pip install --quiet --force-reinstall --no-deps "$wheels"/magic_py-*.whl
status=0
(cd magic-py && MAGIC_BIN="$PWD/../target/release/magic" "$PYTHON" -m pytest -p no:cacheprovider -q) \
    || status=$?
if [ "$status" -eq 5 ]; then
    echo "pytest collected no tests: the Python suite is missing" >&2
    exit 1
fi
exit "$status"
