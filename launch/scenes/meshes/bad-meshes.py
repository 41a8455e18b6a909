"""Meshes glissade must refuse, each written by Gmsh, for the scene crate's refusal tests
(nodes/scene/tests/bad_meshes.rs): into tests/fixtures/msh-bad/ at the repository's root.

    python3 launch/scenes/meshes/bad-meshes.py

Every mesh has the physical curves `left` (x = min) and `right` (x = max) and the physical surface
`a` (and `b` where there are two); MSH 4.1 ASCII, physical groups only (Mesh.SaveAll = 0).
tests/fixtures/msh-bad/README.md says what each one is.

- triangles.msh: one rectangle of 6-node triangles (order 2, not recombined).
- mixed.msh: one physical surface of two rectangles sharing a curve, one recombined (QUA8), one
  not (6-node triangles).
- quad9.msh: 9-node quadrangles (Mesh.SecondOrderIncomplete = 0).
- linear.msh: 4-node quadrangles (Mesh.ElementOrder = 1).
- nonconforming.msh: rectangles `a` and `b` side by side, each with its own curve at x = 1
  (duplicate curves between the same points, not fragmented), meshed with 4 and 6 elements along
  it; QUA8. No longer refused: the parts meet on a non-matching interface (the scene crate's
  test of that reads it).
- pieces.msh: one physical surface `a` of two disjoint rectangles; QUA8.
- duplicates.msh: one physical surface `a` of two rectangles touching along x = 1, each with its
  own points and curve there (3 elements along both): the nodes of x = 1 are there twice; QUA8.
- two-physicals.msh: one rectangle in the physical surfaces `a` and `b`; QUA8.
- hinge.msh: one physical surface `a` of two squares touching at one corner point only; QUA8.
- offset.msh: squares `a` and `b` side by side along x = 1, b shifted up by half an element, so
  that every node of the shared line falls on a node of the other part, corners on middle nodes;
  QUA8.
- crossing.msh: rectangles `a` (height 1) and `b` (height 1.5) side by side along x = 1, each
  with its own curve there, 2 elements along each: b's edge from y = 0.75 to 1.5 crosses the end
  of the curve they share; QUA8.
"""

import os

import gmsh

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.normpath(os.path.join(HERE, "..", "..", "..", "tests", "fixtures", "msh-bad"))


def rectangle(x0, x1, y0, y1, nx, ny, points=None):
    """A transfinite rectangle with the geo kernel: (surface, [bottom, right, top, left] curves).
    `points` reuses corner points (bottom-left, bottom-right, top-right, top-left) where not None."""
    geo = gmsh.model.geo
    given = points or [None] * 4
    p = [given[k] if given[k] is not None else geo.addPoint(x, y, 0)
         for k, (x, y) in enumerate(((x0, y0), (x1, y0), (x1, y1), (x0, y1)))]
    curves = [geo.addLine(p[k], p[(k + 1) % 4]) for k in range(4)]
    surface = geo.addPlaneSurface([geo.addCurveLoop(curves)])
    # The geo kernel's own mesh constraints: they survive the synchronisations.
    for c, n in zip(curves, (nx, ny, nx, ny)):
        geo.mesh.setTransfiniteCurve(c, n + 1)
    geo.mesh.setTransfiniteSurface(surface)
    return surface, curves, p


def start(name, order=2, incomplete=1):
    gmsh.model.add(name)
    gmsh.option.setNumber("Mesh.ElementOrder", order)
    gmsh.option.setNumber("Mesh.SecondOrderIncomplete", incomplete)
    gmsh.option.setNumber("Mesh.RecombineAll", 0)


def finish(name, surfaces, left, right):
    """Physical surfaces ({name: [surfaces]}), curves `left` and `right`; mesh and write."""
    gmsh.model.geo.synchronize()
    for s_name, entities in surfaces.items():
        gmsh.model.addPhysicalGroup(2, entities, name=s_name)
    gmsh.model.addPhysicalGroup(1, left, name="left")
    gmsh.model.addPhysicalGroup(1, right, name="right")
    gmsh.model.mesh.generate(2)
    gmsh.write(os.path.join(OUT, name))
    gmsh.model.remove()


def recombined(surfaces):
    for s in surfaces:
        gmsh.model.geo.mesh.setRecombine(2, s)


def triangles():
    start("triangles")
    s, c, _ = rectangle(0, 2, 0, 1, 2, 1)
    finish("triangles.msh", {"a": [s]}, [c[3]], [c[1]])


def mixed():
    start("mixed")
    s1, c1, p1 = rectangle(0, 1, 0, 1, 2, 2)
    # The second rectangle shares the first one's right side (same points, the curve reversed).
    geo = gmsh.model.geo
    p = [p1[1], geo.addPoint(2, 0, 0), geo.addPoint(2, 1, 0), p1[2]]
    c2 = [geo.addLine(p[0], p[1]), geo.addLine(p[1], p[2]), geo.addLine(p[2], p[3])]
    s2 = geo.addPlaneSurface([geo.addCurveLoop([c2[0], c2[1], c2[2], -c1[1]])])
    for c in c2:
        geo.mesh.setTransfiniteCurve(c, 3)
    geo.mesh.setTransfiniteSurface(s2)
    recombined([s1])
    finish("mixed.msh", {"a": [s1, s2]}, [c1[3]], [c2[1]])


def quad9():
    start("quad9", incomplete=0)
    s, c, _ = rectangle(0, 2, 0, 1, 2, 1)
    recombined([s])
    finish("quad9.msh", {"a": [s]}, [c[3]], [c[1]])


def linear():
    start("linear", order=1)
    s, c, _ = rectangle(0, 2, 0, 1, 2, 1)
    recombined([s])
    finish("linear.msh", {"a": [s]}, [c[3]], [c[1]])


def nonconforming():
    start("nonconforming")
    sa, ca, pa = rectangle(0, 1, 0, 1, 2, 4)
    # b reuses a's points at x = 1 but has its own curve between them: 6 elements there.
    sb, cb, _ = rectangle(1, 2, 0, 1, 2, 6, points=[pa[1], None, None, pa[2]])
    recombined([sa, sb])
    finish("nonconforming.msh", {"a": [sa], "b": [sb]}, [ca[3]], [cb[1]])


def pieces():
    start("pieces")
    s1, c1, _ = rectangle(0, 1, 0, 1, 2, 2)
    s2, c2, _ = rectangle(2, 3, 0, 1, 2, 2)
    recombined([s1, s2])
    finish("pieces.msh", {"a": [s1, s2]}, [c1[3]], [c2[1]])


def duplicates():
    start("duplicates")
    s1, c1, _ = rectangle(0, 1, 0, 1, 2, 3)
    s2, c2, _ = rectangle(1, 2, 0, 1, 2, 3)
    recombined([s1, s2])
    finish("duplicates.msh", {"a": [s1, s2]}, [c1[3]], [c2[1]])


def hinge():
    start("hinge")
    s1, c1, p1 = rectangle(0, 1, 0, 1, 2, 2)
    # The second square shares only the first one's top-right corner point.
    s2, c2, _ = rectangle(1, 2, 1, 2, 2, 2, points=[p1[2], None, None, None])
    recombined([s1, s2])
    finish("hinge.msh", {"a": [s1, s2]}, [c1[3]], [c2[1]])


def beside_unit_square(name, b_y0, b_y1):
    """The unit square `a` and the rectangle `b` = [1, 2] × [b_y0, b_y1], each meshed on its own
    with 2 × 2 elements (its own curve on x = 1)."""
    start(name)
    sa, ca, _ = rectangle(0, 1, 0, 1, 2, 2)
    sb, cb, _ = rectangle(1, 2, b_y0, b_y1, 2, 2)
    recombined([sa, sb])
    finish(f"{name}.msh", {"a": [sa], "b": [sb]}, [ca[3]], [cb[1]])


def offset():
    # b's side on x = 1 is shifted by half an element: its corners fall on a's middle nodes.
    beside_unit_square("offset", 0.25, 1.25)


def two_physicals():
    start("two-physicals")
    s, c, _ = rectangle(0, 2, 0, 1, 2, 1)
    recombined([s])
    finish("two-physicals.msh", {"a": [s], "b": [s]}, [c[3]], [c[1]])


def main():
    os.makedirs(OUT, exist_ok=True)
    gmsh.initialize()
    gmsh.option.setNumber("General.Verbosity", 2)
    # Duplicate points and curves stay duplicates (duplicates.msh, nonconforming.msh).
    gmsh.option.setNumber("Geometry.AutoCoherence", 0)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    for make in (triangles, mixed, quad9, linear, nonconforming, pieces, duplicates, two_physicals, hinge, offset,
                 crossing):
        make()
    gmsh.finalize()


def crossing():
    # b is taller than a: its edge from y = 0.75 to 1.5 crosses a's corner.
    beside_unit_square("crossing", 0.0, 1.5)


if __name__ == "__main__":
    main()
