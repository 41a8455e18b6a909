"""The mesh of the shipped block scene launch/scenes/stratified.toml, made by Gmsh: three layers
of 180 x 30 mm (y 0-30 `bottom`, 30-60 `core`, 60-90 `top`), each cut into six 30 x 30 mm
squares of 20 x 20 QUA8 elements: the node positions of the block mesher.

    python3 launch/scenes/meshes/stratified.py

writes stratified.msh. Physical surfaces (one subdomain each): `bottom.1`..`bottom.6`,
`core.1`..`core.6`, `top.1`..`top.6`, left to right. Physical curves: `clamp` (x = 0, all three
layers), `floor` (y = 0), `roof` (y = 90), `end` (x = 180, all three layers), `core-end`
(x = 180, 30 <= y <= 60; the same curve is also in `end`). Neighbouring squares share their
curves, hence their nodes.
"""

import gmsh

import common

LAYERS = ("bottom", "core", "top")
COLUMNS = 6
SIDE = 30.0
PER_SIDE = 20


def build():
    geo = gmsh.model.geo
    rows = len(LAYERS)
    # points[j][i] at x = i * SIDE, y = j * SIDE.
    points = [[geo.addPoint(i * SIDE, j * SIDE, 0) for i in range(COLUMNS + 1)] for j in range(rows + 1)]
    # horizontal[j][i]: y = j * SIDE, from x = i * SIDE to (i + 1) * SIDE.
    horizontal = [[geo.addLine(points[j][i], points[j][i + 1]) for i in range(COLUMNS)] for j in range(rows + 1)]
    # vertical[j][i]: x = i * SIDE, from y = j * SIDE to (j + 1) * SIDE.
    vertical = [[geo.addLine(points[j][i], points[j + 1][i]) for i in range(COLUMNS + 1)] for j in range(rows)]
    squares = []
    for j in range(rows):
        row = []
        for i in range(COLUMNS):
            loop = geo.addCurveLoop([horizontal[j][i], vertical[j][i + 1], -horizontal[j + 1][i], -vertical[j][i]])
            row.append(geo.addPlaneSurface([loop]))
        squares.append(row)
    geo.synchronize()
    mesh = gmsh.model.mesh
    for c in [c for r in horizontal for c in r] + [c for r in vertical for c in r]:
        mesh.setTransfiniteCurve(c, PER_SIDE + 1)
    for row in squares:
        for s in row:
            mesh.setTransfiniteSurface(s)
            mesh.setRecombine(2, s)
    for j, name in enumerate(LAYERS):
        for i, s in enumerate(squares[j]):
            gmsh.model.addPhysicalGroup(2, [s], name=f"{name}.{i + 1}")
    gmsh.model.addPhysicalGroup(1, [vertical[j][0] for j in range(rows)], name="clamp")
    gmsh.model.addPhysicalGroup(1, horizontal[0], name="floor")
    gmsh.model.addPhysicalGroup(1, horizontal[rows], name="roof")
    gmsh.model.addPhysicalGroup(1, [vertical[j][COLUMNS] for j in range(rows)], name="end")
    gmsh.model.addPhysicalGroup(1, [vertical[1][COLUMNS]], name="core-end")


def main():
    common.start("stratified")
    build()
    common.qua8_options()
    gmsh.model.mesh.generate(2)
    common.write("stratified.msh")
    gmsh.finalize()


if __name__ == "__main__":
    main()
