//! Gmsh's element types: node count, dimension, order and shape of each, and their names in
//! refusals.

/// Gmsh's element types with a fixed number of nodes: (type, nodes, dimension, order, shape), as
/// `gmsh.model.mesh.getElementProperties` gives them (Gmsh 4.15; the tests compare this table with
/// its account in `tests/fixtures/msh/element-types.json`).
const TYPES: &[(u32, usize, u8, u8, &str)] = &[
    (1, 2, 1, 1, "line"),
    (2, 3, 2, 1, "triangle"),
    (3, 4, 2, 1, "quadrangle"),
    (4, 4, 3, 1, "tetrahedron"),
    (5, 8, 3, 1, "hexahedron"),
    (6, 6, 3, 1, "prism"),
    (7, 5, 3, 1, "pyramid"),
    (8, 3, 1, 2, "line"),
    (9, 6, 2, 2, "triangle"),
    (10, 9, 2, 2, "quadrangle"),
    (11, 10, 3, 2, "tetrahedron"),
    (12, 27, 3, 2, "hexahedron"),
    (13, 18, 3, 2, "prism"),
    (14, 14, 3, 2, "pyramid"),
    (15, 1, 0, 0, "point"),
    (16, 8, 2, 2, "quadrangle"),
    (17, 20, 3, 2, "hexahedron"),
    (18, 15, 3, 2, "prism"),
    (19, 13, 3, 2, "pyramid"),
    (20, 9, 2, 3, "triangle"),
    (21, 10, 2, 3, "triangle"),
    (22, 12, 2, 4, "triangle"),
    (23, 15, 2, 4, "triangle"),
    (24, 15, 2, 5, "triangle"),
    (25, 21, 2, 5, "triangle"),
    (26, 4, 1, 3, "line"),
    (27, 5, 1, 4, "line"),
    (28, 6, 1, 5, "line"),
    (29, 20, 3, 3, "tetrahedron"),
    (30, 35, 3, 4, "tetrahedron"),
    (31, 56, 3, 5, "tetrahedron"),
    (32, 22, 3, 4, "tetrahedron"),
    (33, 28, 3, 5, "tetrahedron"),
    (36, 16, 2, 3, "quadrangle"),
    (37, 25, 2, 4, "quadrangle"),
    (38, 36, 2, 5, "quadrangle"),
    (39, 12, 2, 3, "quadrangle"),
    (40, 16, 2, 4, "quadrangle"),
    (41, 20, 2, 5, "quadrangle"),
    (42, 28, 2, 6, "triangle"),
    (43, 36, 2, 7, "triangle"),
    (44, 45, 2, 8, "triangle"),
    (45, 55, 2, 9, "triangle"),
    (46, 66, 2, 10, "triangle"),
    (47, 49, 2, 6, "quadrangle"),
    (48, 64, 2, 7, "quadrangle"),
    (49, 81, 2, 8, "quadrangle"),
    (50, 100, 2, 9, "quadrangle"),
    (51, 121, 2, 10, "quadrangle"),
    (52, 18, 2, 6, "triangle"),
    (53, 21, 2, 7, "triangle"),
    (54, 24, 2, 8, "triangle"),
    (55, 27, 2, 9, "triangle"),
    (56, 30, 2, 10, "triangle"),
    (57, 24, 2, 6, "quadrangle"),
    (58, 28, 2, 7, "quadrangle"),
    (59, 32, 2, 8, "quadrangle"),
    (60, 36, 2, 9, "quadrangle"),
    (61, 40, 2, 10, "quadrangle"),
    (62, 7, 1, 6, "line"),
    (63, 8, 1, 7, "line"),
    (64, 9, 1, 8, "line"),
    (65, 10, 1, 9, "line"),
    (66, 11, 1, 10, "line"),
    (71, 84, 3, 6, "tetrahedron"),
    (72, 120, 3, 7, "tetrahedron"),
    (73, 165, 3, 8, "tetrahedron"),
    (74, 220, 3, 9, "tetrahedron"),
    (75, 286, 3, 10, "tetrahedron"),
    (79, 34, 3, 6, "tetrahedron"),
    (80, 40, 3, 7, "tetrahedron"),
    (81, 46, 3, 8, "tetrahedron"),
    (82, 52, 3, 9, "tetrahedron"),
    (83, 58, 3, 10, "tetrahedron"),
    (84, 1, 1, 0, "line"),
    (85, 1, 2, 0, "triangle"),
    (86, 1, 2, 0, "quadrangle"),
    (87, 1, 3, 0, "tetrahedron"),
    (88, 1, 3, 0, "hexahedron"),
    (89, 1, 3, 0, "prism"),
    (92, 64, 3, 3, "hexahedron"),
    (93, 125, 3, 4, "hexahedron"),
    (94, 216, 3, 5, "hexahedron"),
    (95, 343, 3, 6, "hexahedron"),
    (96, 512, 3, 7, "hexahedron"),
    (97, 729, 3, 8, "hexahedron"),
    (98, 1000, 3, 9, "hexahedron"),
    (99, 32, 3, 3, "hexahedron"),
    (100, 44, 3, 4, "hexahedron"),
    (101, 56, 3, 5, "hexahedron"),
    (102, 68, 3, 6, "hexahedron"),
    (103, 80, 3, 7, "hexahedron"),
    (104, 92, 3, 8, "hexahedron"),
    (105, 104, 3, 9, "hexahedron"),
    (118, 30, 3, 3, "pyramid"),
    (119, 55, 3, 4, "pyramid"),
    (120, 91, 3, 5, "pyramid"),
    (121, 140, 3, 6, "pyramid"),
    (122, 204, 3, 7, "pyramid"),
    (123, 285, 3, 8, "pyramid"),
    (124, 385, 3, 9, "pyramid"),
    (125, 21, 3, 3, "pyramid"),
    (126, 29, 3, 4, "pyramid"),
    (127, 37, 3, 5, "pyramid"),
    (128, 45, 3, 6, "pyramid"),
    (129, 53, 3, 7, "pyramid"),
    (130, 61, 3, 8, "pyramid"),
    (131, 69, 3, 9, "pyramid"),
    (132, 1, 3, 0, "pyramid"),
    (137, 16, 3, 3, "tetrahedron"),
];

fn type_entry(kind: u32) -> Option<&'static (u32, usize, u8, u8, &'static str)> {
    TYPES.iter().find(|t| t.0 == kind)
}

/// Gmsh's name of an element type ("8-node quadrangle", "6-node triangle", ...), for refusals.
/// Where two types share a node count and a shape, their order tells them apart
/// ("15-node triangle of order 4").
pub fn type_name(kind: u32) -> String {
    let Some(&(_, n, _, order, shape)) = type_entry(kind) else {
        return format!("unknown element type {kind}");
    };
    let shared = TYPES.iter().filter(|t| t.1 == n && t.4 == shape).count() > 1;
    if shared {
        format!("{n}-node {shape} of order {order}")
    } else {
        format!("{n}-node {shape}")
    }
}

/// Number of nodes of an element type (None if unknown) and its dimension.
pub fn type_nodes(kind: u32) -> Option<(usize, u8)> {
    type_entry(kind).map(|&(_, n, dim, _, _)| (n, dim))
}
