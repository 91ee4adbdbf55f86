//! Built-in meshes, so no scene ever needs a download.
//!
//! Sizes follow the source papers: `sheet(65)` has K = 4225 vertices (Tan et al. §VI,
//! SHEET), `sheet_with_holes` 4165, `ball` 1538 (BALL), and the default `beam` has
//! 2592 tetrahedra (NNWarp's training beam has 2,629).

use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::tetmesh::TetMesh;
use crate::trimesh::TriMesh;

/// An `n × n` vertex grid over a square of side `size` metres, centred at the origin in
/// the XY plane (normals +Z). Vertex `(i, j)` (i along X, j along Y) has index `j·n + i`.
/// Cell diagonals alternate so the triangulation has no preferred shear direction.
pub fn sheet(n: usize, size: f64) -> Result<TriMesh> {
    let (positions, faces) = sheet_arrays(n, size)?;
    TriMesh::new(positions, faces)
}

fn sheet_arrays(n: usize, size: f64) -> Result<(Vec<Vector3<f64>>, Vec<[usize; 3]>)> {
    if n < 2 {
        return Err(Error::InvalidParameter(format!(
            "sheet needs n >= 2 vertices per side, got {n}"
        )));
    }
    check_vertex_count(&format!("a sheet of n = {n}"), &[n, n])?;
    check_positive("sheet size", size)?;
    let h = size / (n - 1) as f64;
    let positions = (0..n * n)
        .map(|v| Vector3::new((v % n) as f64 * h - size / 2.0, (v / n) as f64 * h - size / 2.0, 0.0))
        .collect();
    let mut faces = Vec::with_capacity(2 * (n - 1) * (n - 1));
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let (a, b, c, d) = (j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i);
            if (i + j) % 2 == 0 {
                faces.extend([[a, b, c], [a, c, d]]);
            } else {
                faces.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    Ok((positions, faces))
}

/// An open tube along +X: `rings` circles of `around` vertices at `x` evenly from `x0`
/// to `x1`, circle `k` of radius `radius(x_k)` about the X axis. Vertex `(k, j)` (ring
/// `k`, angle `2πj/around` from +Y towards +Z) has index `k·around + j`. Faces are
/// oriented with normals pointing away from the axis, and quad diagonals alternate as in
/// [`sheet`]. The sleeve of the drape scene (design §8).
pub fn tube(around: usize, rings: usize, x0: f64, x1: f64, radius: impl Fn(f64) -> f64) -> Result<TriMesh> {
    if around < 3 || rings < 2 {
        return Err(Error::InvalidParameter(format!(
            "a tube needs ≥ 3 vertices around and ≥ 2 rings, got {around} and {rings}"
        )));
    }
    check_vertex_count("the tube", &[around, rings])?;
    if !(x1 > x0) || !x0.is_finite() || !x1.is_finite() {
        return Err(Error::InvalidParameter(format!(
            "a tube needs finite ends x0 < x1, got {x0} and {x1}"
        )));
    }
    let mut positions = Vec::with_capacity(around * rings);
    for k in 0..rings {
        let x = x0 + (x1 - x0) * k as f64 / (rings - 1) as f64;
        let r = radius(x);
        check_positive("tube radius", r)?;
        for j in 0..around {
            let phi = 2.0 * std::f64::consts::PI * j as f64 / around as f64;
            positions.push(Vector3::new(x, r * phi.cos(), r * phi.sin()));
        }
    }
    let mut faces = Vec::with_capacity(2 * around * (rings - 1));
    for k in 0..rings - 1 {
        for j in 0..around {
            let jn = (j + 1) % around;
            let (a, b, c, d) = (
                k * around + j,
                (k + 1) * around + j,
                (k + 1) * around + jn,
                k * around + jn,
            );
            // (a, b, c) runs +X then +φ: x̂ × φ̂ points at the axis, so reverse it.
            if (j + k) % 2 == 0 {
                faces.extend([[a, c, b], [a, d, c]]);
            } else {
                faces.extend([[a, d, b], [b, d, c]]);
            }
        }
    }
    TriMesh::new(positions, faces)
}

/// A circular hole in grid units: vertices strictly inside are removed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hole {
    pub center_i: f64,
    pub center_j: f64,
    pub radius: f64,
}

/// The two holes of the default holed sheet: 60 vertices removed from the 65-grid,
/// leaving K = 4165 (Tan et al.'s SHEET-with-holes size).
pub const DEFAULT_HOLES: [Hole; 2] = [
    Hole {
        center_i: 21.0,
        center_j: 21.5,
        radius: 3.15,
    },
    Hole {
        center_i: 43.0,
        center_j: 43.5,
        radius: 3.15,
    },
];

/// `sheet(n, size)` with circular holes cut out (faces touching a removed vertex go,
/// unreferenced vertices are dropped, the order of the rest is kept).
pub fn sheet_with_holes(n: usize, size: f64, holes: &[Hole]) -> Result<TriMesh> {
    let (positions, faces) = sheet_arrays(n, size)?;
    let removed: Vec<bool> = (0..n * n)
        .map(|v| {
            let (i, j) = ((v % n) as f64, (v / n) as f64);
            holes
                .iter()
                .any(|h| (i - h.center_i).powi(2) + (j - h.center_j).powi(2) < h.radius * h.radius)
        })
        .collect();
    let faces: Vec<[usize; 3]> = faces.into_iter().filter(|f| f.iter().all(|&v| !removed[v])).collect();
    let (positions, faces) = compact(&positions, &faces);
    TriMesh::new(positions, faces)
}

/// A closed UV sphere of `segments` vertices per ring, `rings` rings and two poles:
/// 48 × 32 + 2 = 1538 vertices for Tan et al.'s BALL. Centred at the origin, poles on ±Z,
/// vertex 0 is the north (+Z) pole and the last vertex the south pole.
pub fn ball(segments: usize, rings: usize, radius: f64) -> Result<TriMesh> {
    if segments < 3 || rings < 1 {
        return Err(Error::InvalidParameter(format!(
            "ball needs segments >= 3 and rings >= 1, got {segments} and {rings}"
        )));
    }
    // Two poles besides the rings (`rings + 1` bounds `rings · segments + 2` from above).
    check_vertex_count("the ball", &[segments, rings.saturating_add(1)])?;
    check_positive("ball radius", radius)?;
    let mut positions = vec![Vector3::new(0.0, 0.0, radius)];
    for r in 0..rings {
        let theta = std::f64::consts::PI * (r + 1) as f64 / (rings + 1) as f64;
        for s in 0..segments {
            let phi = 2.0 * std::f64::consts::PI * s as f64 / segments as f64;
            positions.push(radius * Vector3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()));
        }
    }
    let south = positions.len();
    positions.push(Vector3::new(0.0, 0.0, -radius));
    let at = |r: usize, s: usize| 1 + r * segments + s % segments;
    let mut faces = Vec::with_capacity(2 * segments * rings);
    for s in 0..segments {
        faces.push([0, at(0, s), at(0, s + 1)]);
        faces.push([south, at(rings - 1, s + 1), at(rings - 1, s)]);
    }
    for r in 0..rings - 1 {
        for s in 0..segments {
            faces.push([at(r, s), at(r + 1, s), at(r + 1, s + 1)]);
            faces.push([at(r, s), at(r + 1, s + 1), at(r, s + 1)]);
        }
    }
    TriMesh::new(positions, faces)
}

/// A box of `cells` hexahedral cells with physical `size` (metres), from the origin
/// along +X, +Y, +Z, each cell split into 6 tetrahedra (Kuhn/Freudenthal split, which is
/// conforming across cells). Vertex `(i, j, k)` has index `(k·(ny+1) + j)·(nx+1) + i`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeamParams {
    pub cells: [usize; 3],
    pub size: [f64; 3],
}

impl Default for BeamParams {
    /// 12 × 6 × 6 cells over 1.0 × 0.5 × 0.5 m: 637 vertices, 2592 tetrahedra.
    fn default() -> Self {
        Self {
            cells: [12, 6, 6],
            size: [1.0, 0.5, 0.5],
        }
    }
}

/// The box beam of `params`.
pub fn beam(params: &BeamParams) -> Result<TetMesh> {
    grid_tets(params, |_, _, _| true, |p| p)
}

/// A beam whose cross-section shrinks linearly along X to `tip_scale` times its root
/// size (about the beam's axis), for generalisation tests.
pub fn tapered_beam(params: &BeamParams, tip_scale: f64) -> Result<TetMesh> {
    check_positive("tip scale", tip_scale)?;
    let [lx, ly, lz] = params.size;
    grid_tets(
        params,
        |_, _, _| true,
        |p| {
            let s = 1.0 + (tip_scale - 1.0) * p.x / lx;
            Vector3::new(p.x, ly / 2.0 + (p.y - ly / 2.0) * s, lz / 2.0 + (p.z - lz / 2.0) * s)
        },
    )
}

/// A beam bent by `angle` radians about the Y axis: its centre line becomes a circular
/// arc of the beam's length (the inner radius must stay positive).
pub fn bent_beam(params: &BeamParams, angle: f64) -> Result<TetMesh> {
    let [lx, _, lz] = params.size;
    if !(angle.is_finite() && angle > 0.0) {
        return Err(Error::InvalidParameter(format!(
            "bend angle must be positive and finite, got {angle}"
        )));
    }
    let radius = lx / angle;
    if radius <= lz / 2.0 {
        return Err(Error::InvalidParameter(format!(
            "bend angle {angle} rad makes the inner radius {:.4} m non-positive for a beam {lz} m thick",
            radius - lz / 2.0
        )));
    }
    grid_tets(
        params,
        |_, _, _| true,
        |p| {
            // Arc length x along the centre line z = lz/2, curving towards −Z about the
            // axis through (0, ·, lz/2 − R); z' = z − lz/2 is the offset from the centre line.
            let phi = p.x / radius;
            let r = radius + (p.z - lz / 2.0);
            Vector3::new(r * phi.sin(), p.y, lz / 2.0 - radius + r * phi.cos())
        },
    )
}

/// A T-section beam: the cross-section is a flange (the top third of the cells in Z, full
/// width in Y) over a web (the middle third of the cells in Y).
pub fn t_beam(params: &BeamParams) -> Result<TetMesh> {
    let [_, ny, nz] = params.cells;
    if ny < 3 || nz < 3 {
        return Err(Error::InvalidParameter(format!(
            "a T-beam needs at least 3 cells in Y and Z, got {ny} and {nz}"
        )));
    }
    let flange = nz - nz / 3;
    let (w0, w1) = (ny / 3, ny - ny / 3);
    grid_tets(params, |_, j, k| k >= flange || (j >= w0 && j < w1), |p| p)
}

/// The most vertices a generator builds: 2²⁴ (16.8 M), about 400 MB of positions and
/// several times that in elements. Every scene in weft is at least three orders of
/// magnitude smaller; a request beyond it is a typo (`--n 100000` for `--n 100`), and
/// without the check it would end in an allocation failure (an abort, not an error).
pub const MAX_GENERATED_VERTICES: usize = 1 << 24;

/// Checks that the product of `factors` (a vertex count) is at most
/// [`MAX_GENERATED_VERTICES`], without overflowing.
fn check_vertex_count(what: &str, factors: &[usize]) -> Result<()> {
    let count = factors.iter().try_fold(1usize, |acc, &f| acc.checked_mul(f));
    match count {
        Some(c) if c <= MAX_GENERATED_VERTICES => Ok(()),
        _ => Err(Error::InvalidParameter(format!(
            "{what} would have {} vertices, more than the {MAX_GENERATED_VERTICES} a generator builds",
            factors.iter().map(|f| f.to_string()).collect::<Vec<_>>().join(" × ")
        ))),
    }
}

fn check_positive(what: &str, x: f64) -> Result<()> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidParameter(format!(
            "{what} must be positive and finite, got {x}"
        )))
    }
}

fn grid_tets(
    params: &BeamParams,
    keep_cell: impl Fn(usize, usize, usize) -> bool,
    map: impl Fn(Vector3<f64>) -> Vector3<f64>,
) -> Result<TetMesh> {
    let [nx, ny, nz] = params.cells;
    if nx == 0 || ny == 0 || nz == 0 {
        return Err(Error::InvalidParameter(format!(
            "beam needs at least one cell per axis, got {:?}",
            params.cells
        )));
    }
    check_vertex_count(
        &format!("a beam of {nx} × {ny} × {nz} cells"),
        &[nx.saturating_add(1), ny.saturating_add(1), nz.saturating_add(1)],
    )?;
    for (axis, s) in params.size.iter().enumerate() {
        check_positive(["beam length (X)", "beam width (Y)", "beam height (Z)"][axis], *s)?;
    }
    let h = [
        params.size[0] / nx as f64,
        params.size[1] / ny as f64,
        params.size[2] / nz as f64,
    ];
    if !(h[0] * h[1] * h[2]).is_normal() {
        return Err(Error::InvalidParameter(format!(
            "beam cells of {:?} m have no finite, non-zero volume (size {:?} m over {:?} cells)",
            h, params.size, params.cells
        )));
    }
    let vid = |i: usize, j: usize, k: usize| (k * (ny + 1) + j) * (nx + 1) + i;
    let mut positions = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                positions.push(map(Vector3::new(i as f64 * h[0], j as f64 * h[1], k as f64 * h[2])));
            }
        }
    }
    // Kuhn split: one tet per axis permutation, along the path 000 → e_p0 → e_p0 + e_p1 → 111.
    const PERMS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                if !keep_cell(i, j, k) {
                    continue;
                }
                for p in PERMS {
                    let mut c = [i, j, k];
                    let mut t = [vid(i, j, k); 4];
                    for (s, &axis) in p.iter().enumerate() {
                        c[axis] += 1;
                        t[s + 1] = vid(c[0], c[1], c[2]);
                    }
                    // Odd permutations come out negatively oriented in the box; the map
                    // is orientation-preserving, so one swap fixes them.
                    let (a, b, cc, d) = (positions[t[0]], positions[t[1]], positions[t[2]], positions[t[3]]);
                    if crate::geometry::tet_signed_volume(&a, &b, &cc, &d) < 0.0 {
                        t.swap(2, 3);
                    }
                    tets.push(t);
                }
            }
        }
    }
    let (positions, tets) = compact(&positions, &tets);
    TetMesh::new(positions, tets)
}

/// Drops unreferenced vertices, keeping the order of the rest.
fn compact<const N: usize>(
    positions: &[Vector3<f64>],
    elements: &[[usize; N]],
) -> (Vec<Vector3<f64>>, Vec<[usize; N]>) {
    let mut used = vec![false; positions.len()];
    for e in elements {
        for &v in e {
            used[v] = true;
        }
    }
    let mut map = vec![usize::MAX; positions.len()];
    let mut out = Vec::new();
    for (v, &u) in used.iter().enumerate() {
        if u {
            map[v] = out.len();
            out.push(positions[v]);
        }
    }
    (out, elements.iter().map(|e| e.map(|v| map[v])).collect())
}
