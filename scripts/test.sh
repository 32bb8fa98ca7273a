#!/usr/bin/env bash
# Runs every test (core and QGIS) in the project's environment, headless.
set -euo pipefail
cd "$(dirname "$0")/.."
export QT_QPA_PLATFORM=offscreen
exec .venv/bin/python -m pytest "$@"
