"""The plugin's QGIS code keeps to what QGIS 3.22 and 3.40, Qt5 and Qt6 builds all accept: Qt
only through QGIS's ``qgis.PyQt`` shim, and the enums QGIS 3.30/3.36 moved into ``Qgis`` only
through algorithms/compat.py. A static check of the source (it needs no QGIS); the QGIS tests
run the same code on 3.22 (make test) and 3.40 (make test-debian13)."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLUGIN_CODE = sorted(p for folder in ("algorithms", "provider") for p in (ROOT / folder).glob("*.py")
                     if p.name != "compat.py") + [ROOT / "__init__.py"]
FORBIDDEN = {
    r"\bPyQt[56]\b(?!\.)|from PyQt[56]|import PyQt[56]": "import Qt through qgis.PyQt",
    r"\bimport sip\b|from sip\b": "no direct sip (qgis.PyQt.sip if ever needed)",
    r"QgsProcessing\.Type\w+": "compat.VECTOR_* (Qgis.ProcessingSourceType on 3.36+)",
    r"QgsProcessingParameterNumber\.(Double|Integer)\b": "compat.DOUBLE / compat.INTEGER",
    r"QgsWkbTypes\.\w+Z?\b": "compat.POINT_Z etc. (Qgis.WkbType on 3.30+)",
    r"\.exec_\(": "exec() (exec_ is gone in PyQt6)",
    r"\bQVariant\.\w+": "QMetaType types (QVariant.Type is deprecated in QGIS 3.38)",
}


def test_finds_the_plugin_code():
    assert len(PLUGIN_CODE) > 10


@pytest.mark.parametrize("pattern", FORBIDDEN)
def test_plugin_code_avoids_version_specific_api(pattern):
    hits = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in PLUGIN_CODE
            for n, line in enumerate(p.read_text().splitlines(), 1) if re.search(pattern, line)]
    assert not hits, f"use {FORBIDDEN[pattern]}: " + "; ".join(hits)
