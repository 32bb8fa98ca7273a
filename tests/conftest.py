"""Fixtures shared by all tests: small synthetic point files and the real data in ../shared."""
from pathlib import Path

import numpy as np
import pytest

from floodmesh.core import io
from floodmesh.core.demo import synthetic_floodplain

REPO = Path(__file__).resolve().parent.parent
REAL_DATA = REPO.parent / "shared" / "data" / "real"


@pytest.fixture(scope="session")
def demo_points_file(tmp_path_factory):
    """The demo floodplain at 2 ground points/m² (fast) as a classified LAZ file."""
    points, classes = synthetic_floodplain(density=2.0, seed=1)
    path = tmp_path_factory.mktemp("demo") / "floodplain.laz"
    io.write_points_las(path, points, classes=classes)
    return path


@pytest.fixture
def real_data():
    if not REAL_DATA.is_dir():
        pytest.skip("../shared/data/real is not beside this checkout")
    return REAL_DATA


def plane_points(a=0.1, b=-0.05, c=12.0, size=40.0, density=4.0, seed=0, origin=(500000.0, 6e6)):
    """Random points on the plane z = a·x + b·y + c (local x, y), as an (N, 3) array."""
    rng = np.random.default_rng(seed)
    n = int(size * size * density)
    x, y = rng.uniform(0, size, n), rng.uniform(0, size, n)
    return np.column_stack([x + origin[0], y + origin[1], a * x + b * y + c])


def pytest_terminal_summary(terminalreporter):
    """Say how many random meshing cases ran (tests/core/test_mesh_fuzz.py)."""
    from . import fuzz_stats

    line = fuzz_stats.summary()
    if line:
        terminalreporter.write_line(line)
