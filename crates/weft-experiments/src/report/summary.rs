//! The report's first page: each paper's central claim decided from the records, and one
//! speed-against-accuracy figure per family of scenes, one panel per scene and error kind
//! (a simulation's error never on the axis of a reconstruction's).
//!
//! Everything here is computed from `results.json`'s records alone, so the summary of a
//! report is rebuilt whenever any experiment is republished.

use crate::records::{ExperimentOutput, Figure, MIN_SEEDS, Record, figure, find, lower_beyond_spread, seed_count};

/// Whether the records reproduce a claim.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Reproduced,
    NotReproduced,
    /// Measured with fewer than [`MIN_SEEDS`] seeds: the figures say which way it leans
    /// (`true`: towards reproduced), the claim is not decided.
    Undecided {
        seeds: usize,
        leans_reproduced: bool,
    },
    /// The experiment that decides it is not in the report.
    NotMeasured,
}

impl Verdict {
    pub fn as_str(self) -> String {
        match self {
            Self::Reproduced => "reproduced".into(),
            Self::NotReproduced => "not reproduced".into(),
            Self::Undecided {
                seeds,
                leans_reproduced,
            } => format!(
                "not decided: {seeds} seed{} (needs {MIN_SEEDS}); leans {}",
                if seeds == 1 { "" } else { "s" },
                if leans_reproduced {
                    "reproduced"
                } else {
                    "not reproduced"
                }
            ),
            Self::NotMeasured => "not measured".into(),
        }
    }

    /// The verdict on figures from `seeds` seeds.
    fn with_seeds(self, seeds: usize) -> Self {
        match self {
            Self::Reproduced | Self::NotReproduced if seeds < MIN_SEEDS => Self::Undecided {
                seeds,
                leans_reproduced: self == Self::Reproduced,
            },
            other => other,
        }
    }
}

/// One paper's central claim with the paper's figure, ours, and the verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct Claim {
    pub paper: &'static str,
    pub experiment: &'static str,
    pub claim: &'static str,
    pub paper_figure: String,
    pub ours: String,
    pub verdict: Verdict,
}

impl Claim {
    /// The command whose output decides the claim.
    pub fn command(&self) -> String {
        format!("cargo xtask evaluate --size standard --only {}", self.experiment)
    }
}

/// The split every claim is decided on.
const TEST: Option<&str> = Some("test");

/// Keeps the records of `experiment` on `scene` and `split`.
fn on<'a>(experiment: &'a str, scene: &'a str, split: Option<&'a str>) -> impl Fn(&Record) -> bool + Copy + 'a {
    move |r| r.experiment == experiment && r.scene == scene && r.split.as_deref() == split
}

/// Tan et al.: the physics-based loss makes the embedding physically more plausible —
/// `ours` below the baseline without it (`no-pb`) in M_phys at no cost in accuracy. A
/// design scene (the resolution study's coarser sheets aside) counts when `ours`'s M_phys
/// is below `no-pb`'s by more than the two seed spreads (`-sd` records) together and its
/// M_rms is within 2 % of `no-pb`'s; reproduced when at least three quarters of the scenes
/// count (6 of Tan et al.'s 8; the paper: lower on 9 of its 10 pairs).
fn embed_claim(records: &[Record]) -> Claim {
    const RMS_TOLERANCE: f64 = 0.02;
    // The paper's figures sit on the mean records; every figure of ours is recomputed from
    // the per-seed records (`figure`).
    let paper_of = |scene: &str, method: &str, metric: &str| {
        find(records, on("embed", scene, TEST), method, metric).and_then(|r| r.paper_value)
    };
    let figure = |scene: &str, method: &str, metric: &str| figure(records, on("embed", scene, TEST), method, metric);
    let mut ours = (0, 0);
    // The paper's own test: the means alone, one run each, no spread and no M_rms filter.
    let mut means_lower = 0;
    let mut paper = (0, 0);
    // Scenes where the paper's own M_phys gain, applied to `no-pb`'s mean here, would clear
    // the two spreads: whether this run could resolve an effect of the paper's size at all.
    let mut resolvable = (0, 0);
    let mut accurate = (0, 0);
    let mut pca_better = (0, 0);
    let mut scenes: Vec<&str> = records
        .iter()
        .filter(|r| r.experiment == "embed" && r.method == "ours" && r.metric == "m-phys" && r.is_test())
        .map(|r| r.scene.as_str())
        .filter(|s| !COARSE_SHEETS.contains(s))
        .collect();
    scenes.sort_unstable();
    scenes.dedup();
    for scene in scenes {
        let (Some(phys), Some(base)) = (figure(scene, "ours", "m-phys"), figure(scene, "no-pb", "m-phys")) else {
            continue;
        };
        let rms = (figure(scene, "ours", "m-rms"), figure(scene, "no-pb", "m-rms"));
        let within = matches!(rms, (Some(a), Some(b)) if a.0 <= (1.0 + RMS_TOLERANCE) * b.0);
        ours.1 += 1;
        if phys.0 < base.0 {
            means_lower += 1;
        }
        if within && lower_beyond_spread(phys, base) {
            ours.0 += 1;
        }
        if let (Some(p), Some(q)) = (paper_of(scene, "ours", "m-phys"), paper_of(scene, "no-pb", "m-phys")) {
            paper.1 += 1;
            if p < q {
                paper.0 += 1;
            }
            if q > 0.0 {
                resolvable.1 += 1;
                if lower_beyond_spread((base.0 * p / q, phys.1), base) {
                    resolvable.0 += 1;
                }
            }
        }
        if let (Some(a), Some(p)) = (rms.0, paper_of(scene, "ours", "m-rms")) {
            accurate.1 += 1;
            if a.0 <= p {
                accurate.0 += 1;
            }
        }
        // PCA is one deterministic run: the margin is `ours`'s spread alone.
        if let (Some(a), Some(p)) = (figure(scene, "ours", "m-rms"), figure(scene, "pca", "m-rms")) {
            pca_better.1 += 1;
            if lower_beyond_spread(p, a) {
                pca_better.0 += 1;
            }
        }
    }
    let verdict = if ours.1 == 0 {
        Verdict::NotMeasured
    } else if 4 * ours.0 >= 3 * ours.1 {
        Verdict::Reproduced
    } else {
        Verdict::NotReproduced
    };
    Claim {
        paper: "Tan et al. 2018, mesh embedding with a physics-based loss",
        experiment: "embed",
        claim: "The physics-based loss lowers M_phys (physical implausibility) below the baseline trained without it, \
                beyond the seeds' spread and with M_rms within 2 %, on at least three quarters of the scenes",
        paper_figure: format!(
            "lower on {} of {} scenes (Table I: test frames, one model per scene, no spread)",
            paper.0, paper.1
        ),
        ours: format!(
            "lower on {} of {} scenes (on the means alone, as the paper compares: no spread, no M_rms filter, \
             on {}); the paper's own M_phys gain would clear these spreads on {} of {}; `ours` M_rms at or below the paper's on {} of \
             {}; a PCA of the same latent size reconstructs with a lower M_rms than `ours` on {} of {}",
            ours.0, ours.1, means_lower, resolvable.0, resolvable.1, accurate.0, accurate.1, pca_better.0, pca_better.1
        ),
        verdict,
    }
}

/// The resolution study's coarser sheets (Tan et al. Table III), not design scenes.
const COARSE_SHEETS: [&str; 2] = ["sheet-ms-33", "sheet-ms-17"];

/// The largest roll-out window recorded for the test split of `altconv`.
fn longest_rollout(records: &[Record]) -> Option<(usize, String)> {
    records
        .iter()
        .filter(|r| r.experiment == "altconv" && r.is_test())
        .filter_map(|r| {
            Some((
                r.metric.strip_prefix("error-mm-rollout")?.parse::<usize>().ok()?,
                r.metric.clone(),
            ))
        })
        .max()
}

/// Alt-ConvLSTM: on unseen motions, its roll-out error is at most half the best vanilla
/// graph ConvLSTM's and below skinning — the paper's Table 2 (unseen motions, roll-out, 50
/// steps): 8.14 mm against 18.18 mm (ConvLSTM-NP-Y, its best vanilla there) and 19.86 mm
/// (SMPL skinning). Decided on `limb-jiggle`, the data with secondary motion, where it was
/// run (else on `limb`), at the longest roll-out recorded, and only where the margins
/// exceed the seeds' spread; every figure recomputed from the per-seed records.
fn altconv_claim(records: &[Record]) -> Claim {
    let scene = if records
        .iter()
        .any(|r| r.experiment == "altconv" && r.scene == "limb-jiggle")
    {
        "limb-jiggle"
    } else {
        "limb"
    };
    let on = on("altconv", scene, TEST);
    let mut claim = Claim {
        paper: "Alt-ConvLSTM (seed 001), soft-tissue dynamics",
        experiment: "altconv",
        claim: "On unseen motions, Alt-ConvLSTM's roll-out error is at most half the best vanilla graph ConvLSTM's and \
                below skinning",
        paper_figure: "8.14 mm against 18.18 mm (best vanilla, ConvLSTM-NP-Y) and 19.86 mm (SMPL skinning): Table 2, \
                       unseen motions, roll-out over 50 steps, one run"
            .into(),
        ours: "—".into(),
        verdict: Verdict::NotMeasured,
    };
    let scene_records: Vec<Record> = records.iter().filter(|r| r.scene == scene).cloned().collect();
    let Some((steps, metric)) = longest_rollout(&scene_records) else {
        return claim;
    };
    let figure = |method: &str| figure(records, on, method, &metric);
    let (Some(alt), Some(skin)) = (figure("alt-convlstm"), figure("skinning")) else {
        return claim;
    };
    let mut vanillas: Vec<&str> = scene_records
        .iter()
        .filter(|r| r.experiment == "altconv" && r.method.starts_with("convlstm-") && r.metric == metric && r.is_test())
        .map(|r| r.method.as_str())
        .collect();
    vanillas.sort_unstable();
    vanillas.dedup();
    let Some((vanilla, v)) = vanillas
        .into_iter()
        .filter_map(|m| Some((m, figure(m)?)))
        .min_by(|a, b| a.1.0.total_cmp(&b.1.0))
    else {
        return claim;
    };
    let seeds = match seed_count(records, on, "alt-convlstm", &metric) {
        0 => String::new(),
        n => format!(", {n} seeds"),
    };
    claim.ours = format!(
        "`{scene}`: {:.2} ± {:.2} mm against {:.2} ± {:.2} mm (best vanilla, `{vanilla}`) and {:.2} mm (skinning), \
         test split (unseen motions), roll-out over {steps} steps{seeds}",
        alt.0, alt.1, v.0, v.1, skin.0
    );
    claim.verdict = if alt.0 + alt.1 <= 0.5 * (v.0 - v.1) && alt.0 + alt.1 < skin.0 {
        Verdict::Reproduced
    } else {
        Verdict::NotReproduced
    };
    claim
}

/// NNWarp: on unseen shapes the learned correction is far more accurate than modal warping
/// and rotation-strain warping on the same linear solve — decided as the issue states it:
/// for some material, at least two unseen shapes where NNWarp's error (mean over seeds plus
/// its spread) is at most 0.3× both warps'.
fn nnwarp_claim(records: &[Record]) -> Claim {
    const RATIO: f64 = 0.3;
    let value = |scene: &str, method: &str| {
        figure(
            records,
            |r| r.experiment == "nnwarp" && r.scene == scene,
            method,
            "rel-error",
        )
    };
    let mut claim = Claim {
        paper: "NNWarp (Luo et al. 2018), node-wise warping of linear FEM",
        experiment: "nnwarp",
        claim: "On unseen shapes the learned correction's error is at most 0.3× modal warping's and rotation-strain \
                warping's on the same linear solve (at least two shapes, one material)",
        paper_figure: "no figure printed: Fig. 13 (a Neo-Hookean statue, network trained on the beam) shows NNWarp \
                       \"hardly distinguishable from the ground truth\", modal and rotation-strain warping \"quite \
                       different\" (§6); the 0.3× bound is ours"
            .into(),
        ours: "—".into(),
        verdict: Verdict::NotMeasured,
    };
    let mut scenes: Vec<&str> = records
        .iter()
        .filter(|r| r.experiment == "nnwarp" && r.metric == "rel-error" && r.split.as_deref() == Some("unseen-shape"))
        .map(|r| r.scene.as_str())
        .collect();
    scenes.sort_unstable();
    scenes.dedup();
    // Per material: the unseen shapes that pass, and NNWarp's ratio to the better warp.
    let mut per_material: std::collections::BTreeMap<&str, (usize, usize, Vec<f64>)> = Default::default();
    for scene in scenes {
        let material = scene.rsplit('/').next().unwrap_or(scene);
        let (Some((n, sd)), Some((m, _)), Some((r, _))) = (
            value(scene, "nnwarp"),
            value(scene, "modal-warping"),
            value(scene, "rotation-strain-warping"),
        ) else {
            continue;
        };
        let entry = per_material.entry(material).or_default();
        entry.1 += 1;
        if n + sd <= RATIO * m.min(r) {
            entry.0 += 1;
        }
        entry.2.push(n / m.min(r));
    }
    if per_material.is_empty() {
        return claim;
    }
    let seeds = match seed_count(
        records,
        |r| r.experiment == "nnwarp" && r.split.as_deref() == Some("unseen-shape"),
        "nnwarp",
        "rel-error",
    ) {
        0 => String::new(),
        n => format!(" ({n} seed records; NNWarp's figure is their mean plus spread)"),
    };
    claim.ours = per_material
        .iter()
        .map(|(material, (pass, total, ratios))| {
            let mean = ratios.iter().sum::<f64>() / ratios.len().max(1) as f64;
            format!("{material}: {pass} of {total} unseen shapes ≤ 0.3× (NNWarp / better warp {mean:.2} on average)")
        })
        .collect::<Vec<_>>()
        .join("; ")
        + &seeds;
    claim.verdict = if per_material.values().any(|(pass, _, _)| *pass >= 2) {
        Verdict::Reproduced
    } else {
        Verdict::NotReproduced
    };
    claim
}

/// The drape experiment's equal-budget control: `network-only` fine-tuned like every
/// `trained-*` model (the same epochs at the same rate, a fresh Adam, from its best
/// weights) with no layer (issue 72).
pub const DRAPE_CONTROL: &str = "network-only-continued";

/// Geng et al. Table 3's own row [31], the network the quasistatic layers' gains are
/// measured against: (train, validation, test) × (SqrtMSE, MaxDist) in mm. Table 1 prints
/// the same network as 7.684 mm on test (the drape tables' `network-only` paper row).
pub const GENG_TABLE3_NETWORK: [f64; 6] = [2.5364, 10.896, 7.5385, 29.322, 7.5131, 29.308];

/// Each layer trained through (`trained-*`), with the postprocess it is compared with
/// (the same layer after `network-only`; a learned μ's at its start, 0.1).
pub(crate) const LAYER_PAIRS: [(&str, &str, &str); 6] = [
    ("SOCP", "trained-socp", "postprocess-socp"),
    ("μ = 1", "trained-qs-mu1", "postprocess-qs-mu1"),
    ("μ = 0.1", "trained-qs-mu0.1", "postprocess-qs-mu0.1"),
    ("μ = 0.01", "trained-qs-mu0.01", "postprocess-qs-mu0.01"),
    (
        "learned global μ (from 0.1)",
        "trained-qs-learned-mu",
        "postprocess-qs-mu0.1",
    ),
    (
        "learned per-vertex μ (from 0.1)",
        "trained-qs-per-vertex-mu",
        "postprocess-qs-mu0.1",
    ),
];

/// `a` against `b` in per cent, signed (`−4.5 %`).
pub(crate) fn percent_change(a: f64, b: f64) -> String {
    format!("{:+.1} %", 100.0 * (a / b - 1.0)).replace('-', "−")
}

/// The split a claim chooses among methods on: the test split only scores the choice
/// (issue 72).
const VALIDATION: Option<&str> = Some("validation");

/// The drape scene that decides the claim: the loose sleeve where it was run (issue 33),
/// else the sleeve; and the other one.
fn drape_scenes(records: &[Record]) -> (&'static str, &'static str) {
    if records
        .iter()
        .any(|r| r.experiment == "drape" && r.scene == "loose-sleeve")
    {
        ("loose-sleeve", "sleeve")
    } else {
        ("sleeve", "loose-sleeve")
    }
}

/// The `trained-*` method of the drape `scene` with the lowest validation SqrtMSE (the
/// mean over seeds): the method the claim is decided with, chosen without the test split.
fn drape_best_on_validation(records: &[Record], scene: &str) -> Option<String> {
    let mut methods: Vec<&str> = records
        .iter()
        .filter(|r| on("drape", scene, VALIDATION)(r) && r.method.starts_with("trained-") && r.metric == "sqrtmse-mm")
        .map(|r| r.method.as_str())
        .collect();
    methods.sort_unstable();
    methods.dedup();
    methods
        .into_iter()
        .filter_map(|m| Some((m, figure(records, on("drape", scene, VALIDATION), m, "sqrtmse-mm")?.0)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(m, _)| m.to_string())
}

/// Each layer trained through against applied afterwards, on test SqrtMSE, as `value`
/// reads a method's test figure (ours: the mean over its seeds; the paper's: the mean
/// record's `paper_value`); pairs without both figures are left out.
fn drape_layer_changes(test: impl Fn(&str) -> Option<f64>) -> String {
    LAYER_PAIRS
        .iter()
        .filter_map(|(layer, trained, post)| {
            let (t, p) = (test(trained)?, test(post)?);
            let layer = layer.split(" (").next().unwrap_or(layer);
            Some(format!("{layer} {}", percent_change(t, p)))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Geng et al.'s figures for the drape claim, from the records' `paper_value`s: Table 3's
/// trained layers against Table 3's own network (Table 1 prints it 2 % higher), Table 1's
/// SOCP against Table 1's, trained against afterwards per layer, and §6.2's learned μ.
fn drape_paper_figure(records: &[Record], scene: &str) -> String {
    let paper =
        |method: &str| find(records, on("drape", scene, TEST), method, "sqrtmse-mm").and_then(|r| r.paper_value);
    let table3_network = GENG_TABLE3_NETWORK[4];
    let pct = percent_change;
    let (Some(mu01), Some(per_vertex), Some(socp), Some(network)) = (
        paper("trained-qs-mu0.1"),
        paper("trained-qs-per-vertex-mu"),
        paper("trained-socp"),
        paper("network-only"),
    ) else {
        return "—".into();
    };
    format!(
        "Table 3: {mu01} mm (μ = 0.1) and {per_vertex} mm (per-vertex μ_i) against its own network's \
         {table3_network} mm ({}, {}); Table 1: SOCP {socp} against {network} mm ({}); trained against \
         applied afterwards: {}; learned μ 0.090–0.100 from 1, 0.1, 0.01 (§6.2); one run each, no equal-budget control",
        pct(mu01, table3_network),
        pct(per_vertex, table3_network),
        pct(socp, network),
        drape_layer_changes(|m| find(records, on("drape", scene, TEST), m, "sqrtmse-mm")?.paper_value),
    )
}

/// The learned global μ of a drape scene from starts 1, 0.1 and 0.01, in that order.
struct LearnedMu {
    values: Vec<f64>,
    /// Geng et al. §6.2's μ from the same starts.
    paper: Vec<f64>,
    /// Each start's relative change of μ per epoch over the μ study's last epochs.
    changes: Vec<f64>,
}

impl LearnedMu {
    fn of(records: &[Record], scene: &str) -> Self {
        let mut mu = Self {
            values: Vec::new(),
            paper: Vec::new(),
            changes: Vec::new(),
        };
        for start in ["1", "0.1", "0.01"] {
            let method = format!("learned-mu-from-{start}");
            if let Some(r) = find(records, on("drape", scene, None), &method, "learned-mu") {
                mu.values.push(r.value);
                mu.paper.extend(r.paper_value);
            }
            if let Some(r) = find(
                records,
                on("drape", scene, None),
                &method,
                "learned-mu-change-per-epoch",
            ) {
                mu.changes.push(r.value);
            }
        }
        mu
    }

    /// Largest over smallest of the three starts' μ.
    fn ratio(&self) -> f64 {
        let (lo, hi) = self
            .values
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &m| (a.min(m), b.max(m)));
        hi / lo
    }

    fn agrees(&self) -> bool {
        self.values.len() == 3 && self.ratio().is_finite() && self.ratio() <= 1.5
    }

    /// The values, their spread, how far from the paper's and how far from settled.
    fn describe(&self, scene: &str) -> String {
        if self.values.is_empty() {
            return format!("{scene}: learned μ not measured (no `learned-mu-from-*` rows)");
        }
        let sig = |m: &f64| crate::records::three_significant(*m);
        let mut s = format!(
            "{scene}: learned μ {} (largest / smallest {:.2})",
            self.values.iter().map(sig).collect::<Vec<_>>().join(", "),
            self.ratio()
        );
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        if !self.paper.is_empty() {
            let times = mean(&self.paper) / mean(&self.values);
            s += &if times >= 1.0 {
                format!(", {times:.1}× below the paper's")
            } else {
                format!(", {:.1}× above the paper's", 1.0 / times)
            };
        }
        if !self.changes.is_empty() {
            let (lo, hi) = self
                .changes
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &c| (a.min(c), b.max(c)));
            let pct = |c: f64| format!("{:+.1}", 100.0 * c).replace('-', "−");
            s += &format!(
                ", still changing {} to {} % per epoch at the study's end",
                pct(lo),
                pct(hi)
            );
        }
        s
    }
}

/// Geng et al.: training through a projection layer beats the network alone on unseen
/// poses and cuts the stretching-energy error, and the learned global μ lands in the same
/// place from any start. Decided on the loose sleeve where it was run (issue 33), else on
/// the sleeve, against the equal-budget control `network-only-continued` (`network-only`
/// trained the `trained-*` models' extra epochs without a layer; issue 72): the `trained-*`
/// method of the lowest validation SqrtMSE must have a test SqrtMSE at least 5 % below the
/// control's beyond both seed spreads (`mean + sd ≤ 0.95 (mean_c − sd_c)`) and a
/// stretching error at most a fifth of the control's, and the learned μ from starts 1, 0.1
/// and 0.01 must lie within a factor 1.5 of each other. Records without the control (a
/// report from before issue 72) decide nothing: the row shows the figures against
/// `network-only` and says so.
fn drape_claim(records: &[Record]) -> Claim {
    const CONTROL: &str = DRAPE_CONTROL;
    let (scene, other) = drape_scenes(records);
    // Every figure of ours is the mean and spread over the per-seed records.
    let fig = |method: &str, metric: &str| figure(records, on("drape", scene, TEST), method, metric);
    let with_sd = |(mean, sd): Figure| {
        if sd > 0.0 {
            format!("{mean:.3} ± {sd:.3}")
        } else {
            format!("{mean:.3}")
        }
    };
    let mut claim = Claim {
        paper: "Geng, Johnson & Fedkiw 2020, projection layers in training",
        experiment: "drape",
        claim: "Training through a projection layer beats the network trained as long without one on test SqrtMSE (by \
                5 % beyond the seeds' spread) and cuts the stretching-energy error 5×; the learned global μ from \
                three starts agrees within 1.5×",
        paper_figure: drape_paper_figure(records, scene),
        ours: "—".into(),
        verdict: Verdict::NotMeasured,
    };
    // Without the control (a report from before issue 72) the figures are still shown
    // against the network alone, and nothing is decided.
    let control_run = fig(CONTROL, "sqrtmse-mm").is_some();
    let baseline = if control_run { CONTROL } else { "network-only" };
    let (Some(base), Some(base_s)) = (fig(baseline, "sqrtmse-mm"), fig(baseline, "stretching-energy-error")) else {
        return claim;
    };
    let Some(best_method) = drape_best_on_validation(records, scene) else {
        return claim;
    };
    let (Some(best), Some(best_s)) = (
        fig(&best_method, "sqrtmse-mm"),
        fig(&best_method, "stretching-energy-error"),
    ) else {
        return claim;
    };
    let cut = base_s.0 / best_s.0.max(f64::MIN_POSITIVE);
    let beats = best.0 + best.1 <= 0.95 * (base.0 - base.1);
    let mu = LearnedMu::of(records, scene);
    // The largest stretching cut of any layer applied after the untrained network: the
    // metric is the quasistatic layer's own edge-spring energy, which any such layer
    // lowers by construction.
    let untrained = fig("network-only", "stretching-energy-error").and_then(|n| {
        LAYER_PAIRS
            .iter()
            .filter_map(|(_, _, post)| Some((*post, n.0 / fig(post, "stretching-energy-error")?.0)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    });
    let other_mu = LearnedMu::of(records, other);
    let against = if control_run {
        format!(
            "the equal-budget `{CONTROL}` ({}; `network-only` {})",
            percent_change(best.0, base.0),
            fig("network-only", "sqrtmse-mm").map_or("—".into(), |f| format!("{} mm", with_sd(f))),
        )
    } else {
        format!(
            "`network-only` ({}; no `{CONTROL}` records, so no equal-budget control to decide against: the gain \
             includes the trained model's extra epochs)",
            percent_change(best.0, base.0)
        )
    };
    claim.ours = format!(
        "{scene}: `{}` (the trained model of the lowest validation SqrtMSE) {} mm on test against {} mm for \
         {against}; stretching error cut {}× against it¹; trained against applied afterwards: {}; {}²{}. ¹ The \
         energy is the quasistatic layer's own edge-spring energy{}. ² The paper gives no spring stiffnesses: μ's \
         absolute value is not comparable with the paper's. {}Ours: mean ± sd over the seeds",
        best_method,
        with_sd(best),
        with_sd(base),
        crate::records::three_significant(cut),
        drape_layer_changes(|m| Some(fig(m, "sqrtmse-mm")?.0)),
        mu.describe(scene),
        if other_mu.values.is_empty() {
            String::new()
        } else {
            format!("; {}", other_mu.describe(other))
        },
        untrained.map_or(String::new(), |(post, c)| format!(
            ", which a layer applied to the untrained network already cuts (`{post}`: {c:.0}×)"
        )),
        if control_run {
            "The control and every trained model get the same extra epochs from `network-only`. "
        } else {
            ""
        },
    );
    claim.verdict = if !control_run {
        Verdict::NotMeasured
    } else if beats && cut >= 5.0 && mu.agrees() {
        Verdict::Reproduced
    } else {
        Verdict::NotReproduced
    };
    claim
}

/// The four papers' central claims, decided from the experiments' records — and only
/// where the deciding experiment trained its models with at least [`MIN_SEEDS`] seeds.
pub fn claims(outputs: &[ExperimentOutput]) -> Vec<Claim> {
    let records: Vec<Record> = outputs.iter().flat_map(|o| o.records.iter().cloned()).collect();
    [
        embed_claim(&records),
        altconv_claim(&records),
        nnwarp_claim(&records),
        drape_claim(&records),
    ]
    .into_iter()
    .map(|mut c| {
        let seeds = outputs
            .iter()
            .find(|o| o.experiment == c.experiment)
            .map_or(0, |o| o.seeds);
        c.verdict = c.verdict.with_seeds(seeds);
        c
    })
    .collect()
}

/// What a family panel's error measures. Errors of different kinds are never drawn on one
/// axis: a reconstruction of a given true frame (the embedding, PCA) is not a simulation
/// that has to find the frame, and would look better than any solver beside it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// A simulated sequence against a tight reference simulation: M_rms over its frames.
    Simulation,
    /// Encoding and decoding given true test frames (Tan et al.'s M_rms): no time stepping.
    Reconstruction,
    /// A static solve at each load against full nonlinear FEM (NNWarp's rel-error).
    StaticSolve,
    /// An autoregressive roll-out from the true first frames on unseen motions.
    RollOut,
    /// One drape predicted per test pose, no time stepping (Geng et al.'s SqrtMSE).
    PosePrediction,
    /// A projection's result against the same projection solved tightly.
    Projection,
    /// A surrogate's roll-out under the guard against today's solver at its own tolerance.
    Guarded,
}

impl ErrorKind {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Simulation => "simulation",
            Self::Reconstruction => "reconstruction",
            Self::StaticSolve => "static solve",
            Self::RollOut => "roll-out",
            Self::PosePrediction => "pose to drape",
            Self::Projection => "projection",
            Self::Guarded => "guarded roll-out",
        }
    }

    /// One sentence for the plot's header: what a point's error is.
    pub fn meaning(self) -> &'static str {
        match self {
            Self::Simulation => "M_rms over the frames of a simulated sequence against a tight reference simulation",
            Self::Reconstruction => {
                "M_rms of encoding and decoding given true test frames (no time stepping: not comparable with a \
                 simulation's error)"
            }
            Self::StaticSolve => "rel-error of the static solve at each load against full nonlinear FEM",
            Self::RollOut => "error of an autoregressive roll-out on unseen test motions",
            Self::PosePrediction => "SqrtMSE of the drape predicted for each test pose",
            Self::Projection => "SqrtMSE against the same projection solved to a tight tolerance",
            Self::Guarded => {
                "M_rms over the frames of a surrogate's roll-out under the guard (a tolerance τ, or unguarded) \
                 against today's solver at its own tolerance (docs/GUARD.md)"
            }
        }
    }
}

/// One experiment's share of a family: the scenes it contributes (by prefix; empty: all),
/// the metric and split read, and what that error measures.
#[derive(Debug, Clone, Copy)]
pub struct Member {
    pub experiment: &'static str,
    pub scene_prefixes: &'static [&'static str],
    /// `error-mm-rollout` stands for the longest roll-out window recorded.
    pub metric: &'static str,
    pub split: Option<&'static str>,
    pub kind: ErrorKind,
    /// The axis label, without the kind (which each panel's title names).
    pub error_label: &'static str,
}

/// A family of scenes drawn as one figure: one speed-against-accuracy panel per scene and
/// error kind.
#[derive(Debug, Clone, Copy)]
pub struct Family {
    pub name: &'static str,
    pub title: &'static str,
    pub members: &'static [Member],
}

/// The five families: cloth (ground-truth variants and the embedding), volumetric (the
/// warps against full FEM), soft tissue, garments and projection.
pub const FAMILIES: [Family; 5] = [
    Family {
        name: "cloth",
        title: "Cloth: solver variants (simulation), the learned embedding (reconstruction) and guarded surrogates",
        members: &[
            Member {
                experiment: "sim",
                scene_prefixes: &["sheet", "ball"],
                metric: "m-rms",
                split: None,
                kind: ErrorKind::Simulation,
                error_label: "M_rms over the sequence (mm)",
            },
            Member {
                experiment: "embed",
                scene_prefixes: &[],
                metric: "m-rms",
                split: Some("test"),
                kind: ErrorKind::Reconstruction,
                error_label: "M_rms of the test frames (mm)",
            },
            Member {
                experiment: "guarded",
                scene_prefixes: &["sheet"],
                metric: "m-rms",
                split: None,
                kind: ErrorKind::Guarded,
                error_label: "M_rms against today's solver (mm)",
            },
        ],
    },
    Family {
        name: "volumetric",
        title: "Volumetric: warped linear FEM and NNWarp against full FEM, and guarded surrogates",
        members: &[
            Member {
                experiment: "nnwarp",
                scene_prefixes: &[],
                metric: "rel-error",
                split: None,
                kind: ErrorKind::StaticSolve,
                error_label: "rel-error",
            },
            Member {
                experiment: "guarded",
                scene_prefixes: &["beam"],
                metric: "m-rms",
                split: None,
                kind: ErrorKind::Guarded,
                error_label: "M_rms over all nodes against the quasistatic equilibria (mm)",
            },
        ],
    },
    Family {
        name: "soft-tissue",
        title: "Soft tissue: skinning and the learned dynamics on unseen motions, and guarded surrogates",
        members: &[
            Member {
                experiment: "altconv",
                scene_prefixes: &[],
                metric: "error-mm-rollout",
                split: Some("test"),
                kind: ErrorKind::RollOut,
                error_label: "roll-out error (mm)",
            },
            Member {
                experiment: "guarded",
                scene_prefixes: &["limb"],
                metric: "m-rms",
                split: None,
                kind: ErrorKind::Guarded,
                error_label: "M_rms over all nodes against today's solver (mm)",
            },
        ],
    },
    Family {
        name: "garments",
        title: "Garments: pose to cloth, with and without projection layers",
        members: &[Member {
            experiment: "drape",
            scene_prefixes: &[],
            metric: "sqrtmse-mm",
            split: Some("test"),
            kind: ErrorKind::PosePrediction,
            error_label: "SqrtMSE on the test poses (mm)",
        }],
    },
    Family {
        name: "projection",
        title: "Projection layers against their tight references",
        members: &[Member {
            experiment: "proj",
            scene_prefixes: &[],
            metric: "sqrt-mse",
            split: None,
            kind: ErrorKind::Projection,
            error_label: "SqrtMSE (mm)",
        }],
    },
];

/// One method's point on a family panel: one record's error and time ratio, not averaged
/// with any other scene's.
#[derive(Debug, Clone, PartialEq)]
pub struct FamilyPoint {
    pub method: String,
    pub time_ratio: f64,
    pub error: f64,
}

/// One panel of a family figure: the points of one scene and one error kind.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    pub experiment: &'static str,
    pub scene: String,
    pub split: Option<&'static str>,
    pub kind: ErrorKind,
    /// The y axis: what the error is, with its unit.
    pub error_label: String,
    pub points: Vec<FamilyPoint>,
}

impl Panel {
    /// The panel's caption: its scene, and its error kind.
    pub fn title(&self) -> String {
        format!("{} · {}", self.scene, self.kind.as_str())
    }
}

impl Family {
    /// The family's panels, member by member and scene by scene in first-seen order: one per
    /// (member, scene) with a timed record in the member's metric, one point per method.
    pub fn panels(&self, records: &[Record]) -> Vec<Panel> {
        let mut panels: Vec<Panel> = Vec::new();
        for m in self.members {
            // Soft tissue reads its longest roll-out window (50 steps at standard size).
            let (metric, error_label) = if m.metric == "error-mm-rollout" {
                match longest_rollout(records) {
                    Some((steps, metric)) => (metric, format!("{steps}-step {}", m.error_label)),
                    None => continue,
                }
            } else {
                (m.metric.to_string(), m.error_label.to_string())
            };
            let first = panels.len();
            // One point per method: the figure over its seeds, never one seed's.
            for r in records.iter().filter(|r| {
                r.seed.is_none()
                    && r.experiment == m.experiment
                    && (m.scene_prefixes.is_empty() || m.scene_prefixes.iter().any(|p| r.scene.starts_with(p)))
                    && r.metric == metric
                    && (m.split.is_none() || r.split.as_deref() == m.split)
            }) {
                let (Some(t), Some(g)) = (r.seconds_per_frame, r.ground_truth_seconds_per_frame) else {
                    continue;
                };
                if !(t > 0.0 && g > 0.0) {
                    continue;
                }
                let point = FamilyPoint {
                    method: r.method.clone(),
                    time_ratio: t / g,
                    error: r.value,
                };
                match panels[first..].iter_mut().find(|p| p.scene == r.scene) {
                    Some(p) => p.points.push(point),
                    None => panels.push(Panel {
                        experiment: m.experiment,
                        scene: r.scene.clone(),
                        split: m.split,
                        kind: m.kind,
                        error_label: error_label.clone(),
                        points: vec![point],
                    }),
                }
            }
        }
        panels
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(experiment: &str, scene: &str, method: &str, metric: &str, split: Option<&str>, value: f64) -> Record {
        Record {
            experiment: experiment.into(),
            scene: scene.into(),
            method: method.into(),
            metric: metric.into(),
            split: split.map(Into::into),
            value,
            unit: "mm".into(),
            paper_value: None,
            seconds_per_frame: Some(0.01),
            ground_truth_seconds_per_frame: Some(1.0),
            seed: None,
        }
    }

    #[test]
    fn the_nnwarp_claim_needs_two_unseen_shapes_at_a_third_of_both_warps_beyond_the_spread() {
        let cell = |shape: &str, n: f64, sd: f64, mw: f64, rsw: f64| {
            let scene = format!("{shape}/neo-hookean");
            vec![
                rec("nnwarp", &scene, "nnwarp", "rel-error", Some("unseen-shape"), n),
                rec("nnwarp", &scene, "nnwarp", "rel-error-sd", Some("unseen-shape"), sd),
                rec("nnwarp", &scene, "modal-warping", "rel-error", Some("unseen-shape"), mw),
                rec(
                    "nnwarp",
                    &scene,
                    "rotation-strain-warping",
                    "rel-error",
                    Some("unseen-shape"),
                    rsw,
                ),
            ]
        };
        // One shape at a fifth of both warps, one at half: not reproduced.
        let mut r = [
            cell("t-beam", 0.01, 0.001, 0.05, 0.06),
            cell("bent-beam", 0.02, 0.001, 0.04, 0.05),
        ]
        .concat();
        assert_eq!(nnwarp_claim(&r).verdict, Verdict::NotReproduced);
        // A second shape under 0.3× of the better warp: reproduced.
        r.extend(cell("tapered-beam", 0.01, 0.002, 0.04, 0.1));
        assert_eq!(nnwarp_claim(&r).verdict, Verdict::Reproduced);
        // The same mean with a spread that reaches past 0.3×: not reproduced.
        let r = [
            cell("t-beam", 0.01, 0.001, 0.05, 0.06),
            cell("tapered-beam", 0.01, 0.005, 0.04, 0.1),
        ]
        .concat();
        assert_eq!(nnwarp_claim(&r).verdict, Verdict::NotReproduced);
        // The training shape does not count.
        let mut r = cell("t-beam", 0.01, 0.0, 0.05, 0.06);
        for x in &mut r {
            x.split = Some("train-shape".into());
        }
        assert_eq!(nnwarp_claim(&r).verdict, Verdict::NotMeasured);
    }

    /// A drape method's records on `scene`: test SqrtMSE with its spread and stretching
    /// error, and a validation SqrtMSE of `val`.
    fn drape_cell(scene: &str, method: &str, val: f64, v: f64, sd: f64, stretch: f64) -> Vec<Record> {
        vec![
            rec("drape", scene, method, "sqrtmse-mm", Some("validation"), val),
            rec("drape", scene, method, "sqrtmse-mm", Some("test"), v),
            rec("drape", scene, method, "sqrtmse-mm-sd", Some("test"), sd),
            rec("drape", scene, method, "stretching-energy-error", Some("test"), stretch),
        ]
    }

    fn drape_mu(scene: &str, values: [f64; 3]) -> Vec<Record> {
        ["1", "0.1", "0.01"]
            .iter()
            .zip(values)
            .map(|(s, m)| rec("drape", scene, &format!("learned-mu-from-{s}"), "learned-mu", None, m))
            .collect()
    }

    /// The loose sleeve's network alone (10 ± 0.2 mm), its equal-budget control at `control`
    /// ± 0.2 mm, both with a stretching error of 6, the learned μ within 1.2×; and the
    /// sleeve, where the layer loses, which does not count once the loose sleeve ran.
    fn drape_base(control: f64) -> Vec<Record> {
        [
            drape_cell("sleeve", "network-only", 0.2, 0.2, 0.0, 1.0),
            drape_cell("sleeve", "network-only-continued", 0.2, 0.2, 0.0, 1.0),
            drape_cell("sleeve", "trained-qs-mu0.1", 0.3, 0.3, 0.0, 1.0),
            drape_mu("sleeve", [0.1, 0.5, 0.01]),
            drape_cell("loose-sleeve", "network-only", 10.0, 10.0, 0.2, 6.0),
            drape_cell("loose-sleeve", "network-only-continued", control, control, 0.2, 6.0),
            drape_mu("loose-sleeve", [0.1, 0.11, 0.12]),
        ]
        .concat()
    }

    #[test]
    fn the_drape_claim_is_decided_against_the_equal_budget_control_beyond_the_spread_with_agreeing_mu() {
        let with = |trained: Vec<Record>| [drape_base(10.0), trained].concat();
        let trained = |v, sd, stretch| drape_cell("loose-sleeve", "trained-qs-mu0.1", v, v, sd, stretch);
        // 9.0 ± 0.2 against the control's 10 ± 0.2 with a 6× cut and μ within 1.2×.
        let c = drape_claim(&with(trained(9.0, 0.2, 1.0)));
        assert_eq!(c.verdict, Verdict::Reproduced, "{}", c.ours);
        for part in [
            "loose-sleeve: `trained-qs-mu0.1`",
            "against 10.000 ± 0.200 mm for the equal-budget `network-only-continued` (−10.0 %",
            "stretching error cut 6.00× against it",
            "learned μ 0.100, 0.110, 0.120 (largest / smallest 1.20)",
            "sleeve: learned μ 0.100, 0.500, 0.0100 (largest / smallest 50.00)",
        ] {
            assert!(c.ours.contains(part), "{part} not in {}", c.ours);
        }
        // Small μ keep three significant digits.
        let mut r = with(trained(9.0, 0.2, 1.0));
        r.retain(|x| !(x.scene == "loose-sleeve" && x.metric == "learned-mu"));
        r.extend(drape_mu("loose-sleeve", [0.007_414, 0.007_492, 0.007_572]));
        let c = drape_claim(&r);
        assert!(
            c.ours
                .contains("learned μ 0.00741, 0.00749, 0.00757 (largest / smallest 1.02)"),
            "{}",
            c.ours
        );
        assert_eq!(c.verdict, Verdict::Reproduced);
        // The same means with a spread that closes the 5 % margin: not reproduced.
        assert_eq!(
            drape_claim(&with(trained(9.0, 0.5, 1.0))).verdict,
            Verdict::NotReproduced
        );
        // Better but the stretching error cut only 3×: not reproduced.
        assert_eq!(
            drape_claim(&with(trained(9.0, 0.2, 2.0))).verdict,
            Verdict::NotReproduced
        );
        // μ from the three starts 2× apart: not reproduced.
        let mut r = with(trained(9.0, 0.2, 1.0));
        r.retain(|x| !(x.scene == "loose-sleeve" && x.metric == "learned-mu"));
        r.extend(drape_mu("loose-sleeve", [0.1, 0.2, 0.15]));
        assert_eq!(drape_claim(&r).verdict, Verdict::NotReproduced);
        // A postprocess (not trained through the layer) does not count.
        let c = drape_claim(&with(drape_cell(
            "loose-sleeve",
            "postprocess-qs-mu0.1",
            9.0,
            9.0,
            0.2,
            1.0,
        )));
        assert_eq!(c.verdict, Verdict::NotMeasured);
    }

    #[test]
    fn the_drape_claim_needs_the_layer_to_beat_the_extra_epochs_not_only_the_network() {
        // 9.0 ± 0.2 clears the network alone (10 ± 0.2) but not the control trained as
        // long without a layer (9.2 ± 0.2): the gain is the epochs', not the layer's.
        let r = [
            drape_base(9.2),
            drape_cell("loose-sleeve", "trained-qs-mu0.1", 9.0, 9.0, 0.2, 1.0),
        ]
        .concat();
        assert_eq!(drape_claim(&r).verdict, Verdict::NotReproduced);
        // A report without the control (before issue 72) decides nothing.
        let mut r = r;
        r.retain(|x| x.method != "network-only-continued");
        let c = drape_claim(&r);
        assert_eq!(c.verdict, Verdict::NotMeasured);
        assert!(c.ours.contains("no `network-only-continued` records"), "{}", c.ours);
        assert!(
            c.ours.contains("against 10.000 ± 0.200 mm for `network-only` (−10.0 %"),
            "{}",
            c.ours
        );
    }

    #[test]
    fn the_drape_claim_chooses_its_method_on_validation_and_a_poisoned_test_split_does_not_move_it() {
        // `trained-qs-mu0.1` is best on validation and fails on test; `trained-socp` would
        // pass on test but is worse on validation. The claim is decided with the former.
        let records = [
            drape_base(10.0),
            drape_cell("loose-sleeve", "trained-qs-mu0.1", 8.0, 9.9, 0.2, 1.0),
            drape_cell("loose-sleeve", "trained-socp", 9.5, 8.0, 0.2, 1.0),
        ]
        .concat();
        let chosen = "loose-sleeve: `trained-qs-mu0.1`";
        let c = drape_claim(&records);
        assert!(c.ours.starts_with(chosen), "{}", c.ours);
        assert_eq!(c.verdict, Verdict::NotReproduced);
        // Poison every other method's test split (far below anything): the choice and the
        // verdict stay.
        let mut poisoned = records.clone();
        for r in &mut poisoned {
            if r.split.as_deref() == Some("test") && r.method != "trained-qs-mu0.1" && r.metric == "sqrtmse-mm" {
                r.value = 1e-3;
            }
        }
        assert_eq!(
            drape_best_on_validation(&poisoned, "loose-sleeve").as_deref(),
            Some("trained-qs-mu0.1")
        );
        let p = drape_claim(&poisoned);
        assert!(p.ours.starts_with(chosen), "{}", p.ours);
        assert_eq!(p.verdict, c.verdict);
    }

    #[test]
    fn the_drape_row_quotes_tables_1_and_3_against_their_own_networks_and_every_layer_pair() {
        let paper = |mut r: Vec<Record>, p: f64| {
            r[1].paper_value = Some(p);
            r
        };
        let cell = |method: &str, v: f64| drape_cell("loose-sleeve", method, v, v, 0.0, 1.0);
        let mut base = drape_base(4.0);
        base.retain(|x| !(x.scene == "loose-sleeve" && x.method == "network-only"));
        let r = [
            base,
            paper(cell("network-only", 4.0), 7.6840),
            paper(cell("postprocess-socp", 3.9), 7.4326),
            paper(cell("trained-socp", 3.8), 7.1603),
            paper(cell("postprocess-qs-mu1", 3.9), 7.2918),
            paper(cell("trained-qs-mu1", 3.7), 7.2794),
            paper(cell("postprocess-qs-mu0.1", 3.7), 7.1879),
            paper(cell("trained-qs-mu0.1", 3.5), 7.1465),
            paper(cell("postprocess-qs-mu0.01", 3.8), 8.9365),
            paper(cell("trained-qs-mu0.01", 3.4), 7.3596),
            paper(cell("trained-qs-per-vertex-mu", 3.2), 6.9375),
        ]
        .concat();
        let c = drape_claim(&r);
        // Geng et al.'s gains against Table 3's own network (7.5131 mm), not Table 1's.
        for part in [
            "Table 3: 7.1465 mm (μ = 0.1) and 6.9375 mm (per-vertex μ_i) against its own network's 7.5131 mm \
             (−4.9 %, −7.7 %)",
            "Table 1: SOCP 7.1603 against 7.684 mm (−6.8 %)",
            "SOCP −3.7 %, μ = 1 −0.2 %, μ = 0.1 −0.6 %, μ = 0.01 −17.6 %, learned per-vertex μ −3.5 %",
        ] {
            assert!(c.paper_figure.contains(part), "{part} not in {}", c.paper_figure);
        }
        // Ours: every layer trained against applied afterwards (the learned μ against 0.1).
        assert!(
            c.ours
                .contains("SOCP −2.6 %, μ = 1 −5.1 %, μ = 0.1 −5.4 %, μ = 0.01 −10.5 %, learned per-vertex μ −13.5 %"),
            "{}",
            c.ours
        );
    }

    #[test]
    fn the_alt_convlstm_claim_is_decided_on_the_jiggling_limb_beyond_the_seed_spread() {
        let cell = |scene: &str, method: &str, v: f64, sd: f64| {
            vec![
                rec("altconv", scene, method, "error-mm-rollout50", Some("test"), v),
                rec("altconv", scene, method, "error-mm-rollout50-sd", Some("test"), sd),
            ]
        };
        // On `limb` Alt-ConvLSTM wins; on `limb-jiggle` it is not at half the best vanilla
        // model: the claim follows `limb-jiggle`.
        let mut r = [
            cell("limb", "alt-convlstm", 1.0, 0.0),
            cell("limb", "convlstm-np-y", 3.0, 0.0),
            cell("limb", "skinning", 4.0, 0.0),
            cell("limb-jiggle", "alt-convlstm", 5.0, 0.5),
            cell("limb-jiggle", "convlstm-np-y", 9.0, 0.5),
            cell("limb-jiggle", "skinning", 10.0, 0.0),
        ]
        .concat();
        let c = altconv_claim(&r);
        assert_eq!(c.verdict, Verdict::NotReproduced);
        assert!(c.ours.contains("limb-jiggle"), "{}", c.ours);
        // At half the best vanilla model beyond both spreads: reproduced.
        r.retain(|x| !(x.scene == "limb-jiggle" && x.method == "alt-convlstm"));
        r.extend(cell("limb-jiggle", "alt-convlstm", 3.5, 0.5));
        assert_eq!(altconv_claim(&r).verdict, Verdict::Reproduced);
        // The same means with a spread that closes the margin: not reproduced.
        r.retain(|x| !(x.scene == "limb-jiggle" && x.method == "alt-convlstm"));
        r.extend(cell("limb-jiggle", "alt-convlstm", 3.5, 1.5));
        assert_eq!(altconv_claim(&r).verdict, Verdict::NotReproduced);
    }

    #[test]
    fn the_alt_convlstm_claim_follows_the_longest_test_window() {
        let mut r = vec![
            rec(
                "altconv",
                "limb",
                "alt-convlstm",
                "error-mm-rollout10",
                Some("test"),
                1.0,
            ),
            rec(
                "altconv",
                "limb",
                "convlstm-np-y",
                "error-mm-rollout10",
                Some("test"),
                2.0,
            ),
            rec("altconv", "limb", "skinning", "error-mm-rollout10", Some("test"), 3.0),
        ];
        assert_eq!(altconv_claim(&r).verdict, Verdict::Reproduced);
        // At 20 steps Alt-ConvLSTM drifts past the best vanilla model: the claim follows.
        r.extend([
            rec(
                "altconv",
                "limb",
                "alt-convlstm",
                "error-mm-rollout20",
                Some("test"),
                4.0,
            ),
            rec(
                "altconv",
                "limb",
                "convlstm-np-y",
                "error-mm-rollout20",
                Some("test"),
                3.5,
            ),
            rec("altconv", "limb", "skinning", "error-mm-rollout20", Some("test"), 5.0),
            // Known-motion records do not decide a claim about unseen ones.
            rec(
                "altconv",
                "limb",
                "convlstm-cp-y",
                "error-mm-rollout30",
                Some("known"),
                0.1,
            ),
        ]);
        let c = altconv_claim(&r);
        assert_eq!(c.verdict, Verdict::NotReproduced);
        assert!(
            c.ours.contains("20 steps") && c.ours.contains("convlstm-np-y"),
            "{}",
            c.ours
        );
        assert_eq!(altconv_claim(&[]).verdict, Verdict::NotMeasured);
    }

    #[test]
    fn a_claim_on_fewer_than_three_seeds_is_not_decided() {
        let mut out = ExperimentOutput::new("altconv", weft_data::Size::Quick);
        out.records = vec![
            rec(
                "altconv",
                "limb",
                "alt-convlstm",
                "error-mm-rollout10",
                Some("test"),
                1.0,
            ),
            rec(
                "altconv",
                "limb",
                "convlstm-np-y",
                "error-mm-rollout10",
                Some("test"),
                2.0,
            ),
            rec("altconv", "limb", "skinning", "error-mm-rollout10", Some("test"), 3.0),
        ];
        let verdict = |outputs: &[ExperimentOutput]| claims(outputs)[1].verdict;
        assert_eq!(
            verdict(std::slice::from_ref(&out)),
            Verdict::Undecided {
                seeds: 1,
                leans_reproduced: true
            }
        );
        out.seeds = 3;
        assert_eq!(verdict(std::slice::from_ref(&out)), Verdict::Reproduced);
        assert_eq!(claims(&[])[1].verdict, Verdict::NotMeasured);
    }

    #[test]
    fn the_embedding_claim_needs_three_quarters_of_the_scenes_beyond_the_spread() {
        // (ours, no-pb) M_phys with their spreads, and M_rms.
        let pair = |scene: &str, phys: (f64, f64), sd: (f64, f64), rms: (f64, f64)| {
            let mut v = Vec::new();
            for (method, p, s, m) in [("ours", phys.0, sd.0, rms.0), ("no-pb", phys.1, sd.1, rms.1)] {
                v.push(rec("embed", scene, method, "m-phys", Some("test"), p));
                v.push(rec("embed", scene, method, "m-phys-sd", Some("test"), s));
                v.push(rec("embed", scene, method, "m-rms", Some("test"), m));
            }
            v
        };
        let good = |scene: &str| pair(scene, (1.0, 2.0), (0.1, 0.1), (10.0, 10.0));
        let mut r: Vec<Record> = ["a", "b", "c"].into_iter().flat_map(good).collect();
        // Lower, but within the spread.
        r.extend(pair("d", (1.0, 2.0), (0.6, 0.6), (10.0, 10.0)));
        let c = embed_claim(&r);
        assert_eq!(c.verdict, Verdict::Reproduced, "3 of 4 count");
        assert!(
            c.ours.starts_with(
                "lower on 3 of 4 scenes (on the means alone, as the paper compares: no spread, no M_rms filter, on 4);"
            ),
            "{}",
            c.ours
        );
        // Lower beyond the spread, but 3 % less accurate.
        r.extend(pair("e", (1.0, 2.0), (0.1, 0.1), (10.3, 10.0)));
        let c = embed_claim(&r);
        assert_eq!(c.verdict, Verdict::NotReproduced, "3 of 5 count");
        // The paper's comparison is the bare means: the 3 % less accurate scene counts there.
        assert!(c.ours.contains("no M_rms filter, on 5);"), "{}", c.ours);
        // The resolution study's coarser sheets are not design scenes.
        let mut r: Vec<Record> = ["a", "b", "c"].into_iter().flat_map(good).collect();
        r.extend(pair("sheet-ms-17", (3.0, 2.0), (0.1, 0.1), (10.0, 10.0)));
        assert_eq!(embed_claim(&r).verdict, Verdict::Reproduced);
        // The paper's share and its M_rms as printed.
        let mut r = pair("a", (1.0, 2.0), (0.0, 0.0), (10.0, 10.0));
        r[0].paper_value = Some(1.0);
        r[3].paper_value = Some(2.0);
        r[2].paper_value = Some(9.0);
        let c = embed_claim(&r);
        assert_eq!(
            c.paper_figure,
            "lower on 1 of 1 scenes (Table I: test frames, one model per scene, no spread)"
        );
        assert!(c.ours.contains("at or below the paper's on 0 of 1;"), "{}", c.ours);
        // The paper halves M_phys; with no spread that clears it.
        assert!(c.ours.contains("would clear these spreads on 1 of 1;"), "{}", c.ours);
        // A 10 % gain (paper 1.8 against 2) is 0.2 here, inside spreads of 0.1 + 0.15.
        r[0].paper_value = Some(1.8);
        r[1].value = 0.1;
        r[4].value = 0.15;
        let c = embed_claim(&r);
        assert!(c.ours.contains("would clear these spreads on 0 of 1;"), "{}", c.ours);
        // Spreads of 0.05 + 0.1 do not hide it.
        r[1].value = 0.05;
        r[4].value = 0.1;
        let c = embed_claim(&r);
        assert!(c.ours.contains("would clear these spreads on 1 of 1;"), "{}", c.ours);
        assert!(c.ours.ends_with("lower M_rms than `ours` on 0 of 0"), "{}", c.ours);
        // PCA counts where it is lower beyond `ours`'s spread.
        let mut r = pair("a", (1.0, 2.0), (0.0, 0.0), (10.0, 10.0));
        r.push(rec("embed", "a", "ours", "m-rms-sd", Some("test"), 1.0));
        r.push(rec("embed", "a", "pca", "m-rms", Some("test"), 8.5));
        r.extend(pair("b", (1.0, 2.0), (0.0, 0.0), (10.0, 10.0)));
        r.push(rec("embed", "b", "ours", "m-rms-sd", Some("test"), 1.0));
        r.push(rec("embed", "b", "pca", "m-rms", Some("test"), 9.5));
        let c = embed_claim(&r);
        assert!(c.ours.ends_with("lower M_rms than `ours` on 1 of 2"), "{}", c.ours);
    }

    #[test]
    fn a_family_panel_holds_one_scene_and_one_error_kind_never_averaged() {
        // `sheet-ms` is both a simulated scene (`sim`) and an embedded one (`embed`): the
        // simulators' per-step error and the embedding's reconstruction error go to two
        // panels, and no point is averaged over scenes.
        let mut r = vec![
            rec("sim", "sheet-ms", "loose", "m-rms", None, 2.0),
            rec("sim", "ball-ms", "loose", "m-rms", None, 4.0),
            rec("sim", "beam-stvk", "loose", "m-rms", None, 100.0),
            rec("embed", "sheet-ms", "ours", "m-rms", Some("test"), 9.0),
            rec("embed", "sheet-ms", "pca", "m-rms", Some("test"), 0.1),
            rec("embed", "sheet-ms", "ours", "m-rms", Some("validation"), 8.0),
            rec("embed", "ball-ms", "ours", "m-rms", Some("test"), 3.0),
        ];
        r[1].seconds_per_frame = Some(0.04);
        let mut untimed = rec("embed", "ball-ms", "pca", "m-rms", Some("test"), 1.0);
        untimed.seconds_per_frame = None;
        r.push(untimed);
        let panels = FAMILIES[0].panels(&r);
        let summary: Vec<(&str, ErrorKind, Vec<(&str, f64)>)> = panels
            .iter()
            .map(|p| {
                let points = p.points.iter().map(|q| (q.method.as_str(), q.error)).collect();
                (p.scene.as_str(), p.kind, points)
            })
            .collect();
        assert_eq!(
            summary,
            [
                ("sheet-ms", ErrorKind::Simulation, vec![("loose", 2.0)]),
                ("ball-ms", ErrorKind::Simulation, vec![("loose", 4.0)]),
                ("sheet-ms", ErrorKind::Reconstruction, vec![("ours", 9.0), ("pca", 0.1)]),
                ("ball-ms", ErrorKind::Reconstruction, vec![("ours", 3.0)]),
            ],
            "the beam is not cloth, validation and untimed records are not drawn"
        );
        assert!((panels[1].points[0].time_ratio - 0.04).abs() < 1e-12);
        // Every point of every panel of every family is one record of the panel's own scene
        // and error kind: a panel mixing a simulation with a reconstruction fails here.
        for family in FAMILIES {
            for p in family.panels(&r) {
                let member = family.members.iter().find(|m| m.experiment == p.experiment).unwrap();
                assert_eq!(member.kind, p.kind);
                for q in &p.points {
                    let source: Vec<&Record> = r
                        .iter()
                        .filter(|x| x.experiment == p.experiment && x.scene == p.scene && x.method == q.method)
                        .filter(|x| x.metric == member.metric && (p.split.is_none() || x.split.as_deref() == p.split))
                        .collect();
                    assert_eq!(source.len(), 1, "{p:?}");
                    assert_eq!(source[0].value, q.error, "{p:?}");
                }
            }
        }
        assert_eq!(panels[2].title(), "sheet-ms · reconstruction");
    }

    #[test]
    fn the_soft_tissue_panels_read_the_longest_test_window_and_name_it() {
        let r = vec![
            rec("altconv", "limb", "skinning", "error-mm-rollout10", Some("test"), 3.0),
            rec("altconv", "limb", "skinning", "error-mm-rollout50", Some("test"), 5.0),
            rec("altconv", "limb", "skinning", "error-mm-rollout50", Some("known"), 1.0),
            rec(
                "altconv",
                "limb-jiggle",
                "skinning",
                "error-mm-rollout50",
                Some("test"),
                9.0,
            ),
        ];
        let panels = FAMILIES[2].panels(&r);
        assert_eq!(panels.len(), 2);
        assert_eq!(panels[0].points[0].error, 5.0);
        assert_eq!(panels[1].points[0].error, 9.0);
        assert_eq!(panels[0].error_label, "50-step roll-out error (mm)");
        assert!(FAMILIES[2].panels(&[]).is_empty());
    }
}
