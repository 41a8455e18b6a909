"""Meshes of the shrink fit with rings meshed on their own: the rings of shrink-fit.py (inner
20 <= r <= 30 mm, outer 30 <= r <= 50 mm), each made of eight 45-degree sectors (Gmsh surfaces)
gathered in one part (`inner`, `outer`), 4 elements radially in the inner ring and 8 in the outer.

    python3 launch/scenes/meshes/shrink-fit-sectors.py

writes (shrink-fit-2.msh is their conforming twin: 48 elements around both rings)
- shrink-fit-nonmatching.msh: the inner ring 6 elements per sector along the fit, the outer ring 5
  and its sectors turned by 22.5 degrees: the rings are meshed on their own and have no node in
  common on r = 30 (each ring has its own arcs there);
- shrink-fit-nonmatching-fine.msh: the same with the outer ring 10 elements per sector along the
  fit (refined along the fit alone).

Physical curves: `bore` (r = 20), `fit` (r = 30: both rings' arcs where they are separate),
`outside` (r = 50).
"""

import math

import gmsh

import common

SECTORS = 8


def ring(geo, centre, r0, r1, turn, around_fit, radial, fit_arcs=None):
    """One ring of SECTORS sectors between radii r0 < r1, its sectors starting at `turn` degrees;
    `fit_arcs` reuses the arcs of r0 (a shared curve). Returns (surfaces, inner arcs, outer arcs)."""
    angle = lambda q: math.radians(turn + q * 360.0 / SECTORS)
    if fit_arcs is None:
        p0 = [geo.addPoint(r0 * math.cos(angle(q)), r0 * math.sin(angle(q)), 0) for q in range(SECTORS)]
        arcs0 = [geo.addCircleArc(p0[q], centre, p0[(q + 1) % SECTORS]) for q in range(SECTORS)]
    else:
        arcs0, p0 = fit_arcs
    p1 = [geo.addPoint(r1 * math.cos(angle(q)), r1 * math.sin(angle(q)), 0) for q in range(SECTORS)]
    arcs1 = [geo.addCircleArc(p1[q], centre, p1[(q + 1) % SECTORS]) for q in range(SECTORS)]
    rays = [geo.addLine(p0[q], p1[q]) for q in range(SECTORS)]
    surfaces = []
    for q in range(SECTORS):
        loop = geo.addCurveLoop([rays[q], arcs1[q], -rays[(q + 1) % SECTORS], -arcs0[q]])
        surfaces.append(geo.addPlaneSurface([loop]))
    return surfaces, (arcs0, p0), (arcs1, p1), rays


def build(outer_per_sector, turn, shared):
    geo = gmsh.model.geo
    centre = geo.addPoint(0, 0, 0)
    inner, bore, fit_in, rays_in = ring(geo, centre, 20.0, 30.0, 0.0, 6, 4)
    outer, fit_out, outside, rays_out = ring(geo, centre, 30.0, 50.0, turn, outer_per_sector, 8,
                                             fit_arcs=fit_in if shared else None)
    geo.synchronize()
    mesh = gmsh.model.mesh
    for arcs, n in ((bore[0], 6), (fit_in[0], 6), (fit_out[0], outer_per_sector), (outside[0], outer_per_sector)):
        for a in arcs:
            mesh.setTransfiniteCurve(a, n + 1)
    for rays, n in ((rays_in, 4), (rays_out, 8)):
        for r in rays:
            mesh.setTransfiniteCurve(r, n + 1)
    for s in inner + outer:
        mesh.setTransfiniteSurface(s)
        mesh.setRecombine(2, s)
    gmsh.model.addPhysicalGroup(2, inner, name="inner")
    gmsh.model.addPhysicalGroup(2, outer, name="outer")
    gmsh.model.addPhysicalGroup(1, bore[0], name="bore")
    fit = list(fit_in[0]) + ([] if shared else list(fit_out[0]))
    gmsh.model.addPhysicalGroup(1, fit, name="fit")
    gmsh.model.addPhysicalGroup(1, outside[0], name="outside")


def main():
    for name, outer_per_sector, turn, shared in (
        ("shrink-fit-nonmatching", 5, 22.5, False),
        ("shrink-fit-nonmatching-fine", 10, 22.5, False),
    ):
        common.start(name)
        build(outer_per_sector, turn, shared)
        common.qua8_options()
        gmsh.model.mesh.generate(2)
        common.write(f"{name}.msh")
        gmsh.finalize()


if __name__ == "__main__":
    main()
