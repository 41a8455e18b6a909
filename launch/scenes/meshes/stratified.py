"""The mesh of the shipped block scene launch/scenes/stratified.toml, written by Gmsh with the
block mesher's nodes bit for bit: three layers of 180 x 30 mm (y 0-30 `bottom`, 30-60 `core`,
60-90 `top`), each cut into six 30 x 30 mm squares of 20 x 20 QUA8 elements.

    python3 launch/scenes/meshes/stratified.py

writes stratified.msh (binary MSH 4.1: the doubles themselves, not 16 digits). Physical surfaces
(one subdomain each): `bottom.1`..`bottom.6`, `core.1`..`core.6`, `top.1`..`top.6`, left to
right. Physical curves: `clamp` (x = 0, all three layers), `floor` (y = 0), `roof` (y = 90),
`end` (x = 180, all three layers), `core-end` (x = 180, 30 <= y <= 60; the same curve is also in
`end`).

Gmsh does not mesh here: its transfinite placement puts nodes up to 2.7e-10 mm off the block
mesher's. The script reads the blocks of the scene, computes every node with the floating-point
operations of the block mesher (glissade_mechanics::mesh::Mesh::structured on the subdomain
rectangles of glissade_scene's `subdomains()`; Python's floats are IEEE doubles too), checks that
neighbouring squares compute their shared nodes to the same bits, and gives Gmsh the nodes and
elements on the geometric entities (`gmsh.model.mesh.addNodes` / `addElements`): each position
one node, classified on its point, curve or surface, so neighbouring squares share their nodes.
"""

import os
import struct
import tomllib

import gmsh

import common

SCENE = os.path.normpath(os.path.join(common.HERE, "..", "stratified.toml"))
LAYERS = ("bottom", "core", "top")


def bits(x):
    return struct.pack("<d", x)


def cut(r, k, n):
    """The subdomain cut of glissade_scene's `subdomains()`: r0 + (r1 - r0) * k / n, r1 at k == n."""
    if k == n:
        return r[1]
    return r[0] + (r[1] - r[0]) * float(k) / float(n)


def structured(x, y, nx, ny):
    """Mesh::rectangle(x, y, nx, ny): the node positions of the (2 nx + 1) x (2 ny + 1) grid by
    local index (i, j), without the centres (i, j both odd), as Mesh::structured computes them."""
    corners = ((x[0], y[0]), (x[1], y[0]), (x[1], y[1]), (x[0], y[1]))
    gx, gy = 2 * nx + 1, 2 * ny + 1
    out = {}
    for j in range(gy):
        for i in range(gx):
            if i % 2 == 1 and j % 2 == 1:
                continue
            u = float(i) / float(gx - 1)
            v = float(j) / float(gy - 1)
            w = ((1.0 - u) * (1.0 - v), u * (1.0 - v), u * v, (1.0 - u) * v)
            # Rust's f64 `sum()`: a left fold from -0.0, in corner order (not Python's `sum`,
            # which compensates from 3.12 on).
            px = -0.0
            py = -0.0
            for c in range(4):
                px = px + w[c] * corners[c][0]
            for c in range(4):
                py = py + w[c] * corners[c][1]
            out[(i, j)] = (px, py)
    return out


def blocks():
    """The scene's three layers: one x range, split [sx, 1], stacked in y in the order of LAYERS."""
    with open(SCENE, "rb") as f:
        scene = tomllib.load(f)
    layers = scene["block"]
    assert [b["name"] for b in layers] == list(LAYERS), "the layers of stratified.toml"
    for b in layers:
        assert b["x"] == layers[0]["x"] and b["nx"] == layers[0]["nx"], "one x range and nx"
        assert b.get("split", [1, 1])[1] == 1 and b["split"] == layers[0]["split"], "split [sx, 1]"
    for below, above in zip(layers, layers[1:]):
        assert below["y"][1] == above["y"][0], "layers stacked"
    return layers


def build():
    layers = blocks()
    sx = layers[0]["split"][0]
    ex = layers[0]["nx"] // sx
    rows = len(layers)
    # The block mesher's nodes of every square (subdomain), by global grid index (I, J): square
    # (i, j)'s local node (a, b) is (2 ex i + a, j0 + b) with j0 the rows of the layers below.
    position = {}
    # Global grid rows of each layer's bottom and the element rows of each layer.
    row0 = [0]
    for b in layers:
        row0.append(row0[-1] + 2 * b["ny"])
    for j, b in enumerate(layers):
        ey = b["ny"]
        ry = (cut(b["y"], 0, 1), cut(b["y"], 1, 1))
        for i in range(sx):
            rx = (cut(b["x"], i, sx), cut(b["x"], i + 1, sx))
            for (a, c), p in structured(rx, ry, ex, ey).items():
                key = (2 * ex * i + a, row0[j] + c)
                if key in position:
                    q = position[key]
                    assert bits(q[0]) == bits(p[0]) and bits(q[1]) == bits(p[1]), \
                        f"node {key}: {q} in one square, {p} in its neighbour"
                else:
                    position[key] = p
    columns = 2 * ex * sx  # last grid column

    geo = gmsh.model.geo
    # points[j][i]: the corner at grid (2 ex i, row0[j]).
    points = [[geo.addPoint(*position[(2 * ex * i, row0[j])], 0) for i in range(sx + 1)]
              for j in range(rows + 1)]
    # horizontal[j][i]: grid row row0[j], from the corner i to i + 1.
    horizontal = [[geo.addLine(points[j][i], points[j][i + 1]) for i in range(sx)] for j in range(rows + 1)]
    # vertical[j][i]: grid column 2 ex i, from row0[j] to row0[j + 1].
    vertical = [[geo.addLine(points[j][i], points[j + 1][i]) for i in range(sx + 1)] for j in range(rows)]
    squares = []
    for j in range(rows):
        row = []
        for i in range(sx):
            loop = geo.addCurveLoop([horizontal[j][i], vertical[j][i + 1], -horizontal[j + 1][i], -vertical[j][i]])
            row.append(geo.addPlaneSurface([loop]))
        squares.append(row)
    geo.synchronize()

    # Nodes: tags from 1, points first, then the curves' inner nodes in the curve's direction,
    # then the surfaces' inner nodes row by row.
    mesh = gmsh.model.mesh
    tag_of = {}

    def add_nodes(dim, entity, keys):
        tags = list(range(len(tag_of) + 1, len(tag_of) + 1 + len(keys)))
        coords = []
        for t, k in zip(tags, keys):
            tag_of[k] = t
            coords += [position[k][0], position[k][1], 0.0]
        mesh.addNodes(dim, entity, tags, coords)

    for j in range(rows + 1):
        for i in range(sx + 1):
            add_nodes(0, points[j][i], [(2 * ex * i, row0[j])])
    for j in range(rows + 1):
        for i in range(sx):
            add_nodes(1, horizontal[j][i], [(a, row0[j]) for a in range(2 * ex * i + 1, 2 * ex * (i + 1))])
    for j in range(rows):
        for i in range(sx + 1):
            add_nodes(1, vertical[j][i], [(2 * ex * i, c) for c in range(row0[j] + 1, row0[j + 1])])
    for j in range(rows):
        for i in range(sx):
            add_nodes(2, squares[j][i], [(a, c) for c in range(row0[j] + 1, row0[j + 1])
                                         for a in range(2 * ex * i + 1, 2 * ex * (i + 1))
                                         if (a, c) in position])
    assert len(tag_of) == len(position)

    # Elements: tags from 1, the 3-node lines of the physical curves (end, end, middle in the
    # curve's direction), then the QUA8 of each square in the block mesher's order (element rows
    # from the bottom, left to right; corners counter-clockwise from the bottom-left, then the
    # mid nodes of the edges 1-2, 2-3, 3-4, 4-1).
    count = [0]

    def add_elements(entity, kind, nodes, per):
        n = len(nodes) // per
        tags = list(range(count[0] + 1, count[0] + 1 + n))
        count[0] += n
        mesh.addElementsByType(entity, kind, tags, nodes)

    def line(entity, keys):
        nodes = []
        for e in range(0, len(keys) - 1, 2):
            nodes += [tag_of[keys[e]], tag_of[keys[e + 2]], tag_of[keys[e + 1]]]
        add_elements(entity, 8, nodes, 3)

    clamp = [vertical[j][0] for j in range(rows)]
    end = [vertical[j][sx] for j in range(rows)]
    for j in (0, rows):
        for i in range(sx):
            line(horizontal[j][i], [(a, row0[j]) for a in range(2 * ex * i, 2 * ex * (i + 1) + 1)])
    for j in range(rows):
        for curve, a in ((clamp[j], 0), (end[j], columns)):
            line(curve, [(a, c) for c in range(row0[j], row0[j + 1] + 1)])
    for j, b in enumerate(layers):
        for i in range(sx):
            nodes = []
            for ej in range(b["ny"]):
                for ei in range(ex):
                    a, c = 2 * ex * i + 2 * ei, row0[j] + 2 * ej
                    nodes += [tag_of[k] for k in ((a, c), (a + 2, c), (a + 2, c + 2), (a, c + 2),
                                                  (a + 1, c), (a + 2, c + 1), (a + 1, c + 2), (a, c + 1))]
            add_elements(squares[j][i], 16, nodes, 8)

    for j, name in enumerate(LAYERS):
        for i, s in enumerate(squares[j]):
            gmsh.model.addPhysicalGroup(2, [s], name=f"{name}.{i + 1}")
    gmsh.model.addPhysicalGroup(1, clamp, name="clamp")
    gmsh.model.addPhysicalGroup(1, horizontal[0], name="floor")
    gmsh.model.addPhysicalGroup(1, horizontal[rows], name="roof")
    gmsh.model.addPhysicalGroup(1, end, name="end")
    gmsh.model.addPhysicalGroup(1, [vertical[1][sx]], name="core-end")


def main():
    common.start("stratified")
    build()
    common.qua8_options()
    # Binary: the nodes' doubles as computed (ASCII keeps 16 significant digits).
    gmsh.option.setNumber("Mesh.Binary", 1)
    common.write("stratified.msh")
    gmsh.finalize()


if __name__ == "__main__":
    main()
