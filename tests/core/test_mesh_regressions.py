"""Fixed cases that the mesh fuzz tests (tests/core/test_mesh_fuzz.py, `make fuzz`) or a random
search once found failing, kept exactly as found so that every run checks them."""
import numpy as np
import shapely

from floodmesh.core.mesh import below_angle_bound, build_pslg, triangulate_pslg

# A valid star-shaped domain: on its 0.04 m snapping grid, the domain shrunk by the 0.2 m snap
# distance came out invalid, and clipping the lines to it raised GEOS's "TopologyException: side
# location conflict at 3.888 7.32" out of build_pslg (about one draw in 33,000).
GEOS_DOMAIN = shapely.from_wkt(
    "POLYGON ((8.275895734818665 8.133786236349156, 4.094561751343572 7.38027379968444, "
    "3.3361032034066858 9.11896309837189, 3.262191051860615 8.665235120886015, "
    "3.7322826451666855 7.105956992320152, 1.2472228801621057 7.678928723839855, "
    "6.343711603816422 3.471716889212696, 8.275895734818665 8.133786236349156))")
GEOS_LINES = [
    np.array([[1.1856853437305948, 8.090216361065686], [0.9124956385278937, 9.395626040703473]]),
    np.array([[8.215006565214544, 3.5966964210939425], [2.1015548722285606, 9.496696924452717],
              [3.76737770449608, 4.792075877736376]])]


def test_valid_domain_whose_shrunk_copy_rounds_invalid_meshes():
    assert GEOS_DOMAIN.is_valid
    pslg = build_pslg(GEOS_LINES, GEOS_DOMAIN, snap=0.2)
    vertices, triangles = triangulate_pslg(pslg, min_angle=30, max_area=0.05,
                                           area=GEOS_DOMAIN.area)
    defects, _ = below_angle_bound(vertices, triangles, pslg.segments, 30)
    assert len(triangles) > 100 and not defects.any()
