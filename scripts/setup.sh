#!/usr/bin/env bash
# Sets up everything FloodMesh needs on Debian 12: QGIS and the scientific stack from Debian's
# packages, then a virtual environment that sees them (--system-site-packages) and adds what
# Debian lacks (triangle, laspy+lazrs, numba, shapely 2) from PyPI, pinned to Debian's numpy.
# Safe to run again: it installs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

DEB_PACKAGES=(qgis python3-qgis qgis-providers python3-venv python3-numpy python3-scipy
              python3-rasterio python3-fiona python3-pyproj python3-matplotlib gdal-bin)

missing=()
for p in "${DEB_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing Debian packages: ${missing[*]}"
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv (Debian python with system site-packages)"
    /usr/bin/python3 -m venv --system-site-packages .venv
fi
stamp=.venv/.floodmesh-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ constraints.txt -nt "$stamp" ]; then
    echo "setup: installing Python dependencies into .venv"
    .venv/bin/pip install -q --disable-pip-version-check -c constraints.txt -e ".[test]"
    touch "$stamp"
fi

# pyproj looks for PROJ's data under sys.prefix, which in a venv is the venv: point it at Debian's.
mkdir -p .venv/share
[ -e .venv/share/proj ] || ln -s /usr/share/proj .venv/share/proj

# ANUGA, the flood solver of `floodmesh flood`, needs numpy >= 2, which Debian 12's QGIS stack
# (numpy 1.24) cannot share a process with, and Debian's rasterio breaks its import: it gets its
# own environment without system site packages; FloodMesh runs it as a child process.
if [ ! -x .venv-flood/bin/python ]; then
    echo "setup: creating .venv-flood (ANUGA's environment)"
    /usr/bin/python3 -m venv .venv-flood
fi
if ! OMP_NUM_THREADS=1 .venv-flood/bin/python -c "import anuga" >/dev/null 2>&1; then
    echo "setup: installing ANUGA into .venv-flood"
    .venv-flood/bin/pip install -q --disable-pip-version-check "anuga==4.2.0" \
        || echo "setup: ANUGA could not be installed; floodmesh flood will say so"
fi

# QGIS finds plugins by folder name: build/plugins/floodmesh is this repository.
mkdir -p build/plugins
ln -sfn "$(pwd)" build/plugins/floodmesh
echo "setup: ready"
