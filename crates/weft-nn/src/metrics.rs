//! Tan et al.'s embedding metrics (§VI-B/C), as defined in docs/RESULTS.md ("Metrics"): M_rms
//! (Kavan et al.'s E_RMS), M_STED (Vasa & Skala's spatio-temporal edge difference) and
//! nDCG of kNN label retrieval. M_phys is `weft_sim::ImplicitEuler::m_phys`.
//!
//! Frames are flat `[x0, y0, z0, x1, …]` in metres.

use crate::error::{Error, Result};

fn check_pairs(reference: &[Vec<f64>], predicted: &[Vec<f64>]) -> Result<usize> {
    if reference.is_empty() || reference.len() != predicted.len() {
        return Err(Error::Shape {
            what: "metric frames",
            expected: format!("{} predicted frames (at least one)", reference.len()),
            got: format!("{}", predicted.len()),
        });
    }
    let n = reference[0].len();
    if n == 0 || !n.is_multiple_of(3) || reference.iter().chain(predicted).any(|f| f.len() != n) {
        return Err(Error::Shape {
            what: "metric frame",
            expected: format!("{n} coordinates in every frame (a multiple of 3)"),
            got: "frames of different lengths".into(),
        });
    }
    Ok(n)
}

/// Sum of squared coordinate differences between `a` and `b` restricted to `map`
/// (`a` vertex i ↔ `b` vertex `map[i]`, so a coarse mesh can be compared with its fine
/// counterpart), and the largest vertex distance (m).
pub fn frame_error(a: &[f64], b: &[f64], map: &[usize]) -> (f64, f64) {
    let mut sq = 0.0;
    let mut max = 0.0f64;
    for (i, &j) in map.iter().enumerate() {
        let d2: f64 = (0..3).map(|k| (a[3 * i + k] - b[3 * j + k]).powi(2)).sum();
        sq += d2;
        max = max.max(d2.sqrt());
    }
    (sq, max)
}

/// Accumulates M_rms frame by frame: `1000 · ‖A − Â‖_F / √(3 V F)`, i.e. 1000 × the RMS
/// over every coordinate of every compared vertex of every frame, raw coordinates in
/// metres (so: mm), no alignment; and the largest vertex distance.
#[derive(Debug, Default, Clone, Copy)]
pub struct RmsAccumulator {
    sum_sq: f64,
    count: usize,
    max_m: f64,
}

impl RmsAccumulator {
    /// Adds one frame; returns that frame's own M_rms (mm).
    pub fn add(&mut self, a: &[f64], b: &[f64], map: &[usize]) -> f64 {
        let (sq, max) = frame_error(a, b, map);
        self.sum_sq += sq;
        self.count += 3 * map.len();
        self.max_m = self.max_m.max(max);
        1e3 * (sq / (3 * map.len()).max(1) as f64).sqrt()
    }
    pub fn m_rms_mm(&self) -> f64 {
        1e3 * (self.sum_sq / self.count.max(1) as f64).sqrt()
    }
    pub fn max_error_mm(&self) -> f64 {
        1e3 * self.max_m
    }
}

/// M_rms (mm) of `predicted` against `reference`, frame for frame, every vertex.
pub fn m_rms(reference: &[Vec<f64>], predicted: &[Vec<f64>]) -> Result<f64> {
    let n = check_pairs(reference, predicted)?;
    let map: Vec<usize> = (0..n / 3).collect();
    let mut acc = RmsAccumulator::default();
    for (a, b) in reference.iter().zip(predicted) {
        acc.add(b, a, &map);
    }
    Ok(acc.m_rms_mm())
}

/// Parameters of STED (Vasa & Skala 2011). Their defaults could not be confirmed from
/// the paper; weft's are recorded with every result.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StedParams {
    /// Speed (m/s) converting the frame time into a length in the temporal edges.
    pub speed: f64,
    /// Weight of the temporal part: `STED = √(STED_s² + c² STED_t²)`.
    pub temporal_weight: f64,
    /// Frame time (s).
    pub dt: f64,
}

/// STED and its two parts.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Sted {
    pub spatial: f64,
    pub temporal: f64,
    pub combined: f64,
}

/// M_STED over consecutive `frames` (one window, ≥ 2 frames for the temporal part):
/// - spatial: per frame and vertex, the length-weighted standard deviation of the relative
///   edge-length differences `|l − l̂|/l` over the edges incident to the vertex, averaged
///   over vertices and frames (a uniform stretch costs nothing);
/// - temporal: per vertex and frame pair, `|tl − t̂l| / tl` with temporal edge length
///   `tl = √(‖p_{f+1} − p_f‖² + (s Δt)²)`, averaged.
///
/// Edges of zero reference length are skipped.
pub fn sted(edges: &[[usize; 2]], reference: &[Vec<f64>], predicted: &[Vec<f64>], params: StedParams) -> Result<Sted> {
    let n = check_pairs(reference, predicted)?;
    let v = n / 3;
    if let Some(&[a, b]) = edges.iter().find(|&&[a, b]| a >= v || b >= v) {
        return Err(Error::InvalidParameter {
            name: "STED edge",
            value: format!("[{a}, {b}]"),
            reason: "refers to a vertex outside the frames",
        });
    }
    if !(params.speed > 0.0 && params.dt > 0.0 && params.temporal_weight >= 0.0) {
        return Err(Error::InvalidParameter {
            name: "STED parameters",
            value: format!("{params:?}"),
            reason: "needs a positive speed and frame time and a non-negative weight",
        });
    }
    let dist = |f: &[f64], a: usize, b: usize| {
        ((f[3 * a] - f[3 * b]).powi(2) + (f[3 * a + 1] - f[3 * b + 1]).powi(2) + (f[3 * a + 2] - f[3 * b + 2]).powi(2))
            .sqrt()
    };
    let mut incident: Vec<Vec<usize>> = vec![Vec::new(); v];
    for (e, &[a, b]) in edges.iter().enumerate() {
        incident[a].push(e);
        incident[b].push(e);
    }
    let mut spatial = 0.0;
    for (fr, fp) in reference.iter().zip(predicted) {
        let len: Vec<f64> = edges.iter().map(|&[a, b]| dist(fr, a, b)).collect();
        let ed: Vec<f64> = edges
            .iter()
            .zip(&len)
            .map(|(&[a, b], &l)| {
                if l > 0.0 {
                    (l - dist(fp, a, b)).abs() / l
                } else {
                    f64::NAN
                }
            })
            .collect();
        let mut frame_sum = 0.0;
        for inc in &incident {
            let valid: Vec<usize> = inc.iter().copied().filter(|&e| len[e] > 0.0).collect();
            let total: f64 = valid.iter().map(|&e| len[e]).sum();
            if total == 0.0 {
                continue;
            }
            let mean: f64 = valid.iter().map(|&e| len[e] / total * ed[e]).sum();
            let var: f64 = valid.iter().map(|&e| len[e] / total * (ed[e] - mean).powi(2)).sum();
            frame_sum += var.sqrt();
        }
        spatial += frame_sum / v as f64;
    }
    spatial /= reference.len() as f64;
    let mut temporal = 0.0;
    let pairs = reference.len().saturating_sub(1);
    let st = params.speed * params.dt;
    for f in 0..pairs {
        let mut sum = 0.0;
        for i in 0..v {
            let step = |frames: &[Vec<f64>]| {
                let d: f64 = (0..3)
                    .map(|k| (frames[f + 1][3 * i + k] - frames[f][3 * i + k]).powi(2))
                    .sum();
                (d + st * st).sqrt()
            };
            let (tl, tlh) = (step(reference), step(predicted));
            sum += (tl - tlh).abs() / tl;
        }
        temporal += sum / v as f64;
    }
    if pairs > 0 {
        temporal /= pairs as f64;
    }
    Ok(Sted {
        spatial,
        temporal,
        combined: (spatial * spatial + (params.temporal_weight * temporal).powi(2)).sqrt(),
    })
}

/// nDCG of kNN label retrieval (Yang, Peltonen & Kaski, as Tan §VI-C): for each item,
/// rank the others by distance; relevance 1 where the label matches. Returns the mean
/// `DCG_K / IDCG_K` for every K = 1…N−1 (index K−1); items whose label no other item
/// shares are skipped.
pub fn ndcg_curve(points: &[Vec<f64>], labels: &[u8]) -> Result<Vec<f64>> {
    let n = points.len();
    if n < 2 || labels.len() != n {
        return Err(Error::Shape {
            what: "nDCG items",
            expected: "at least two points, one label each".into(),
            got: format!("{n} points, {} labels", labels.len()),
        });
    }
    let discount = |r: usize| 1.0 / ((r + 1) as f64).log2();
    let mut sums = vec![0.0; n - 1];
    let mut counted = 0usize;
    for i in 0..n {
        let same = labels
            .iter()
            .enumerate()
            .filter(|&(j, &l)| j != i && l == labels[i])
            .count();
        if same == 0 {
            continue;
        }
        counted += 1;
        let mut others: Vec<(f64, usize)> = (0..n)
            .filter(|&j| j != i)
            .map(|j| {
                let d: f64 = points[i].iter().zip(&points[j]).map(|(a, b)| (a - b).powi(2)).sum();
                (d, j)
            })
            .collect();
        others.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let (mut dcg, mut idcg) = (0.0, 0.0);
        for (k, &(_, j)) in others.iter().enumerate() {
            let r = k + 1;
            if labels[j] == labels[i] {
                dcg += discount(r);
            }
            if r <= same {
                idcg += discount(r);
            }
            sums[k] += dcg / idcg;
        }
    }
    if counted == 0 {
        return Err(Error::InvalidParameter {
            name: "nDCG labels",
            value: format!("{n} items"),
            reason: "no two items share a label",
        });
    }
    Ok(sums.into_iter().map(|s| s / counted as f64).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> (Vec<[usize; 2]>, Vec<f64>) {
        (
            vec![[0, 1], [1, 2], [0, 2]],
            vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        )
    }

    #[test]
    fn m_rms_is_kavan_per_coordinate_and_max_error_is_per_vertex() {
        // One vertex off by (3, 4, 0) mm, one exact: per-coordinate RMS = sqrt(25/6) mm.
        let a = [0.003, 0.004, 0.0, 1.0, 1.0, 1.0];
        let b = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let mut acc = RmsAccumulator::default();
        let frame = acc.add(&a, &b, &[0, 1]);
        assert!((frame - (25.0f64 / 6.0).sqrt()).abs() < 1e-9);
        assert!((acc.m_rms_mm() - frame).abs() < 1e-12);
        assert!((acc.max_error_mm() - 5.0).abs() < 1e-9);
        // A vertex map compares a coarse vertex with its fine counterpart.
        let fine = [9.0, 9.0, 9.0, 0.0, 0.0, 0.0];
        let (sq, _) = frame_error(&b[..3], &fine, &[1]);
        assert_eq!(sq, 0.0);
    }

    #[test]
    fn m_rms_is_1000_times_the_coordinate_rms() {
        let a = vec![vec![0.0; 6], vec![0.0; 6]];
        let mut b = a.clone();
        b[1][4] = 0.006; // one coordinate of 12 off by 6 mm → RMS √(36e-6/12) m
        let expect = 1000.0 * (36e-6f64 / 12.0).sqrt();
        assert!((m_rms(&a, &b).unwrap() - expect).abs() < 1e-12);
        assert!(m_rms(&a, &b[..1]).is_err());
    }

    #[test]
    fn sted_ignores_uniform_stretch_and_rigid_motion_but_not_shear() {
        let (edges, rest) = tri();
        let p = StedParams {
            speed: 1.0,
            temporal_weight: 1.0,
            dt: 0.1,
        };
        let scaled: Vec<f64> = rest.iter().map(|x| 1.3 * x).collect();
        let s = sted(&edges, std::slice::from_ref(&rest), std::slice::from_ref(&scaled), p).unwrap();
        assert!(s.spatial.abs() < 1e-15, "uniform stretch costs nothing: {s:?}");
        let mut sheared = rest.clone();
        sheared[3] = 1.5; // vertex 1 moved along x: edges 0–1 and 1–2 change differently
        let s = sted(&edges, std::slice::from_ref(&rest), std::slice::from_ref(&sheared), p).unwrap();
        assert!(s.spatial > 0.05, "{s:?}");
        // Temporal: the same motion in both sequences costs nothing; a different one does.
        let moved: Vec<f64> = rest
            .iter()
            .enumerate()
            .map(|(i, x)| if i % 3 == 2 { x + 0.2 } else { *x })
            .collect();
        let a = vec![rest.clone(), moved.clone()];
        assert_eq!(sted(&edges, &a, &a, p).unwrap().temporal, 0.0);
        let still = vec![rest.clone(), rest.clone()];
        let t = sted(&edges, &a, &still, p).unwrap();
        // tl = √(0.2² + 0.1²), t̂l = 0.1 for every vertex.
        let tl = (0.04f64 + 0.01).sqrt();
        assert!((t.temporal - (tl - 0.1) / tl).abs() < 1e-12);
        assert!((t.combined - t.temporal).abs() < 1e-12);
    }

    #[test]
    fn ndcg_is_one_for_perfect_clusters_and_lower_when_mixed() {
        let pts = vec![vec![0.0], vec![0.1], vec![5.0], vec![5.1]];
        let curve = ndcg_curve(&pts, &[0, 0, 1, 1]).unwrap();
        assert!(curve.iter().all(|&v| (v - 1.0).abs() < 1e-12), "{curve:?}");
        let mixed = ndcg_curve(&pts, &[0, 1, 0, 1]).unwrap();
        // Each item's nearest neighbour has the other label: DCG_1 = 0.
        assert_eq!(mixed[0], 0.0);
        assert!(mixed[2] < 1.0);
        assert!(ndcg_curve(&pts, &[0, 1, 2, 3]).is_err());
    }
}
