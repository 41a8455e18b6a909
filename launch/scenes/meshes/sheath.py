"""Mesh of the cable sheath scene: three concentric layers centred at the origin, 10-13 mm,
13-16 mm and 16-20 mm, each cut into 8 equal sectors by radial lines.

    python3 launch/scenes/meshes/sheath.py

writes sheath.msh: QUA8 elements, 4 per sector around (32 around), 3 per layer radially, mid nodes
of the arcs on the circles. Physical surfaces (one subdomain each): `inner.k`, `middle.k`,
`outer.k` for k = 1..8, sector k spanning (k - 1) * 45 to k * 45 degrees counter-clockwise from
+x. Physical curves: `bore` (r = 10), `inner-middle` (r = 13), `middle-outer` (r = 16),
`outside` (r = 20). Neighbouring sectors and layers share their curves, hence their nodes.
"""

import math

import gmsh

import common

RADII = (10.0, 13.0, 16.0, 20.0)
LAYERS = ("inner", "middle", "outer")
SECTORS = 8
AROUND_PER_SECTOR = 4
RADIAL_PER_LAYER = 3


def build():
    geo = gmsh.model.geo
    centre = geo.addPoint(0, 0, 0)
    step = 2 * math.pi / SECTORS
    points = [[geo.addPoint(r * math.cos(k * step), r * math.sin(k * step), 0) for k in range(SECTORS)]
              for r in RADII]
    arcs = [[geo.addCircleArc(points[i][k], centre, points[i][(k + 1) % SECTORS]) for k in range(SECTORS)]
            for i in range(len(RADII))]
    rays = [[geo.addLine(points[j][k], points[j + 1][k]) for k in range(SECTORS)] for j in range(len(LAYERS))]
    surfaces = []
    for j in range(len(LAYERS)):
        layer = []
        for k in range(SECTORS):
            loop = geo.addCurveLoop([rays[j][k], arcs[j + 1][k], -rays[j][(k + 1) % SECTORS], -arcs[j][k]])
            layer.append(geo.addPlaneSurface([loop]))
        surfaces.append(layer)
    geo.synchronize()
    mesh = gmsh.model.mesh
    for row in arcs:
        for c in row:
            mesh.setTransfiniteCurve(c, AROUND_PER_SECTOR + 1)
    for row in rays:
        for c in row:
            mesh.setTransfiniteCurve(c, RADIAL_PER_LAYER + 1)
    for layer in surfaces:
        for s in layer:
            mesh.setTransfiniteSurface(s)
            mesh.setRecombine(2, s)
    for j, name in enumerate(LAYERS):
        for k, s in enumerate(surfaces[j]):
            gmsh.model.addPhysicalGroup(2, [s], name=f"{name}.{k + 1}")
    for i, name in enumerate(("bore", "inner-middle", "middle-outer", "outside")):
        gmsh.model.addPhysicalGroup(1, arcs[i], name=name)


def main():
    common.start("sheath")
    build()
    common.qua8_options()
    gmsh.model.mesh.generate(2)
    common.write("sheath.msh")
    gmsh.finalize()


if __name__ == "__main__":
    main()
