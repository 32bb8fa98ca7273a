"""The smallest angle between the input segments at each node, vectorised, against the
definition (every pair of segments at a node) on random planar graphs."""
import numpy as np
import pytest

from floodmesh.core.steps.mesh import input_corner_angles


def _every_pair(nodes, segments):
    """The definition: the loop over nodes and all pairs that input_corner_angles replaced."""
    smallest = np.full(len(nodes), 180.0)
    incident = {}
    for a, b in segments:
        incident.setdefault(a, []).append(b)
        incident.setdefault(b, []).append(a)
    for v, others in incident.items():
        d = nodes[others, :2] - nodes[v, :2]
        d /= np.hypot(*d.T)[:, None]
        cos = np.clip(d @ d.T, -1, 1)
        np.fill_diagonal(cos, -1)
        smallest[v] = np.degrees(np.arccos(cos.max())) if len(others) > 1 else 180.0
    return smallest


@pytest.mark.parametrize("seed", range(4))
def test_input_corner_angles_are_the_every_pair_definition(seed):
    rng = np.random.default_rng(seed)
    nodes = np.column_stack([400_000 + rng.uniform(0, 50, 300), 5_600_000 + rng.uniform(0, 50, 300),
                             rng.uniform(0, 3, 300)])
    segments = rng.integers(0, 300, (600, 2))
    segments = segments[segments[:, 0] != segments[:, 1]]
    segments = np.vstack([segments, segments[:5]])  # a segment given twice meets itself at 0°
    expected = _every_pair(nodes, segments)
    ours = input_corner_angles(nodes, segments)
    np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-6)
    assert (ours[segments[:5].ravel()] < 1e-5).all()  # arccos near 1: a few 1e-7 °
    assert (ours[np.setdiff1d(np.arange(300), segments.ravel())] == 180.0).all()


def test_no_segments():
    assert (input_corner_angles(np.zeros((3, 3)), np.zeros((0, 2), int)) == 180.0).all()
