"""Mesh of a wedge pressed into a V-groove (plane, mm).

    python3 launch/scenes/meshes/wedge.py

writes wedge.msh. The base block is 60 x 30 mm (-30 <= x <= 30, -30 <= y <= 0) with a symmetric
trapezoidal groove cut from its top: 24 mm wide at y = 0 (x = +-12), 15 mm deep, its flanks
inclined at 30 degrees to the vertical, so that the flat bottom at y = -15 spans
x = +-(12 - 15 tan 30) = +-3.3397. Right flank: x = 12 + y tan 30 (left: its mirror image).

The wedge is the trapezoid between the flank lines from y = -10 to y = +10: its flat bottom
(y = -10, x = +-6.2265) is 5 mm above the groove bottom, its top (y = 10, x = +-17.7735) 10 mm
above the base, its sides the flank lines. The two parts touch along the flanks from y = -10 to
y = 0 only: one curve entity on each side, shared by both parts, so its nodes are those of both.
Below the wedge the flanks (y = -15 to -10) and the groove bottom are free edges of the base; above
y = 0 the wedge's sides are free (they leave the base at its corners x = +-12, y = 0, at 60 degrees
from its top).

Geometric surfaces, all four-sided and transfinite: the base is seven of them (on each side three
rows from the groove to x = +-30 between y = 0, -10, -15 and -30, and the block under the groove
bottom), the wedge two (below and above y = 0). QUA8 elements: 6 along each contact segment, 3
along each free flank, 10 from the groove to each side, 6 from y = -15 to -30, 3 along the groove
bottom; the wedge 10 across, 6 up to y = 0 and 5 above.

Physical surfaces (one subdomain each): `base`, `wedge`. Physical curves: `flank-left` and
`flank-right` (the contact segments, x < 0 and x > 0), `wedge-top` (y = 10), `base-bottom`
(y = -30), `base-sides` (x = -30 and x = 30).
"""

import math

import gmsh

import common

HALF_WIDTH = 30.0  # base: -30 <= x <= 30
BASE_BOTTOM = -30.0  # base: -30 <= y <= 0
GROOVE_HALF_WIDTH = 12.0  # at y = 0
GROOVE_BOTTOM = -15.0
FLANK_ANGLE = 30.0  # degrees from the vertical
WEDGE_BOTTOM = -10.0
WEDGE_TOP = 10.0

CONTACT = 6  # elements along each contact segment (y = -10 to 0)
FREE_FLANK = 3  # along each free flank below the wedge (y = -15 to -10)
ACROSS = 10  # base, from the groove to x = +-30, in each row
UNDER = 6  # base, from y = -15 to -30
FLOOR = 3  # along the groove bottom
WEDGE_ACROSS = 10
WEDGE_UPPER = 5  # wedge, from y = 0 to its top


def flank_x(y):
    """x of the right flank line at height y (the left one is at -flank_x(y))."""
    return GROOVE_HALF_WIDTH + y * math.tan(math.radians(FLANK_ANGLE))


def ccw(curves, side):
    """A curve loop given counter-clockwise for the right side (side = 1), mirrored for the left
    one (side = -1): the mirror image of a counter-clockwise loop runs clockwise, so it is
    reversed."""
    return curves if side > 0 else [-c for c in reversed(curves)]


def build():
    geo = gmsh.model.geo
    line = geo.addLine
    halves = {}
    for side in (-1, 1):
        p = {
            "top": geo.addPoint(side * flank_x(0.0), 0, 0),  # groove corner at y = 0
            "contact": geo.addPoint(side * flank_x(WEDGE_BOTTOM), WEDGE_BOTTOM, 0),  # wedge corner
            "floor": geo.addPoint(side * flank_x(GROOVE_BOTTOM), GROOVE_BOTTOM, 0),  # groove bottom corner
            "under": geo.addPoint(side * flank_x(GROOVE_BOTTOM), BASE_BOTTOM, 0),
            "side0": geo.addPoint(side * HALF_WIDTH, 0, 0),
            "side1": geo.addPoint(side * HALF_WIDTH, WEDGE_BOTTOM, 0),
            "side2": geo.addPoint(side * HALF_WIDTH, GROOVE_BOTTOM, 0),
            "side3": geo.addPoint(side * HALF_WIDTH, BASE_BOTTOM, 0),
            "wedge": geo.addPoint(side * flank_x(WEDGE_TOP), WEDGE_TOP, 0),  # wedge top corner
        }
        c = {
            # Up the flank line: the contact segment (shared), the free flank below it, the
            # wedge's free side above the base.
            "contact": line(p["contact"], p["top"]),
            "free": line(p["floor"], p["contact"]),
            "wedge-side": line(p["top"], p["wedge"]),
            # Up x = +-flank_x(-15), from the base bottom to the groove bottom.
            "under": line(p["under"], p["floor"]),
            # Outwards from the groove at y = 0, -10, -15, -30.
            "row0": line(p["top"], p["side0"]),
            "row1": line(p["contact"], p["side1"]),
            "row2": line(p["floor"], p["side2"]),
            "row3": line(p["under"], p["side3"]),
            # Up the side x = +-30.
            "side1": line(p["side1"], p["side0"]),
            "side2": line(p["side2"], p["side1"]),
            "side3": line(p["side3"], p["side2"]),
        }
        halves[side] = (p, c)
    (pl, cl), (pr, cr) = halves[-1], halves[1]
    # Across, left to right: the base bottom under the groove, the groove bottom, the wedge's
    # bottom, its section at y = 0 and its top.
    under_floor = line(pl["under"], pr["under"])
    floor = line(pl["floor"], pr["floor"])
    wedge_bottom = line(pl["contact"], pr["contact"])
    wedge_middle = line(pl["top"], pr["top"])
    wedge_top = line(pl["wedge"], pr["wedge"])

    base = []
    for side in (-1, 1):
        c = halves[side][1]
        for loop in ([c["row3"], c["side3"], -c["row2"], -c["under"]],
                     [c["row2"], c["side2"], -c["row1"], -c["free"]],
                     [c["row1"], c["side1"], -c["row0"], -c["contact"]]):
            base.append(geo.addPlaneSurface([geo.addCurveLoop(ccw(loop, side))]))
        if side < 0:
            base.append(geo.addPlaneSurface([geo.addCurveLoop([under_floor, cr["under"], -floor, -cl["under"]])]))
    wedge = [
        geo.addPlaneSurface([geo.addCurveLoop([wedge_bottom, cr["contact"], -wedge_middle, -cl["contact"]])]),
        geo.addPlaneSurface([geo.addCurveLoop([wedge_middle, cr["wedge-side"], -wedge_top, -cl["wedge-side"]])]),
    ]
    geo.synchronize()

    mesh = gmsh.model.mesh
    for c in (cl, cr):
        for key, n in (("contact", CONTACT), ("free", FREE_FLANK), ("wedge-side", WEDGE_UPPER), ("under", UNDER),
                       ("row0", ACROSS), ("row1", ACROSS), ("row2", ACROSS), ("row3", ACROSS),
                       ("side1", CONTACT), ("side2", FREE_FLANK), ("side3", UNDER)):
            mesh.setTransfiniteCurve(c[key], n + 1)
    for curve, n in ((under_floor, FLOOR), (floor, FLOOR), (wedge_bottom, WEDGE_ACROSS),
                     (wedge_middle, WEDGE_ACROSS), (wedge_top, WEDGE_ACROSS)):
        mesh.setTransfiniteCurve(curve, n + 1)
    for s in base + wedge:
        mesh.setTransfiniteSurface(s)
        mesh.setRecombine(2, s)

    gmsh.model.addPhysicalGroup(2, base, name="base")
    gmsh.model.addPhysicalGroup(2, wedge, name="wedge")
    gmsh.model.addPhysicalGroup(1, [cl["contact"]], name="flank-left")
    gmsh.model.addPhysicalGroup(1, [cr["contact"]], name="flank-right")
    gmsh.model.addPhysicalGroup(1, [wedge_top], name="wedge-top")
    gmsh.model.addPhysicalGroup(1, [cl["row3"], under_floor, cr["row3"]], name="base-bottom")
    sides = [c[k] for c in (cl, cr) for k in ("side3", "side2", "side1")]
    gmsh.model.addPhysicalGroup(1, sides, name="base-sides")
    return base, wedge, cl["contact"], cr["contact"]


def element_nodes(dim, entities):
    nodes = set()
    for e in entities:
        for ns in gmsh.model.mesh.getElements(dim, e)[2]:
            nodes.update(int(n) for n in ns)
    return nodes


def check(base, wedge, flanks):
    """Gmsh's account of the mesh: QUA8 on the physical surfaces and 3-node lines on the physical
    curves only; each flank one curve entity in the boundary of a base surface and of a wedge
    surface (with opposite orientations); the nodes that both parts' elements use are exactly
    the flanks' nodes; no two saved nodes at the same place."""
    for dim, tag in gmsh.model.getPhysicalGroups():
        want = [16] if dim == 2 else [8]
        for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            types = [int(t) for t in gmsh.model.mesh.getElementTypes(dim, e)]
            if types != want:
                raise RuntimeError(f"{gmsh.model.getPhysicalName(dim, tag)}: entity {e} has element types {types}")
    for flank in flanks:
        up = sorted(int(s) for s in gmsh.model.getAdjacencies(1, flank)[0])
        in_base = [s for s in up if s in base]
        in_wedge = [s for s in up if s in wedge]
        if len(up) != 2 or len(in_base) != 1 or len(in_wedge) != 1:
            raise RuntimeError(f"flank {flank}: in the boundary of surfaces {up}")
        signs = []
        for s in up:
            b = [t for d, t in gmsh.model.getBoundary([(2, s)], combined=False, oriented=True) if abs(t) == flank]
            if len(b) != 1:
                raise RuntimeError(f"flank {flank}: not once in the boundary of surface {s}")
            signs.append(b[0] > 0)
        if signs[0] == signs[1]:
            raise RuntimeError(f"flank {flank}: the same orientation in both surfaces")
    flank_nodes = set()
    for flank in flanks:
        flank_nodes.update(int(n) for n in gmsh.model.mesh.getNodes(1, flank, includeBoundary=True)[0])
    if len(flank_nodes) != 2 * (2 * CONTACT + 1):
        raise RuntimeError(f"{len(flank_nodes)} nodes on the flanks")
    common_nodes = element_nodes(2, base) & element_nodes(2, wedge)
    if common_nodes != flank_nodes:
        raise RuntimeError(f"the parts share {len(common_nodes)} nodes, the flanks have {len(flank_nodes)}")
    saved = element_nodes(2, base) | element_nodes(2, wedge)
    places = {}
    for n in saved:
        x = gmsh.model.mesh.getNode(n)[0]
        key = (round(x[0], 6), round(x[1], 6))
        if key in places:
            raise RuntimeError(f"nodes {places[key]} and {n} at {key}")
        places[key] = n


def main():
    common.start("wedge")
    base, wedge, *flanks = build()
    common.qua8_options()
    gmsh.model.mesh.generate(2)
    check(base, wedge, flanks)
    common.write("wedge.msh")
    gmsh.finalize()


if __name__ == "__main__":
    main()
