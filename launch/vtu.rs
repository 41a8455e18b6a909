//! ParaView output: a `.pvd` time series with, per time point, one VTK XML unstructured grid of
//! the subdomains and one of the interfaces (binary appended data, raw, little-endian, UInt64
//! block headers). docs/outputs.md describes every array.
//!
//! - Solid (`solid-NNNN.vtu`): every subdomain's nodes in the reference configuration (z = 0),
//!   its QUA8 elements as quadratic quadrilaterals (VTK type 23, the same node order), point data
//!   `displacement` (3 components, u_z = 0), `stress` (σ_xx, σ_yy, σ_zz, σ_xy, σ_yz, σ_xz, the
//!   order of ParaView's symmetric tensors; nodal averages), `von_mises`; cell data `subdomain`.
//! - Interfaces (`interfaces-NNNN.vtu`): each interface's node pairs at their coordinates, its
//!   3-node edges (those of side a whose middle node is a pair) as quadratic edges (VTK type 21:
//!   end, end, middle), point data `traction_n`, `traction_t` (F on side a in the interface's
//!   frame, MPa), `jump_n`, `jump_t` (W_b − W_a, mm; both of s, the state the verdict judged),
//!   `displacement_a`, `displacement_b` (W_a, W_b: side b's projected on a non-matching
//!   interface; NaN at clamped ends), `status` (0 separated, 1 stick, 2 slip, 3 limit, 4 grazing,
//!   −1 on perfect interfaces, −2 at an edge end clamped on both sides, which is no pair), `normal`
//!   and `tangent`; cell data `interface` and `contact` (1 on contact interfaces).

use crate::error::{Error, IoWhat, Result};
use crate::output::pair_values;
pub use crate::output::series_paths;
use glissade_mechanics::model::Model;
use glissade_mechanics::post::{nodal_stresses_into, von_mises, NodalStress};
use glissade_messages::InterfaceSolution;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// VTK cell type of a quadratic quadrilateral (8 nodes).
const VTK_QUADRATIC_QUAD: u8 = 23;
/// VTK cell type of a quadratic edge (3 nodes).
const VTK_QUADRATIC_EDGE: u8 = 21;
/// `status` of an interface point clamped on both sides: not an unknown of the problem; its
/// traction (a support reaction) is not computed (NaN) and its jump is 0.
const CLAMPED: i32 = -2;

/// What [`write_series`] wrote.
#[derive(Debug, Clone)]
pub struct Series {
    /// The `.pvd` collection, to open in ParaView.
    pub pvd: PathBuf,
    /// The folder of the `.vtu` files, next to it.
    pub dir: PathBuf,
    pub files: usize,
    pub bytes: u64,
}

/// The time points a series written every `every` time points holds: 0, every, 2·every, … and
/// the last.
pub fn series_times(n_points: usize, every: usize) -> Vec<usize> {
    let mut times: Vec<usize> = (0..n_points).step_by(every.max(1)).collect();
    if times.last() != Some(&(n_points - 1)) {
        times.push(n_points - 1);
    }
    times
}

/// The displacements `u` and the interface solutions checked against the scene (every
/// subdomain at every time point, every interface with W, F and statuses of its shape), the
/// solutions by interface.
fn checked_inputs<'a>(
    model: &Model,
    u: &[Vec<&[f64]>],
    interfaces: &'a [InterfaceSolution],
) -> Result<Vec<Option<&'a InterfaceSolution>>> {
    let nt = model.time.n_points();
    if u.len() != model.subdomains.len() {
        return Err(Error::ResultShape {
            what: format!("displacements of {} subdomains", u.len()),
            scene: format!("{}", model.subdomains.len()),
        });
    }
    for (s, per_time) in u.iter().enumerate() {
        let sub = &model.subdomains[s];
        if per_time.len() != nt || per_time.iter().any(|v| v.len() != sub.n_dofs()) {
            return Err(Error::ResultShape {
                what: format!(
                    "displacement of subdomain `{}`: {} time points of {:?} values",
                    sub.name,
                    per_time.len(),
                    per_time.first().map(|v| v.len())
                ),
                scene: format!("{nt} of {}", sub.n_dofs()),
            });
        }
    }
    let mut by_interface: Vec<Option<&InterfaceSolution>> = vec![None; model.interfaces.len()];
    for sol in interfaces {
        let slot = by_interface
            .get_mut(sol.interface as usize)
            .ok_or_else(|| Error::ResultShape {
                what: format!("a solution of interface {}", sol.interface),
                scene: format!("{} interface(s)", model.interfaces.len()),
            })?;
        *slot = Some(sol);
    }
    for (i, itf) in model.interfaces.iter().enumerate() {
        let Some(sol) = by_interface[i] else {
            return Err(Error::ResultMissing {
                what: format!(
                    "solution of interface {i} ({} | {})",
                    model.subdomains[itf.a].name, model.subdomains[itf.b].name
                ),
            });
        };
        let rows = 2 * itf.n_pairs();
        for (name, f) in [("F_a", &sol.f_a), ("W_a", &sol.w_a), ("W_b", &sol.w_b)] {
            if f.rows() != rows || f.cols() != nt {
                return Err(Error::ResultShape {
                    what: format!("interface {i}: {name} is {} × {}", f.rows(), f.cols()),
                    scene: format!("{rows} × {nt}"),
                });
            }
        }
        if itf.is_contact() && sol.status.len() != itf.n_pairs() * nt {
            return Err(Error::ResultShape {
                what: format!("interface {i}: {} statuses", sol.status.len()),
                scene: format!("{}", itf.n_pairs() * nt),
            });
        }
    }
    Ok(by_interface)
}

/// Writes the time series of `model` to `out/<stem>.pvd` and `out/<stem>-vtu/`, every `every`
/// time points and the last ([`series_times`]): `u[s][i]` is subdomain s's displacement at time
/// point i (2 values per node), `interfaces` the interface solutions (ŝ) of the run. Refuses to
/// write over an existing series; the folder appears under its name only once complete.
pub fn write_series(
    model: &Model,
    u: &[Vec<&[f64]>],
    interfaces: &[InterfaceSolution],
    out: &Path,
    stem: &str,
    every: usize,
) -> Result<Series> {
    let nt = model.time.n_points();
    let by_interface = checked_inputs(model, u, interfaces)?;
    let (pvd, dir) = series_paths(out, stem);
    for p in [&pvd, &dir] {
        if std::fs::symlink_metadata(p).is_ok() {
            return Err(Error::Exists(p.to_path_buf()));
        }
    }
    let partial = out.join(format!(".{stem}-vtu.partial"));
    if partial.exists() {
        std::fs::remove_dir_all(&partial).what(|| format!("cannot remove {}", partial.display()))?;
    }
    std::fs::create_dir_all(&partial).what(|| format!("cannot create {}", partial.display()))?;
    let times = series_times(nt, every);
    let written = write_vtu_files(model, u, &by_interface, &partial, &dir, &times);
    let (bytes, collection) = match written {
        Ok(w) => w,
        Err(e) => {
            // Nothing of a series that could not be written is kept.
            let _ = std::fs::remove_dir_all(&partial);
            return Err(Error::NotDone {
                what: format!("the ParaView series {} was not written", pvd.display()),
                source: Box::new(e),
            });
        }
    };
    let text = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"1.0\" byte_order=\"LittleEndian\">\n  <Collection>\n{collection}  </Collection>\n</VTKFile>\n"
    );
    if let Err(e) = crate::files::rename_new(&partial, &dir) {
        let _ = std::fs::remove_dir_all(&partial);
        return Err(Error::Move {
            from: partial,
            to: dir,
            why: crate::files::io_why(&e),
        });
    }
    if let Err(e) = crate::files::write_through_partial(&pvd, false, |w| w.write_all(text.as_bytes())) {
        // The series' files without their index: removed with it.
        let _ = std::fs::remove_dir_all(&dir);
        return Err(Error::NotDone {
            what: format!("the ParaView series {} was not written", pvd.display()),
            source: Box::new(e),
        });
    }
    Ok(Series {
        pvd,
        dir,
        files: 2 * times.len(),
        bytes: bytes + text.len() as u64,
    })
}

/// Writes the VTU files of time points `times` into `folder` (named in errors as in `dir`, where
/// they go once complete); returns their bytes and the `.pvd` collection's entries.
fn write_vtu_files(
    model: &Model,
    u: &[Vec<&[f64]>],
    by_interface: &[Option<&InterfaceSolution>],
    folder: &Path,
    dir: &Path,
    times: &[usize],
) -> Result<(u64, String)> {
    use rayon::prelude::*;
    let solid = SolidGrid::new(model);
    let edges = InterfaceGrid::new(model);
    // `dir` is `<out>/<stem>-vtu` (series_paths): it has a file name.
    let dir_name = dir
        .file_name()
        .expect("series_paths names the folder <stem>-vtu")
        .to_string_lossy()
        .into_owned();
    // Time points in parallel, each thread with a buffer of its own (most of the time goes to the
    // kernel's copy of the files into the page cache, which then runs on every core too); the
    // collection lists them in time order whatever order they were written in.
    let files: Vec<(usize, u64)> = times
        .par_iter()
        .map_init(Vec::new, |buf, &i| -> Result<(usize, u64)> {
            let mut bytes = 0u64;
            for part in [0, 1] {
                let name = vtu_name(part, i);
                buf.clear();
                if part == 0 {
                    solid.write(model, u, i, buf)?;
                } else {
                    edges.write(model, by_interface, i, buf);
                }
                std::fs::write(folder.join(&name), &buf[..]).map_err(|e| Error::Write {
                    path: dir.join(&name),
                    why: crate::files::io_why(&e),
                })?;
                bytes += buf.len() as u64;
            }
            Ok((i, bytes))
        })
        .collect::<Result<_>>()?;
    let mut collection = String::new();
    for &(i, _) in &files {
        let t = model.time.t(i);
        for part in [0, 1] {
            let _ = writeln!(
                collection,
                r#"    <DataSet timestep="{t:?}" part="{part}" file="{dir_name}/{}"/>"#,
                vtu_name(part, i)
            );
        }
    }
    Ok((files.iter().map(|&(_, b)| b).sum(), collection))
}

/// The file of time point `i`'s solid (part 0) or interfaces (part 1).
fn vtu_name(part: usize, i: usize) -> String {
    if part == 0 {
        format!("solid-{i:04}.vtu")
    } else {
        format!("interfaces-{i:04}.vtu")
    }
}

/// Points and cells of a grid, as the bytes of their arrays.
#[derive(Default)]
struct Geometry {
    points: Vec<u8>,
    connectivity: Vec<u8>,
    offsets: Vec<u8>,
    types: Vec<u8>,
    n_points: usize,
    n_cells: usize,
    /// Length of the connectivity (the last offset).
    n_refs: usize,
}

impl Geometry {
    fn point(&mut self, [x, y]: [f64; 2]) {
        put_f64(&mut self.points, &[x, y, 0.0]);
        self.n_points += 1;
    }

    fn cell(&mut self, kind: u8, nodes: &[usize]) {
        for &n in nodes {
            self.connectivity.extend_from_slice(&(n as i64).to_le_bytes());
        }
        self.n_cells += 1;
        self.n_refs += nodes.len();
        self.offsets.extend_from_slice(&(self.n_refs as i64).to_le_bytes());
        self.types.push(kind);
    }

    /// A new piece of this geometry, its points and cells written.
    fn piece(&self) -> Appended {
        let mut w = Appended::new(self.n_points, self.n_cells);
        w.section("Points");
        w.array("Points", "Float64", 3, &self.points);
        w.end("Points");
        w.section("Cells");
        w.array("connectivity", "Int64", 1, &self.connectivity);
        w.array("offsets", "Int64", 1, &self.offsets);
        w.array("types", "UInt8", 1, &self.types);
        w.end("Cells");
        w
    }
}

/// The subdomains' geometry, the same at every time point.
struct SolidGrid {
    geometry: Geometry,
    subdomain: Vec<u8>,
}

impl SolidGrid {
    fn new(model: &Model) -> Self {
        let mut geometry = Geometry::default();
        let mut subdomain = Vec::new();
        for (s, sub) in model.subdomains.iter().enumerate() {
            let base = geometry.n_points;
            for &x in &sub.mesh.coords {
                geometry.point(x);
            }
            for el in &sub.mesh.elements {
                geometry.cell(VTK_QUADRATIC_QUAD, &el.map(|n| base + n));
                subdomain.extend_from_slice(&(s as i32).to_le_bytes());
            }
        }
        SolidGrid { geometry, subdomain }
    }

    fn write(&self, model: &Model, u: &[Vec<&[f64]>], i: usize, out: &mut Vec<u8>) -> Result<()> {
        let n_points = self.geometry.n_points;
        let mut displacement = Vec::with_capacity(24 * n_points);
        let mut stress = Vec::with_capacity(48 * n_points);
        let mut vm = Vec::with_capacity(8 * n_points);
        let mut nodal: Vec<NodalStress> = Vec::new();
        let mut count = Vec::new();
        for (s, sub) in model.subdomains.iter().enumerate() {
            let v = u[s][i];
            let n = sub.mesh.coords.len();
            nodal.resize(n, [0.0; 4]);
            count.resize(n, 0);
            nodal_stresses_into(sub, model.plane, v, &mut nodal, &mut count).map_err(|e| Error::ResultShape {
                what: format!("displacement of subdomain `{}` gives no stresses ({e})", sub.name),
                scene: "a field on its mesh".into(),
            })?;
            for k in 0..n {
                put_f64(&mut displacement, &[v[2 * k], v[2 * k + 1], 0.0]);
                let [sx, sy, sz, txy] = nodal[k];
                put_f64(&mut stress, &[sx, sy, sz, txy, 0.0, 0.0]);
                put_f64(&mut vm, &[von_mises(&nodal[k])]);
            }
        }
        let mut w = self.geometry.piece();
        w.section("PointData");
        w.array("displacement", "Float64", 3, &displacement);
        w.array("stress", "Float64", 6, &stress);
        w.array("von_mises", "Float64", 1, &vm);
        w.end("PointData");
        w.section("CellData");
        w.array("subdomain", "Int32", 1, &self.subdomain);
        w.end("CellData");
        w.finish(out);
        Ok(())
    }
}

/// The interfaces' geometry (node pairs and 3-node edges), the same at every time point.
struct InterfaceGrid {
    geometry: Geometry,
    interface: Vec<u8>,
    contact: Vec<u8>,
    normal: Vec<u8>,
    tangent: Vec<u8>,
    /// Per interface, its points after the node pairs: nodes of side a on an interface edge
    /// that are clamped on both sides (not unknowns, so not pairs).
    extra: Vec<usize>,
}

impl InterfaceGrid {
    fn new(model: &Model) -> Self {
        let mut g = InterfaceGrid {
            geometry: Geometry::default(),
            interface: Vec::new(),
            contact: Vec::new(),
            normal: Vec::new(),
            tangent: Vec::new(),
            extra: Vec::new(),
        };
        for (k, itf) in model.interfaces.iter().enumerate() {
            let base = g.geometry.n_points;
            let mesh = &model.subdomains[itf.a].mesh;
            let pair_of: HashMap<usize, usize> = itf.pairs.iter().enumerate().map(|(p, &(n, _))| (n, p)).collect();
            // Nodes of side a on an interface edge that are not pairs (clamped on both sides).
            let mut extra: Vec<usize> = Vec::new();
            let mut point = |n: usize| match pair_of.get(&n) {
                Some(&p) => base + p,
                None => {
                    let e = extra.iter().position(|&m| m == n).unwrap_or_else(|| {
                        extra.push(n);
                        extra.len() - 1
                    });
                    base + itf.n_pairs() + e
                }
            };
            for el in &mesh.elements {
                for side in 0..4 {
                    let (c0, mid, c1) = (el[side], el[4 + side], el[(side + 1) % 4]);
                    if !pair_of.contains_key(&mid) {
                        continue;
                    }
                    g.geometry.cell(VTK_QUADRATIC_EDGE, &[point(c0), point(c1), point(mid)]);
                    g.interface.extend_from_slice(&(k as i32).to_le_bytes());
                    g.contact.extend_from_slice(&(itf.is_contact() as i32).to_le_bytes());
                }
            }
            // Clamped extra points take the interface's mean frame (they are no pair).
            let frame = itf.mean_frame().0;
            let normals = itf.normals.iter().copied().chain(extra.iter().map(|_| frame));
            let coords = itf.coords.iter().copied().chain(extra.iter().map(|&n| mesh.coords[n]));
            for (x, n) in coords.zip(normals) {
                g.geometry.point(x);
                put_f64(&mut g.normal, &[n[0], n[1], 0.0]);
                put_f64(&mut g.tangent, &[-n[1], n[0], 0.0]);
            }
            g.extra.push(extra.len());
        }
        g
    }

    fn write(&self, model: &Model, solutions: &[Option<&InterfaceSolution>], i: usize, out: &mut Vec<u8>) {
        let n = self.geometry.n_points;
        let (mut f_n, mut f_t, mut j_n, mut j_t, mut status) = (
            Vec::with_capacity(8 * n),
            Vec::with_capacity(8 * n),
            Vec::with_capacity(8 * n),
            Vec::with_capacity(8 * n),
            Vec::with_capacity(4 * n),
        );
        let (mut u_a, mut u_b) = (Vec::with_capacity(24 * n), Vec::with_capacity(24 * n));
        for (k, itf) in model.interfaces.iter().enumerate() {
            let sol = solutions[k].expect("checked by write_series");
            let np = itf.n_pairs();
            for p in 0..np {
                let [n, t, jn, jt] = pair_values(itf, sol, i, p);
                put_f64(&mut f_n, &[n]);
                put_f64(&mut f_t, &[t]);
                put_f64(&mut j_n, &[jn]);
                put_f64(&mut j_t, &[jt]);
                // Each side's displacement at the pair: side b's through its projection on a
                // non-matching interface.
                put_f64(&mut u_a, &[sol.w_a.get(2 * p, i), sol.w_a.get(2 * p + 1, i), 0.0]);
                put_f64(&mut u_b, &[sol.w_b.get(2 * p, i), sol.w_b.get(2 * p + 1, i), 0.0]);
                let st = if itf.is_contact() {
                    sol.status[i * np + p] as i32
                } else {
                    -1
                };
                status.extend_from_slice(&st.to_le_bytes());
            }
            for _ in 0..self.extra[k] {
                put_f64(&mut f_n, &[f64::NAN]);
                put_f64(&mut f_t, &[f64::NAN]);
                put_f64(&mut j_n, &[0.0]);
                put_f64(&mut j_t, &[0.0]);
                put_f64(&mut u_a, &[f64::NAN; 3]);
                put_f64(&mut u_b, &[f64::NAN; 3]);
                status.extend_from_slice(&CLAMPED.to_le_bytes());
            }
        }
        let mut w = self.geometry.piece();
        w.section("PointData");
        w.array("traction_n", "Float64", 1, &f_n);
        w.array("traction_t", "Float64", 1, &f_t);
        w.array("jump_n", "Float64", 1, &j_n);
        w.array("jump_t", "Float64", 1, &j_t);
        w.array("displacement_a", "Float64", 3, &u_a);
        w.array("displacement_b", "Float64", 3, &u_b);
        w.array("status", "Int32", 1, &status);
        w.array("normal", "Float64", 3, &self.normal);
        w.array("tangent", "Float64", 3, &self.tangent);
        w.end("PointData");
        w.section("CellData");
        w.array("interface", "Int32", 1, &self.interface);
        w.array("contact", "Int32", 1, &self.contact);
        w.end("CellData");
        w.finish(out);
    }
}

fn put_f64(out: &mut Vec<u8>, values: &[f64]) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// One piece of a VTK XML unstructured grid with its arrays in raw appended data: each block is
/// its byte count (UInt64) followed by the bytes.
struct Appended {
    xml: String,
    data: Vec<u8>,
}

impl Appended {
    fn new(n_points: usize, n_cells: usize) -> Self {
        let xml = format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n  <UnstructuredGrid>\n    <Piece NumberOfPoints=\"{n_points}\" NumberOfCells=\"{n_cells}\">\n"
        );
        Appended { xml, data: Vec::new() }
    }

    fn section(&mut self, name: &str) {
        let _ = writeln!(self.xml, "      <{name}>");
    }

    fn end(&mut self, name: &str) {
        let _ = writeln!(self.xml, "      </{name}>");
    }

    fn array(&mut self, name: &str, ty: &str, components: usize, bytes: &[u8]) {
        let components = if components > 1 {
            format!(" NumberOfComponents=\"{components}\"")
        } else {
            String::new()
        };
        let _ = writeln!(
            self.xml,
            "        <DataArray type=\"{ty}\" Name=\"{name}\"{components} format=\"appended\" offset=\"{}\"/>",
            self.data.len()
        );
        self.data.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        self.data.extend_from_slice(bytes);
    }

    fn finish(self, out: &mut Vec<u8>) {
        out.extend_from_slice(self.xml.as_bytes());
        out.extend_from_slice(b"    </Piece>\n  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _");
        out.extend_from_slice(&self.data);
        out.extend_from_slice(b"\n  </AppendedData>\n</VTKFile>\n");
    }
}

/// Writes `data` (already complete) to `path` through a partial file, refusing to overwrite.
pub fn write_new_file(path: &Path, data: &[u8]) -> Result<()> {
    if std::fs::symlink_metadata(path).is_ok() {
        return Err(Error::Exists(path.to_path_buf()));
    }
    crate::files::write_through_partial(path, false, |w| w.write_all(data))
}

#[cfg(test)]
mod tests {
    use super::series_times;

    #[test]
    fn a_thinned_series_keeps_the_last_time_point() {
        assert_eq!(series_times(11, 1), (0..11).collect::<Vec<_>>());
        assert_eq!(series_times(11, 4), [0, 4, 8, 10]);
        assert_eq!(series_times(11, 5), [0, 5, 10]);
        assert_eq!(series_times(1, 3), [0]);
    }
}
