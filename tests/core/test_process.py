"""The front ends' process settings (``frontends.process``)."""
import subprocess
import sys

import pytest

# An array freed and made again, its pages touched: how many page faults the second one costs
# (numpy's huge-page request off, so that a fault is one 4 KiB page)
SECOND_ARRAY_FAULTS = """
import resource, sys
import numpy as np
from floodmesh.core.frontends.process import keep_freed_memory
kept = keep_freed_memory() if sys.argv[1] == "kept" else None
a = np.ones(2_000_000)  # 16 MB, a gridding tile's Delaunay arrays' size
del a
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
b = np.ones(2_000_000)
print(kept, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _second_array(mode):
    out = subprocess.run([sys.executable, "-c", SECOND_ARRAY_FAULTS, mode], check=True,
                         capture_output=True, text=True,
                         env={"NUMPY_MADVISE_HUGEPAGE": "0", "PATH": ""}).stdout.split()
    return out[0], int(out[1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_freed_memory_is_kept_for_the_next_array():
    """By default glibc gives a freed 16 MB block back to the kernel and the next array faults
    its 3,900 pages in again; in a front end's process the heap keeps it."""
    _, default = _second_array("default")
    kept, faults = _second_array("kept")
    assert default > 3000
    assert kept == "True" and faults < 100
