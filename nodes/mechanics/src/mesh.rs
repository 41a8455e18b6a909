//! QUA8 meshes: node coordinates and 8-node serendipity elements, and the structured generator
//! for straight-sided quadrilateral blocks.
//!
//! Local node order of an element: corners 0..3 counter-clockwise from (ξ, η) = (−1, −1), then
//! mid-side nodes 4 (bottom), 5 (right), 6 (top), 7 (left).

/// A QUA8 mesh. Dof `2·node` is x, `2·node + 1` is y.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Mesh {
    pub coords: Vec<[f64; 2]>,
    pub elements: Vec<[usize; 8]>,
    /// The four sides of a structured block (bottom, right, top, left), each as its 3-node
    /// edges in order of increasing x (bottom, top) or y (right, left). Empty for general meshes.
    pub sides: Vec<Vec<[usize; 3]>>,
}

/// Side of a structured block, in the order of [`Mesh::sides`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BlockSide {
    Bottom = 0,
    Right = 1,
    Top = 2,
    Left = 3,
}

impl BlockSide {
    pub const ALL: [BlockSide; 4] = [BlockSide::Bottom, BlockSide::Right, BlockSide::Top, BlockSide::Left];

    pub fn name(self) -> &'static str {
        match self {
            BlockSide::Bottom => "bottom",
            BlockSide::Right => "right",
            BlockSide::Top => "top",
            BlockSide::Left => "left",
        }
    }
}

impl Mesh {
    /// Structured nx × ny QUA8 mesh of the quadrilateral with straight sides and corners
    /// `corners` (counter-clockwise from the bottom-left), by bilinear mapping of the unit square.
    pub fn structured(corners: [[f64; 2]; 4], nx: usize, ny: usize) -> Self {
        let (gx, gy) = (2 * nx + 1, 2 * ny + 1);
        let mut id = vec![usize::MAX; gx * gy];
        let mut coords = Vec::with_capacity(gx * gy - nx * ny);
        for j in 0..gy {
            for i in 0..gx {
                if i % 2 == 1 && j % 2 == 1 {
                    continue;
                }
                let u = i as f64 / (gx - 1) as f64;
                let v = j as f64 / (gy - 1) as f64;
                let w = [(1.0 - u) * (1.0 - v), u * (1.0 - v), u * v, (1.0 - u) * v];
                let x = (0..4).map(|c| w[c] * corners[c][0]).sum();
                let y = (0..4).map(|c| w[c] * corners[c][1]).sum();
                id[j * gx + i] = coords.len();
                coords.push([x, y]);
            }
        }
        let g = |i: usize, j: usize| id[j * gx + i];
        let mut elements = Vec::with_capacity(nx * ny);
        for ej in 0..ny {
            for ei in 0..nx {
                let (i, j) = (2 * ei, 2 * ej);
                elements.push([
                    g(i, j),
                    g(i + 2, j),
                    g(i + 2, j + 2),
                    g(i, j + 2),
                    g(i + 1, j),
                    g(i + 2, j + 1),
                    g(i + 1, j + 2),
                    g(i, j + 1),
                ]);
            }
        }
        let bottom = (0..nx)
            .map(|e| [g(2 * e, 0), g(2 * e + 1, 0), g(2 * e + 2, 0)])
            .collect();
        let top = (0..nx)
            .map(|e| [g(2 * e, gy - 1), g(2 * e + 1, gy - 1), g(2 * e + 2, gy - 1)])
            .collect();
        let left = (0..ny)
            .map(|e| [g(0, 2 * e), g(0, 2 * e + 1), g(0, 2 * e + 2)])
            .collect();
        let right = (0..ny)
            .map(|e| [g(gx - 1, 2 * e), g(gx - 1, 2 * e + 1), g(gx - 1, 2 * e + 2)])
            .collect();
        Self {
            coords,
            elements,
            sides: vec![bottom, right, top, left],
        }
    }

    /// Structured mesh of the axis-aligned rectangle [x0, x1] × [y0, y1].
    pub fn rectangle(x: [f64; 2], y: [f64; 2], nx: usize, ny: usize) -> Self {
        Self::structured([[x[0], y[0]], [x[1], y[0]], [x[1], y[1]], [x[0], y[1]]], nx, ny)
    }

    pub fn n_nodes(&self) -> usize {
        self.coords.len()
    }

    /// Nodes of one side of a structured block, in order along the side, without repeats.
    pub fn side_nodes(&self, side: BlockSide) -> Vec<usize> {
        let edges = &self.sides[side as usize];
        let mut nodes = Vec::with_capacity(2 * edges.len() + 1);
        for (k, e) in edges.iter().enumerate() {
            if k == 0 {
                nodes.push(e[0]);
            }
            nodes.push(e[1]);
            nodes.push(e[2]);
        }
        nodes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn structured_counts_and_sides() {
        let m = Mesh::rectangle([0.0, 30.0], [0.0, 30.0], 20, 20);
        assert_eq!(m.n_nodes(), 41 * 41 - 400);
        assert_eq!(m.elements.len(), 400);
        let top = m.side_nodes(BlockSide::Top);
        assert_eq!(top.len(), 41);
        for w in top.windows(2) {
            assert!(m.coords[w[1]][0] > m.coords[w[0]][0]);
            assert_eq!(m.coords[w[0]][1], 30.0);
        }
        // Mid-side node of the first element sits half-way along its bottom edge.
        let e = m.elements[0];
        assert_eq!(m.coords[e[4]], [0.75, 0.0]);
    }
}
