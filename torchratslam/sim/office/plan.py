"""The office floor plan as data: junction nodes and the corridors and doors between them.

A plan is a literal read by :func:`torchratslam.sim.office.builder.build_office`: every
edge is a straight, axis-aligned passage of the given width between two nodes, every
room a rectangle around a node, and the floor's free space is their union. The robot
moves along the edges' centre lines, so the same literal defines the local movement
paths.

:data:`OFFICE_FLOOR` is 34 m x 16 m: a corridor loop around a central block with a
cross corridor, a dead-end wing and six rooms off the corridors, in the spirit of the
paper's Fig. 2 and Fig. 13 (a loop that an obstacle can block, with a longer way round).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["OFFICE_FLOOR", "SMALL_FLOOR", "FloorPlan"]


@dataclass(frozen=True)
class FloorPlan:
    """An office floor as data.

    Attributes:
        name: a label.
        nodes: ``name -> (x, y)`` junctions, corridor ends and room centres (m).
        edges: ``(a, b, width)`` axis-aligned passages between nodes (m).
        rooms: ``(node, width, height)`` rectangles centred on a node (m).
        wall_height: wall height (m).
        start: the node the robot starts at, and its heading (deg).
    """

    name: str
    nodes: dict[str, tuple[float, float]]
    edges: tuple[tuple[str, str, float], ...]
    rooms: tuple[tuple[str, float, float], ...] = ()
    wall_height: float = 2.2
    start: tuple[str, float] = ("A", 0.0)


OFFICE_FLOOR = FloorPlan(
    name="office",
    nodes={
        # the outer corridor loop (anticlockwise from the bottom left)
        "A": (2.0, 2.0),
        "a1": (6.0, 2.0),
        "B": (12.0, 2.0),
        "b1": (17.0, 2.0),
        "C": (22.0, 2.0),
        "D": (32.0, 2.0),
        "E": (32.0, 14.0),
        "F": (22.0, 14.0),
        "f1": (17.0, 14.0),
        "G": (12.0, 14.0),
        "h1": (6.0, 14.0),
        "H": (2.0, 14.0),
        "r6": (2.0, 8.0),
        # the cross corridor and a dead-end wing
        "X": (12.0, 8.0),
        "Y": (22.0, 8.0),
        "W": (27.0, 8.0),
        # room centres
        "r1": (6.0, 5.5),
        "r2": (17.0, 5.5),
        "r3": (6.0, 10.5),
        "r4": (17.0, 10.5),
        "r5": (27.0, 11.5),
    },
    edges=(
        ("A", "a1", 1.8),
        ("a1", "B", 1.8),
        ("B", "b1", 1.8),
        ("b1", "C", 1.8),
        ("C", "D", 1.8),
        ("D", "E", 1.8),
        ("E", "F", 1.8),
        ("F", "f1", 1.8),
        ("f1", "G", 1.8),
        ("G", "h1", 1.8),
        ("h1", "H", 1.8),
        ("H", "r6", 1.8),
        ("r6", "A", 1.8),
        ("B", "X", 1.6),
        ("X", "G", 1.6),
        ("C", "Y", 1.6),
        ("Y", "F", 1.6),
        ("X", "Y", 1.6),
        ("Y", "W", 1.6),
        ("W", "r5", 1.0),
        ("a1", "r1", 1.0),
        ("b1", "r2", 1.0),
        ("h1", "r3", 1.0),
        ("f1", "r4", 1.0),
    ),
    rooms=(
        ("r1", 4.0, 3.0),
        ("r2", 4.0, 3.0),
        ("r3", 4.0, 3.0),
        ("r4", 4.0, 3.0),
        ("r5", 3.0, 2.5),
        ("r6", 2.6, 5.0),
    ),
    start=("A", 0.0),
)


SMALL_FLOOR = FloorPlan(
    name="small",
    nodes={
        "A": (1.0, 1.0),
        "B": (6.0, 1.0),
        "C": (11.0, 1.0),
        "D": (11.0, 7.0),
        "E": (6.0, 7.0),
        "F": (1.0, 7.0),
    },
    edges=(
        ("A", "B", 1.6),
        ("B", "C", 1.6),
        ("C", "D", 1.6),
        ("D", "E", 1.6),
        ("E", "F", 1.6),
        ("F", "A", 1.6),
        ("B", "E", 1.6),
    ),
    start=("A", 0.0),
)
"""A 10 m x 6 m loop with a cross corridor: the quick experiments' floor."""
