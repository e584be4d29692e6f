"""Anchor grids: a field of reference nodes laid out on a regular grid (004 sect. 5.1: a
node every 5 m over each training area), declared once as ``[[anchor_grids]]`` and expanded
to the same anchors by the emulated lab (emulator.scenario) and the lab computer (host.config).

A grid of ``count = [nx, ny]`` nodes ``spacing_m`` apart starts at ``origin`` (its south-west
node); node (i, j) (i along x, j along y) gets the id ``first_id + j nx + i`` (row by row,
x fastest) and stands at ``origin + spacing_m (i, j)`` at height ``z`` (none: the tag's,
a planar layout). Ids above 254 need the wide ranging report (protocols.nanoloc, type 02).
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.limits import MAX_COORD_M, MAX_HEIGHT_M
from navtwin.common.schema import REQUIRED, Invalid, between, each, key

#: the wide ranging report's anchor ids (16-bit, 0 and 0xFFFF reserved)
WIDE_ANCHOR_IDS = (1, 65_534)
#: nodes in one grid: 004's two training areas hold 961 and 441
MAX_NODES = 20_000


@dataclass(frozen=True)
class AnchorGrid:
    """A rectangular field of anchors, ``spacing_m`` apart (module doc)."""

    first_id: int = key(REQUIRED, "", "id of the south-west node; the others count up row by row, "
                        "x fastest", between(*WIDE_ANCHOR_IDS))
    origin: tuple[float, float] = key(REQUIRED, "m", "position (x, y) of the south-west node",
                                      each(between(-MAX_COORD_M, MAX_COORD_M)))
    spacing_m: float = key(REQUIRED, "m", "distance between neighbouring nodes along x and y",
                           between(0.01, MAX_COORD_M))
    count: tuple[int, int] = key(REQUIRED, "", "nodes along x and along y", each(between(1, MAX_NODES)))
    z: float | None = key(None, "m", "antenna height; none = the tag's height (a planar layout)",
                          between(-MAX_HEIGHT_M, MAX_HEIGHT_M))

    def __post_init__(self):
        n = self.count[0] * self.count[1]
        if n > MAX_NODES:
            raise Invalid("count", f"gives {n} nodes, more than {MAX_NODES}; split the field into grids")
        if self.first_id + n - 1 > WIDE_ANCHOR_IDS[1]:
            raise Invalid("first_id", f"{self.first_id} + {n} nodes passes id {WIDE_ANCHOR_IDS[1]}; "
                                      "start the grid lower")

    @property
    def ids(self) -> range:
        return range(self.first_id, self.first_id + self.count[0] * self.count[1])

    @property
    def box(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1): the rectangle the nodes span, the area the grid covers."""
        (x0, y0), s = self.origin, self.spacing_m
        return x0, y0, x0 + s * (self.count[0] - 1), y0 + s * (self.count[1] - 1)

    def nodes(self) -> list[tuple[int, float, float, float | None]]:
        """(id, x, y, z) of every node, in id order."""
        (x0, y0), s, (nx, ny) = self.origin, self.spacing_m, self.count
        return [(self.first_id + j * nx + i, x0 + s * i, y0 + s * j, self.z)
                for j in range(ny) for i in range(nx)]


def expand(grids) -> list[tuple[int, float, float, float | None]]:
    """The nodes of every grid, grid by grid; raises Invalid naming the grid when ids repeat."""
    out, seen = [], set()
    for k, g in enumerate(grids):
        nodes = g.nodes()
        clash = seen.intersection(g.ids)
        if clash:
            raise Invalid(f"[[anchor_grids]] #{k + 1} first_id", f"reuses anchor id {min(clash)}; "
                                                                  "give each grid its own id range")
        seen.update(g.ids)
        out.extend(nodes)
    return out
