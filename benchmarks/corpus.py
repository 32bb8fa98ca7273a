"""The evaluation corpus of analytic floodplains (issue 28): terrains whose true surface and true
break lines are known, none of them the demo case the defaults were first tuned on. Each is a
``demo.Floodplain`` on the demo's 300 x 240 m area (local metres; a gently rising plain with a
"river" whose banks and every feature's crest and toe are the true lines). ``fidelity.py``
surveys each at the noise and density asked and scores the chain against the truth.

- demo geometry, seed 7: the demo's features (meandering river, tributary, levee, road,
  terrace) surveyed with a seed the tuning never saw.
- oblique geometry, seed 11: a straight river at 32° to the grid, a tributary, a levee, a road.
- angle 0° … 90° (seeds 13 + the angle): three parallel embankments at 0, 15, 30, 45, 60, 75
  and 90° to the grid, through the whole area (no line ends inside it: short embankments'
  rounded ends, which no true line describes, took most of the error when the angles shared
  one terrain), on a plain rising gently from a river south of the area.
- crossings, seed 17: a road embankment at 70° over a channel (the channel cuts it) and over a
  levee, and a second embankment meeting the levee (a junction).
- narrow embankments at 10° and at 80° (seeds 19, 23): crests 1 m wide with side slopes 1, 2
  and 3 cells wide, parallel, through the whole area, on the same plain.
"""
from __future__ import annotations

import shapely

from floodmesh.core.frontends import demo

Profile = demo.Profile


def _straight(angle: float, through: tuple[float, float], length: float = 500.0):
    """A straight centreline at ``angle``° to the grid's x axis through ``through``."""
    import math

    dx, dy = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    x, y = through
    return shapely.LineString([(x - dx * length / 2, y - dy * length / 2),
                               (x + dx * length / 2, y + dy * length / 2)])


_river = shapely.LineString([(-20, 28), (320, 238)])
OBLIQUE = demo.Floodplain({
    "river": (_river, Profile(-2.0, 5.0, 9.0)),
    "tributary": (shapely.LineString([(30, 260), (70, 190), (120, 114)]),
                  Profile(-1.5, 2.5, 5.5)),
    "levee": (_river.offset_curve(-32.0), Profile(1.2, 1.5, 5.1)),
    "road": (shapely.LineString([(175, -10), (240, 50), (320, 90)]), Profile(2.0, 3.5, 6.5)),
}, terrace=None)



# ``demo.ground_elevation`` raises the plain away from the feature named "river", taken as a
# function of x: for lines at any angle the river runs outside the area, south of it, and the
# plain rises gently (0.4 %) to the north
_SOUTH_RIVER = (shapely.LineString([(-50.0, -40.0), (350.0, -40.0)]), Profile(-2.0, 4.0, 8.0))


def angled(angle: float) -> demo.Floodplain:
    """Three embankments (1.5 m high, 3 m crest, 1:2 sides) at ``angle``° to the grid,
    parallel, through the whole area: no line ends, crossings or meanders inside it."""
    middle = _straight(angle, (150.0, 120.0))
    return demo.Floodplain({
        "river": _SOUTH_RIVER,
        **{f"embankment {k}": (middle.offset_curve(offset), Profile(1.5, 1.5, 4.5))
           for k, offset in enumerate((-70.0, 0.0, 70.0))},
    }, terrace=None)


_channel = shapely.LineString([(-20, 60), (120, 110), (320, 130)])
CROSSINGS = demo.Floodplain({
    "river": (_channel, Profile(-2.0, 4.0, 8.0)),
    "road": (_straight(70.0, (150.0, 120.0), 320.0), Profile(1.5, 3.0, 6.0)),
    "levee": (_channel.offset_curve(-45.0), Profile(1.2, 1.5, 4.5)),
    "embankment": (shapely.LineString([(200, -10), (245, 75)]), Profile(1.2, 1.5, 4.5)),
}, terrace=None)

def narrow(angle: float) -> demo.Floodplain:
    """Three narrow embankments (0.8 m high, crest 1 m wide, side slopes 1, 2 and 3 m wide:
    cells at the reference 1 m grid) at ``angle``° to the grid, parallel, through the whole
    area."""
    middle = _straight(angle, (150.0, 120.0))
    return demo.Floodplain({
        "river": _SOUTH_RIVER,
        **{f"narrow, {w} m sides": (middle.offset_curve(offset), Profile(0.8, 0.5, 0.5 + w))
           for w, offset in ((1, -70.0), (2, 0.0), (3, 70.0))},
    }, terrace=None)


TERRAINS = {
    "demo geometry, seed 7": (demo.DEMO, 7),
    "oblique geometry, seed 11": (OBLIQUE, 11),
    **{f"angle {a}°, seed {13 + a}": (angled(float(a)), 13 + a)
       for a in (0, 15, 30, 45, 60, 75, 90)},
    "crossings, seed 17": (CROSSINGS, 17),
    "narrow embankments at 10°, seed 19": (narrow(10.0), 19),
    "narrow embankments at 80°, seed 23": (narrow(80.0), 23),
}
