"""Test fixtures of the scene crate's Gmsh reader (nodes/scene/src/msh.rs).

Writes one small mesh of 8-node quadrangles in the four formats Gmsh writes (MSH 4.1 and 2.2,
ASCII and binary), and in MSH 4.1 with the nodes' parametric coordinates, into
nodes/scene/tests/fixtures/msh/, plus what Gmsh's own API says about it
(two-parts.json) and the node count and dimension of every element type Gmsh knows
(element-types.json). The tests compare the reader against these accounts, so CI needs no Gmsh.

    python3 launch/scenes/meshes/fixtures.py

The mesh: a rectangle 0 <= x <= 2, 0 <= y <= 1 ("left", 3 x 2 elements) and, sharing its edge
x = 2, a second part closed on the right by a circular arc through (3, 0) and (3, 1) centred at
(2.5, 0.5) ("right", 2 x 2 elements). Physical curves: "clamp" (x = 0), "interface" (x = 2, also
in "glued"), "floor" (y = 0, both parts), "arc"; one physical point without a name.
"""

import json
import os

import gmsh

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.normpath(os.path.join(HERE, "..", "..", "..", "nodes", "scene", "tests", "fixtures", "msh"))


def build():
    geo = gmsh.model.geo
    p1 = geo.addPoint(0, 0, 0)
    p2 = geo.addPoint(2, 0, 0)
    p3 = geo.addPoint(2, 1, 0)
    p4 = geo.addPoint(0, 1, 0)
    p5 = geo.addPoint(3, 0, 0)
    p6 = geo.addPoint(3, 1, 0)
    centre = geo.addPoint(2.5, 0.5, 0)
    bottom_left = geo.addLine(p1, p2)
    shared = geo.addLine(p2, p3)
    top_left = geo.addLine(p3, p4)
    clamp = geo.addLine(p4, p1)
    bottom_right = geo.addLine(p2, p5)
    arc = geo.addCircleArc(p5, centre, p6)
    top_right = geo.addLine(p6, p3)
    left = geo.addPlaneSurface([geo.addCurveLoop([bottom_left, shared, top_left, clamp])])
    right = geo.addPlaneSurface([geo.addCurveLoop([bottom_right, arc, top_right, -shared])])
    geo.synchronize()
    mesh = gmsh.model.mesh
    for c in (bottom_left, top_left):
        mesh.setTransfiniteCurve(c, 4)
    for c in (shared, clamp, bottom_right, arc, top_right):
        mesh.setTransfiniteCurve(c, 3)
    for s in (left, right):
        mesh.setTransfiniteSurface(s)
        mesh.setRecombine(2, s)
    gmsh.model.addPhysicalGroup(2, [left], name="left")
    gmsh.model.addPhysicalGroup(2, [right], name="right")
    gmsh.model.addPhysicalGroup(1, [clamp], name="clamp")
    gmsh.model.addPhysicalGroup(1, [shared], name="interface")
    gmsh.model.addPhysicalGroup(1, [shared], name="glued")
    gmsh.model.addPhysicalGroup(1, [bottom_left, bottom_right], name="floor")
    gmsh.model.addPhysicalGroup(1, [arc], name="arc")
    gmsh.model.addPhysicalGroup(0, [p1])
    gmsh.option.setNumber("Mesh.ElementOrder", 2)
    gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 1)
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    mesh.generate(2)


def account():
    """What Gmsh's API says of the mesh: nodes, elements of the physical entities, groups."""
    tags, coords, _ = gmsh.model.mesh.getNodes()
    nodes = {int(t): [coords[3 * i], coords[3 * i + 1]] for i, t in enumerate(tags)}
    groups = []
    physicals_of = {}
    for dim, tag in gmsh.model.getPhysicalGroups():
        entities = [int(e) for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)]
        groups.append({"dim": dim, "tag": tag, "name": gmsh.model.getPhysicalName(dim, tag),
                       "entities": entities})
        for e in entities:
            physicals_of.setdefault((dim, e), []).append(tag)
    elements = []
    used = set()
    for (dim, entity), physicals in sorted(physicals_of.items()):
        types, etags, enodes = gmsh.model.mesh.getElements(dim, entity)
        for kind, ts, ns in zip(types, etags, enodes):
            n = len(ns) // len(ts)
            for i, t in enumerate(ts):
                node_tags = [int(x) for x in ns[n * i:n * (i + 1)]]
                used.update(node_tags)
                elements.append({"tag": int(t), "kind": int(kind), "dim": dim, "entity": entity,
                                 "nodes": node_tags, "physicals": sorted(physicals)})
    counts = {}
    for e in elements:
        counts[str(e["kind"])] = counts.get(str(e["kind"]), 0) + 1
    return {
        # Saved: the nodes of these elements (not the centre of the arc, a point of the geometry).
        "nodes": [[t, nodes[t][0], nodes[t][1]] for t in sorted(used)],
        "elements": sorted(elements, key=lambda e: e["tag"]),
        "element_counts": counts,
        "physical_groups": groups,
    }


def element_types():
    # Gmsh complains on stderr about the numbers it does not know: quiet while asking.
    gmsh.option.setNumber("General.Verbosity", 0)
    kinds = []
    for kind in range(1, 256):
        try:
            name, dim, order, num_nodes, _, _ = gmsh.model.mesh.getElementProperties(kind)
        except Exception:
            continue
        kinds.append({"kind": kind, "name": name, "dim": dim, "order": order, "nodes": num_nodes})
    gmsh.option.setNumber("General.Verbosity", 2)
    return kinds


def write_json(path, value):
    """JSON with one list item per line: short diffs when Gmsh changes."""
    with open(path, "w") as f:
        if isinstance(value, list):
            f.write("[\n" + ",\n".join(json.dumps(v) for v in value) + "\n]\n")
            return
        f.write("{\n")
        for i, (key, v) in enumerate(value.items()):
            f.write(json.dumps(key) + ": ")
            if isinstance(v, list):
                f.write("[\n" + ",\n".join(" " + json.dumps(x) for x in v) + "\n]")
            else:
                f.write(json.dumps(v))
            f.write(",\n" if i + 1 < len(value) else "\n")
        f.write("}\n")


def main():
    os.makedirs(OUT, exist_ok=True)
    gmsh.initialize()
    gmsh.option.setNumber("General.Verbosity", 2)
    gmsh.model.add("two-parts")
    build()
    for version, binary, name in ((4.1, 0, "two-parts-4.1.msh"), (4.1, 1, "two-parts-4.1-binary.msh"),
                                  (2.2, 0, "two-parts-2.2.msh"), (2.2, 1, "two-parts-2.2-binary.msh")):
        gmsh.option.setNumber("Mesh.MshFileVersion", version)
        gmsh.option.setNumber("Mesh.Binary", binary)
        gmsh.write(os.path.join(OUT, name))
    # MSH 4.1 with the parametric coordinates of the nodes on curves and surfaces (skipped by
    # the reader), ASCII and binary.
    gmsh.option.setNumber("Mesh.SaveParametric", 1)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    for binary, name in ((0, "two-parts-4.1-parametric.msh"), (1, "two-parts-4.1-parametric-binary.msh")):
        gmsh.option.setNumber("Mesh.Binary", binary)
        gmsh.write(os.path.join(OUT, name))
    gmsh.option.setNumber("Mesh.SaveParametric", 0)
    write_json(os.path.join(OUT, "two-parts.json"), account())
    write_json(os.path.join(OUT, "element-types.json"), element_types())
    gmsh.finalize()


if __name__ == "__main__":
    main()
