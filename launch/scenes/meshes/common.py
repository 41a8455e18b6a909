"""What the mesh scripts of this directory share: Gmsh's options for glissade's QUA8 meshes and the
writing of a mesh with Gmsh's own account of it.

Each script builds its geometry with the geo kernel (shared curve entities between neighbouring
surfaces, so the nodes of a shared curve are the same nodes in both), meshes it transfinite and
recombined, and calls `write` for each mesh file. stratified.py instead gives Gmsh the block
mesher's nodes and elements and writes binary.
"""

import json
import os

import gmsh

HERE = os.path.dirname(os.path.abspath(__file__))
# Gmsh's account of each mesh (node count, element counts, physical groups), for the scene crate's
# tests, which must not need Gmsh.
ACCOUNTS = os.path.normpath(os.path.join(HERE, "..", "..", "..", "nodes", "scene", "tests", "fixtures", "msh"))


def start(name):
    gmsh.initialize()
    gmsh.option.setNumber("General.Verbosity", 2)
    gmsh.model.add(name)


def qua8_options():
    """8-node quadrangles (QUA8) only, saved as MSH 4.1 ASCII, physical groups only."""
    gmsh.option.setNumber("Mesh.ElementOrder", 2)
    gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 1)
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.option.setNumber("Mesh.SaveAll", 0)


def write(filename):
    """Writes the current mesh beside the scripts and Gmsh's account of it among the fixtures."""
    gmsh.write(os.path.join(HERE, filename))
    groups = []
    counts = {}
    for dim, tag in gmsh.model.getPhysicalGroups():
        entities = [int(e) for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)]
        groups.append({"dim": dim, "tag": tag, "name": gmsh.model.getPhysicalName(dim, tag),
                       "entities": entities})
    # Elements saved: those of the entities of physical groups, each once.
    # Nodes saved: those of these elements (the centre of the arcs, a geometric point meshed by a
    # node of no element, is not saved).
    saved = {(g["dim"], e) for g in groups for e in g["entities"]}
    nodes = set()
    for dim, entity in sorted(saved):
        types, tags, node_tags = gmsh.model.mesh.getElements(dim, entity)
        for kind, ts, ns in zip(types, tags, node_tags):
            counts[str(int(kind))] = counts.get(str(int(kind)), 0) + len(ts)
            nodes.update(int(n) for n in ns)
    account = {"nodes": len(nodes), "element_counts": counts, "physical_groups": groups}
    stem = os.path.splitext(filename)[0]
    with open(os.path.join(ACCOUNTS, stem + ".json"), "w") as f:
        f.write("{\n")
        f.write(f' "nodes": {account["nodes"]},\n')
        f.write(f' "element_counts": {json.dumps(counts)},\n')
        f.write(' "physical_groups": [\n')
        f.write(",\n".join("  " + json.dumps(g) for g in groups))
        f.write("\n ]\n}\n")
