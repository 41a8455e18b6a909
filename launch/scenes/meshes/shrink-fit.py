"""Meshes of the shrink-fit scenes: two concentric full rings centred at the origin, inner ring
20 <= r <= 30 mm, outer ring 30 <= r <= 50 mm, in contact on the circle r = 30 mm.

    python3 launch/scenes/meshes/shrink-fit.py

writes shrink-fit-1.msh (coarse), shrink-fit-2.msh (medium) and shrink-fit-3.msh (fine): 24, 48
and 96 elements around; 2, 4, 8 radially in the inner ring and 4, 8, 16 in the outer one. QUA8
elements, mid nodes of the arcs on the circles.

Each ring is four quarter sectors (transfinite needs four-sided surfaces) gathered in one physical
surface: `inner`, `outer`. The quarter arcs of r = 30 are shared by both rings: the fit circle is
one closed chain of element edges whose nodes are those of both rings. Physical curves: `bore`
(r = 20), `fit` (r = 30), `outside` (r = 50).
"""

import math

import gmsh

import common

RADII = (20.0, 30.0, 50.0)
LEVELS = {1: (24, 2, 4), 2: (48, 4, 8), 3: (96, 8, 16)}


def build(around, radial_inner, radial_outer):
    geo = gmsh.model.geo
    centre = geo.addPoint(0, 0, 0)
    # points[i][q]: radius i, angle q * 90 degrees.
    points = [[geo.addPoint(r * math.cos(q * math.pi / 2), r * math.sin(q * math.pi / 2), 0) for q in range(4)]
              for r in RADII]
    # arcs[i][q]: radius i, from angle q * 90 to (q + 1) * 90 degrees (counter-clockwise).
    arcs = [[geo.addCircleArc(points[i][q], centre, points[i][(q + 1) % 4]) for q in range(4)]
            for i in range(len(RADII))]
    # rays[j][q]: from radius j to radius j + 1 at angle q * 90 degrees.
    rays = [[geo.addLine(points[j][q], points[j + 1][q]) for q in range(4)] for j in range(2)]
    rings = []
    for j in range(2):
        sectors = []
        for q in range(4):
            # Counter-clockwise: out along the ray at q, along the outer arc, back along the ray at
            # q + 1, back along the inner arc.
            loop = geo.addCurveLoop([rays[j][q], arcs[j + 1][q], -rays[j][(q + 1) % 4], -arcs[j][q]])
            sectors.append(geo.addPlaneSurface([loop]))
        rings.append(sectors)
    geo.synchronize()
    mesh = gmsh.model.mesh
    per_quarter = around // 4
    for i in range(len(RADII)):
        for q in range(4):
            mesh.setTransfiniteCurve(arcs[i][q], per_quarter + 1)
    for j, n in enumerate((radial_inner, radial_outer)):
        for q in range(4):
            mesh.setTransfiniteCurve(rays[j][q], n + 1)
    for s in rings[0] + rings[1]:
        mesh.setTransfiniteSurface(s)
        mesh.setRecombine(2, s)
    gmsh.model.addPhysicalGroup(2, rings[0], name="inner")
    gmsh.model.addPhysicalGroup(2, rings[1], name="outer")
    gmsh.model.addPhysicalGroup(1, arcs[0], name="bore")
    gmsh.model.addPhysicalGroup(1, arcs[1], name="fit")
    gmsh.model.addPhysicalGroup(1, arcs[2], name="outside")


def main():
    for level, (around, radial_inner, radial_outer) in LEVELS.items():
        common.start(f"shrink-fit-{level}")
        build(around, radial_inner, radial_outer)
        common.qua8_options()
        gmsh.model.mesh.generate(2)
        common.write(f"shrink-fit-{level}.msh")
        gmsh.finalize()


if __name__ == "__main__":
    main()
