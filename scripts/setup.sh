#!/usr/bin/env bash
# Sets up everything FloodMesh needs on Debian 12 or 13: QGIS and the scientific stack from
# Debian's packages, then a virtual environment that sees them (--system-site-packages) and adds
# what Debian lacks (triangle, laspy+lazrs, numba, shapely 2) from PyPI, pinned to the versions of
# Debian's Python packages installed here (.venv/constraints.txt, written below).
# Safe to run again: it installs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

DEB_PACKAGES=(qgis python3-qgis qgis-providers python3-venv python3-numpy python3-scipy
              python3-rasterio python3-fiona python3-pyproj python3-matplotlib gdal-bin
              python3-setuptools python3-wheel)
# Debian's Python packages that pip must never replace (QGIS, GDAL and each other are built
# against them): the environment is pinned to the versions installed.
SYSTEM_PINS=(numpy scipy rasterio fiona pyproj matplotlib)
DEB_PACKAGES+=(xvfb xauth)  # a virtual display for the desktop QGIS test (tests/qgis/test_desktop.py)
DEB_PACKAGES+=(gcc python3-dev)  # numba's ahead-of-time build of the raster kernels (core/_kernels/aot.py)
# shapely: Debian's own where it is shapely 2 (Debian 13: 2.1, built against the GEOS that QGIS
# links). QGIS 3.40's qgis.core imports shapely itself, so a PyQGIS script run from .venv would
# otherwise load PyPI's wheel, with a GEOS of its own, into a process that has QGIS's. Debian 12's
# is shapely 1.8: there the wheel comes from PyPI (and only the worker, never QGIS, imports it).
shapely_candidate() { apt-cache policy python3-shapely 2>/dev/null | awk '/Candidate:/ {print $2}'; }
shapely_candidate=$(shapely_candidate)
if { [ -z "$shapely_candidate" ] || [ "$shapely_candidate" = "(none)" ]; } \
        && ! ls /var/lib/apt/lists/*_Packages* >/dev/null 2>&1; then
    # a fresh machine has no package lists yet: fetch them before asking
    $( [ "$(id -u)" -eq 0 ] || echo sudo ) apt-get -o DPkg::Lock::Timeout=600 update -qq
    shapely_candidate=$(shapely_candidate)
fi
if [ -n "$shapely_candidate" ] && [ "$shapely_candidate" != "(none)" ] \
        && dpkg --compare-versions "$shapely_candidate" ge 2; then
    DEB_PACKAGES+=(python3-shapely)
    SYSTEM_PINS+=(shapely)
fi

missing=()
for p in "${DEB_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing Debian packages: ${missing[*]}"
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    # wait for another apt (another setup, unattended upgrades) instead of failing at once
    APT=(apt-get -o DPkg::Lock::Timeout=600 -o Acquire::Retries=3)
    $SUDO "${APT[@]}" update -qq
    $SUDO "${APT[@]}" install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv (Debian python with system site-packages)"
    /usr/bin/python3 -m venv --system-site-packages .venv
fi
# constraints.txt (the project's own pins) plus the system's versions, e.g. numpy 1.24.2 on
# Debian 12 and 2.2.4 on Debian 13
{ cat constraints.txt
  /usr/bin/python3 -I - "${SYSTEM_PINS[@]}" <<'EOF'
import sys
from importlib.metadata import PackageNotFoundError, version
for name in sys.argv[1:]:
    try:
        print(f"{name}=={version(name)}")
    except PackageNotFoundError:
        pass
EOF
} >.venv/constraints.txt.new
# a shapely wheel an earlier setup put into .venv gives way to the system's pinned one
if grep -q '^shapely==' .venv/constraints.txt.new \
        && [ -n "$(compgen -G '.venv/lib/python3*/site-packages/shapely' || true)" ]; then
    echo "setup: using Debian's python3-shapely instead of PyPI's wheel"
    .venv/bin/pip uninstall -q -y shapely
fi
stamp=.venv/.floodmesh-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ core/requirements.txt -nt "$stamp" ] \
        || ! cmp -s .venv/constraints.txt.new .venv/constraints.txt; then
    echo "setup: installing Python dependencies into .venv ($(grep '^numpy' .venv/constraints.txt.new))"
    # the build backend is Debian's setuptools (python3-setuptools), not one that pip would fetch
    # into an isolated build environment
    .venv/bin/pip install -q --disable-pip-version-check --no-build-isolation \
        -c .venv/constraints.txt.new -e ".[test]"
    touch "$stamp"
fi
mv .venv/constraints.txt.new .venv/constraints.txt  # only once pip has kept to it
# the fort.14/hgrid.gr3 readers ADCIRC and SCHISM users script with, for the export tests: their
# parsers only, without the dependencies (which would pull in a second numpy)
if ! .venv/bin/python -c "import importlib.util as u, sys; sys.exit(not (u.find_spec('pyschism') and u.find_spec('adcircpy')))"; then
    .venv/bin/pip install -q --disable-pip-version-check --no-deps pyschism==0.1.15 adcircpy==1.2.7
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

# Compile the numba kernels now (about 2 minutes, once; seconds when cached), not in the first run.
.venv/bin/python -m floodmesh.core.frontends.warmup
# Byte-compile the package as pip does for a regular install (an editable one leaves it to the
# first import, which cannot write where PYTHONDONTWRITEBYTECODE is set): compiling FloodMesh's
# modules from source costs every `floodmesh` process about 0.1 s of CPU, 8 % of `floodmesh slope`
# on a 6000² DEM.
.venv/bin/python -m compileall -q __init__.py core algorithms provider >/dev/null

# QGIS finds plugins by folder name: build/plugins/floodmesh is this repository.
mkdir -p build/plugins
ln -sfn "$(pwd)" build/plugins/floodmesh
echo "setup: ready"
