"""The library of named worlds, each with a default robot path.

``hallway``
    A 40 m hallway, 2 m wide, like the one outside the paper's laboratory (Figs. 3-5): both
    walls broken by door recesses (doors set 0.2 m back), jogs where the hallway widens, one
    open door into a small office.  The robot drives down the hallway, turns round at the far
    end and drives back (≈ 75 m).
``lab``
    A cluttered 12 m × 9 m laboratory: desks along the west wall, a central bench, a round and a
    square pillar, cabinets and shelves, a box at an angle, and an open door onto a corridor.
    The robot drives two laps round the central bench (≈ 48 m).
``loop``
    A ring of corridors (2.2 m wide) round a block of rooms, 28 m × 18 m overall: door recesses
    and an alcove in the outer walls, rooms behind open and closed doors in the block.  The robot
    drives one lap and on along the first corridor and up the second (≈ 113 m), so it sees the
    walls of the start again after its odometry has drifted: the SLAM test case.

``get_world(name)`` returns the :class:`~slam.sim.world.World` (with its waypoints);
``load_world(name_or_path)`` also accepts a ``world.json`` path.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from slam.errors import InputError
from slam.sim.world import World, WorldBuilder, read_world

__all__ = ["WORLD_NAMES", "get_world", "load_world"]

#: A feature along a wall: (distance from the wall's start (m), width (m), kind, depth (m)).
#: ``kind`` is ``"recess"`` (a door set back by ``depth``) or ``"gap"`` (an open doorway).
Feature = tuple[float, float, str, float]

DOOR_M = 0.9
RECESS_M = 0.2


def _wall(
    b: WorldBuilder,
    start: Sequence[float],
    end: Sequence[float],
    features: Sequence[Feature] = (),
    outward: float = 1.0,
) -> None:
    """A straight wall from ``start`` to ``end`` broken by door recesses and gaps.

    Recesses go to the left of the direction ``start → end`` when ``outward = +1``, to the
    right when ``-1``.
    """
    p0 = np.asarray(start, dtype=float)
    p1 = np.asarray(end, dtype=float)
    length = float(np.linalg.norm(p1 - p0))
    u = (p1 - p0) / length
    n = outward * np.array([-u[1], u[0]])
    s_prev = 0.0
    for s, width, kind, depth in sorted(features):
        if not (s_prev <= s and s + width <= length):
            raise ValueError(f"feature at {s} m does not fit the wall")
        a = p0 + u * s
        c = p0 + u * (s + width)
        if s > s_prev:
            b.segment(p0 + u * s_prev, a, "wall")
        if kind == "recess":
            b.segment(a, a + n * depth, "wall")
            b.segment(a + n * depth, c + n * depth, "door")
            b.segment(c + n * depth, c, "wall")
        elif kind != "gap":
            raise ValueError(f"unknown wall feature {kind!r}")
        s_prev = s + width
    if s_prev < length:
        b.segment(p0 + u * s_prev, p1, "wall")


def _recess(s: float, width: float = DOOR_M, depth: float = RECESS_M) -> Feature:
    return (s, width, "recess", depth)


def _gap(s: float, width: float = DOOR_M) -> Feature:
    return (s, width, "gap", 0.0)


def hallway() -> World:
    """The hallway of the paper's Fig. 5 (see the module docstring)."""
    b = WorldBuilder()
    # South wall y = -1 (recesses go to -y, i.e. to the right of +x), jog to y = -1.3 at x = 26.
    _wall(b, (0, -1), (26, -1), [_recess(2.5), _recess(8.0), _recess(13.5), _recess(19.0)], -1)
    b.segment((26, -1), (26, -1.3))
    _wall(b, (26, -1.3), (40, -1.3), [_recess(3.0), _recess(9.5)], -1)
    # North wall y = +1 with an alcove (y = 1.4) from x = 14 to 20 and an open office door.
    _wall(b, (0, 1), (14, 1), [_recess(4.0), _recess(10.0)], 1)
    b.segment((14, 1), (14, 1.4))
    _wall(b, (14, 1.4), (20, 1.4), [_recess(2.0, 1.2, 0.3)], 1)
    b.segment((20, 1.4), (20, 1))
    _wall(b, (20, 1), (40, 1), [_recess(3.5), _gap(10.0), _recess(15.0)], 1)
    # The office behind the open door (x 29.0..34.5, y 1..4.5), a desk and a cabinet in it.
    b.polyline([(29.0, 1.0), (29.0, 4.5), (34.5, 4.5), (34.5, 1.0)])
    b.box(31.5, 3.6, 1.6, 0.7, label="desk")
    b.box(29.3, 2.0, 0.5, 1.2, label="cabinet")
    # End walls.
    b.segment((0, -1), (0, 1))
    b.segment((40, -1.3), (40, 1))
    waypoints = [(1.0, 0.5), (38.0, 0.5), (38.0, -0.5), (1.0, -0.5)]
    return b.build(
        "hallway",
        waypoints,
        "40 m hallway with door recesses and jogs (the paper's Fig. 5); down and back",
    )


def lab() -> World:
    """The cluttered laboratory (see the module docstring)."""
    b = WorldBuilder()
    # Room walls, open door in the south wall (x 5..6) onto a corridor y -2..0.
    _wall(b, (0, 0), (12, 0), [_gap(5.0, 1.0)], -1)
    _wall(b, (12, 0), (12, 9), [_recess(6.0, 1.0, 0.25)], -1)
    b.segment((12, 9), (0, 9))
    b.segment((0, 9), (0, 0))
    b.polyline([(0, 0), (0, -2), (12, -2), (12, 0)])
    # Furniture.
    for y in (1.0, 3.4, 5.8):
        b.box(0.4, y, 0.8, 1.6, label="desk")
    b.box(4.5, 4.0, 3.0, 1.2, label="bench")
    b.polygon(8.5, 5.8, 0.3, 8, label="pillar")
    b.box(3.0, 5.0, 0.4, 0.4, label="pillar")
    b.box(6.0, 8.3, 2.0, 0.6, label="cabinet")
    b.box(11.3, 3.0, 0.6, 2.5, label="shelf")
    b.box(10.4, 7.4, 0.8, 0.8, label="box")
    b.rotated_box(10.4, 1.0, 0.7, 0.5, math.radians(30.0), label="box")
    b.rotated_box(5.6, 6.0, 0.6, 0.4, math.radians(-20.0), label="cart")
    lap = [(2.3, 2.3), (9.6, 2.3), (9.6, 7.0), (2.3, 7.0)]
    waypoints = lap + lap + [(2.3, 2.3)]
    return b.build(
        "lab",
        waypoints,
        "12 m x 9 m laboratory with desks, a bench, pillars, boxes; two laps round the bench",
    )


def loop() -> World:
    """The ring of corridors round a block of rooms (see the module docstring)."""
    b = WorldBuilder()
    x0, y0, x1, y1 = 0.0, 0.0, 28.0, 18.0  # outer walls
    w = 2.2  # corridor width
    bx0, by0, bx1, by1 = x0 + w, y0 + w, x1 - w, y1 - w  # the block of rooms
    # Outer walls (counter-clockwise; recesses go outward = to the right).
    _wall(b, (x0, y0), (x1, y0), [_recess(5.0), _recess(12.0, 1.8, 0.5), _recess(20.5)], -1)
    _wall(b, (x1, y0), (x1, y1), [_recess(4.0), _gap(9.5, 1.2)], -1)
    _wall(b, (x1, y1), (x0, y1), [_recess(3.0), _recess(9.0), _recess(17.0, 1.5, 0.4)], -1)
    _wall(b, (x0, y1), (x0, y0), [_recess(6.5)], -1)
    # Stairwell behind the open door in the east wall.
    b.polyline([(x1, 9.5), (x1 + 3.0, 9.5), (x1 + 3.0, 10.7), (x1, 10.7)])
    # The block: south face with rooms behind open doors (gaps) and closed doors (recesses).
    mid = 0.5 * (by0 + by1)
    _wall(b, (bx0, by0), (bx1, by0), [_gap(2.0), _recess(7.0), _gap(12.0), _recess(18.0)], 1)
    _wall(b, (bx1, by0), (bx1, by1), [_gap(2.0), _recess(9.0)], 1)
    _wall(b, (bx1, by1), (bx0, by1), [_gap(3.0), _recess(9.0), _gap(15.5), _recess(20.0)], 1)
    _wall(b, (bx0, by1), (bx0, by0), [_recess(3.0), _gap(9.0)], 1)
    # Inside the block: a spine wall and room dividers.
    b.segment((bx0, mid), (bx1, mid))
    for x in (7.5, 12.5, 17.5, 22.0):
        b.segment((x, by0), (x, mid))
    for x in (8.0, 13.5, 19.0):
        b.segment((x, mid), (x, by1))
    b.box(bx0 + 1.0, by0 + 2.5, 1.4, 0.7, label="desk")
    b.box(14.0, by1 - 1.5, 1.6, 0.8, label="desk")
    b.rotated_box(bx1 - 1.8, 11.0, 0.8, 0.6, math.radians(25.0), label="box")
    c = 0.5 * w
    waypoints = [
        (3.5, y0 + c),
        (x1 - c, y0 + c),
        (x1 - c, y1 - c),
        (x0 + c, y1 - c),
        (x0 + c, y0 + c),
        (x1 - c, y0 + c),
        (x1 - c, 8.0),
    ]
    return b.build(
        "loop",
        waypoints,
        "ring of 2.2 m corridors round a block of rooms (28 m x 18 m); 1.3 laps",
    )


_FACTORIES: dict[str, Callable[[], World]] = {"hallway": hallway, "lab": lab, "loop": loop}

#: Names accepted by :func:`get_world` and ``lineslam simulate``.
WORLD_NAMES: tuple[str, ...] = tuple(_FACTORIES)


def get_world(name: str) -> World:
    """The named world (one of :data:`WORLD_NAMES`), with its default waypoints."""
    try:
        factory = _FACTORIES[name]
    except KeyError:
        raise InputError(
            f"unknown world {name!r}; named worlds: {', '.join(WORLD_NAMES)} "
            "(or give a path to a world.json)"
        ) from None
    return factory()


def load_world(name_or_path: str | Path) -> World:
    """A named world, or the ``world.json`` at ``name_or_path``."""
    if isinstance(name_or_path, str) and name_or_path in _FACTORIES:
        return get_world(name_or_path)
    path = Path(name_or_path)
    if path.suffix.lower() == ".json" or path.exists():
        return read_world(path)
    return get_world(str(name_or_path))
