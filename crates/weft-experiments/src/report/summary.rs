//! The report's first page: each paper's central claim decided from the records, and one
//! speed-against-accuracy figure per family of scenes, one panel per scene and error kind
//! (a simulation's error never on the axis of a reconstruction's).
//!
//! Everything here is computed from `results.json`'s records alone, so the summary of a
//! report is rebuilt whenever any experiment is republished.

use crate::records::{ExperimentOutput, MIN_SEEDS, Record, figure, find, lower_beyond_spread, seed_count};

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
        paper_figure: format!("lower on {} of {} scenes (Table I)", paper.0, paper.1),
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
    claim.ours = per_material
        .iter()
        .map(|(material, (pass, total, ratios))| {
            let mean = ratios.iter().sum::<f64>() / ratios.len().max(1) as f64;
            format!("{material}: {pass} of {total} unseen shapes ≤ 0.3× (NNWarp / better warp {mean:.2} on average)")
        })
        .collect::<Vec<_>>()
        .join("; ");
    claim.verdict = if per_material.values().any(|(pass, _, _)| *pass >= 2) {
        Verdict::Reproduced
    } else {
        Verdict::NotReproduced
    };
    claim
}

/// Geng et al.: training through a projection layer beats the network alone on unseen
/// poses and cuts the stretching-energy error, and the learned global μ lands in the same
/// place from any start. Decided on the loose sleeve where it was run (issue 33), else on
/// the sleeve: some `trained-*` method's test SqrtMSE at least 5 % below the network's
/// beyond both seed spreads (`mean + sd ≤ 0.95 (mean_net − sd_net)`), with its stretching
/// error cut at least 5×, and the learned μ from starts 1, 0.1 and 0.01 within a factor
/// 1.5 of each other.
fn drape_claim(records: &[Record]) -> Claim {
    let scene = if records
        .iter()
        .any(|r| r.experiment == "drape" && r.scene == "loose-sleeve")
    {
        "loose-sleeve"
    } else {
        "sleeve"
    };
    let test = |method: &str, metric: &str| find(records, on("drape", scene, TEST), method, metric);
    let sd =
        |method: &str, metric: &str| figure(records, on("drape", scene, TEST), method, metric).map_or(0.0, |f| f.1);
    let mut claim = Claim {
        paper: "Geng, Johnson & Fedkiw 2020, projection layers in training",
        experiment: "drape",
        claim: "Training through a projection layer beats the network alone on test SqrtMSE (by 5 % beyond the seeds' \
                spread) and cuts the stretching-energy error 5×; the learned global μ from three starts agrees \
                within 1.5×",
        paper_figure: "—".into(),
        ours: "—".into(),
        verdict: Verdict::NotMeasured,
    };
    let (Some(net), Some(net_s)) = (
        test("network-only", "sqrtmse-mm"),
        test("network-only", "stretching-energy-error"),
    ) else {
        return claim;
    };
    if let (Some(p), Some(q)) = (
        net.paper_value,
        test("trained-qs-mu0.1", "sqrtmse-mm").and_then(|r| r.paper_value),
    ) {
        claim.paper_figure = format!("{q:.3} mm (μ = 0.1) against {p:.3} mm (Tables 1, 3)");
        if let (Some(ps), Some(qs)) = (
            net_s.paper_value,
            test("trained-qs-mu0.1", "stretching-energy-error").and_then(|r| r.paper_value),
        ) {
            claim.paper_figure += &format!(
                "; stretching error cut {:.1}× (Table 4); μ 0.090–0.100 from 1, 0.1, 0.01",
                ps / qs
            );
        }
    }
    let bar = 0.95 * (net.value - sd("network-only", "sqrtmse-mm"));
    let trained = records
        .iter()
        .filter(|r| {
            r.experiment == "drape"
                && r.scene == scene
                && r.method.starts_with("trained-")
                && r.metric == "sqrtmse-mm"
                && r.is_test()
        })
        .filter_map(|r| {
            let s = test(&r.method, "stretching-energy-error")?;
            let cut = net_s.value / s.value.max(f64::MIN_POSITIVE);
            let upper = r.value + sd(&r.method, "sqrtmse-mm");
            Some((r, cut, upper <= bar && cut >= 5.0))
        })
        .collect::<Vec<_>>();
    let Some(best) = trained.iter().min_by(|a, b| {
        (!a.2, a.0.value)
            .partial_cmp(&(!b.2, b.0.value))
            .unwrap_or(std::cmp::Ordering::Equal)
    }) else {
        return claim;
    };
    let mu: Vec<f64> = ["1", "0.1", "0.01"]
        .iter()
        .filter_map(|s| {
            find(
                records,
                on("drape", scene, None),
                &format!("learned-mu-from-{s}"),
                "learned-mu",
            )
            .map(|r| r.value)
        })
        .collect();
    let (lo, hi) = mu
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &m| (a.min(m), b.max(m)));
    let mu_ratio = hi / lo;
    let mu_agrees = mu.len() == 3 && mu_ratio.is_finite() && mu_ratio <= 1.5;
    // A figure with its seeds' spread where there is one.
    let with_sd = |r: &Record| match test(&r.method, "sqrtmse-mm-sd") {
        Some(sd) => format!("{:.3} ± {:.3}", r.value, sd.value),
        None => format!("{:.3}", r.value),
    };
    let learned = if mu.is_empty() {
        "learned μ not measured (no `learned-mu-from-*` rows)".to_string()
    } else {
        format!(
            "learned μ {} (largest / smallest {:.2})",
            mu.iter()
                .map(|&m| crate::records::three_significant(m))
                .collect::<Vec<_>>()
                .join(", "),
            mu_ratio
        )
    };
    claim.ours = format!(
        "{scene}: {} mm (`{}`) against {} mm; stretching error cut {:.1}×; {learned}",
        with_sd(best.0),
        best.0.method,
        with_sd(net),
        best.1,
    );
    claim.verdict = if best.2 && mu_agrees {
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
        title: "Cloth: solver variants (simulation) and the learned embedding (reconstruction)",
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
        ],
    },
    Family {
        name: "volumetric",
        title: "Volumetric: warped linear FEM and NNWarp against full FEM",
        members: &[Member {
            experiment: "nnwarp",
            scene_prefixes: &[],
            metric: "rel-error",
            split: None,
            kind: ErrorKind::StaticSolve,
            error_label: "rel-error",
        }],
    },
    Family {
        name: "soft-tissue",
        title: "Soft tissue: skinning and the learned dynamics on unseen motions",
        members: &[Member {
            experiment: "altconv",
            scene_prefixes: &[],
            metric: "error-mm-rollout",
            split: Some("test"),
            kind: ErrorKind::RollOut,
            error_label: "roll-out error (mm)",
        }],
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

    #[test]
    fn the_drape_claim_is_decided_on_the_loose_sleeve_beyond_the_spread_with_agreeing_mu() {
        let cell = |scene: &str, method: &str, v: f64, sd: f64, stretch: f64| {
            vec![
                rec("drape", scene, method, "sqrtmse-mm", Some("test"), v),
                rec("drape", scene, method, "sqrtmse-mm-sd", Some("test"), sd),
                rec("drape", scene, method, "stretching-energy-error", Some("test"), stretch),
            ]
        };
        let mu = |scene: &str, values: [f64; 3]| {
            ["1", "0.1", "0.01"]
                .iter()
                .zip(values)
                .map(|(s, m)| rec("drape", scene, &format!("learned-mu-from-{s}"), "learned-mu", None, m))
                .collect::<Vec<_>>()
        };
        // 10 ± 0.2 against 9.0 ± 0.2 with a 6× cut and μ within 1.2×: reproduced. The
        // sleeve, where the layer loses, does not count once the loose sleeve ran.
        let base = [
            cell("sleeve", "network-only", 0.2, 0.0, 1.0),
            cell("sleeve", "trained-qs-mu0.1", 0.3, 0.0, 1.0),
            mu("sleeve", [0.1, 0.5, 0.01]),
            cell("loose-sleeve", "network-only", 10.0, 0.2, 6.0),
            mu("loose-sleeve", [0.1, 0.11, 0.12]),
        ]
        .concat();
        let with = |trained: Vec<Record>| [base.clone(), trained].concat();
        let c = drape_claim(&with(cell("loose-sleeve", "trained-qs-mu0.1", 9.0, 0.2, 1.0)));
        assert_eq!(c.verdict, Verdict::Reproduced, "{}", c.ours);
        assert!(c.ours.contains("loose-sleeve"), "{}", c.ours);
        assert!(
            c.ours
                .contains("learned μ 0.100, 0.110, 0.120 (largest / smallest 1.20)"),
            "{}",
            c.ours
        );
        // Small μ keep three significant digits.
        let mut r = with(cell("loose-sleeve", "trained-qs-mu0.1", 9.0, 0.2, 1.0));
        r.retain(|x| !(x.scene == "loose-sleeve" && x.metric == "learned-mu"));
        r.extend(mu("loose-sleeve", [0.007_414, 0.007_492, 0.007_572]));
        let c = drape_claim(&r);
        assert!(
            c.ours
                .contains("learned μ 0.00741, 0.00749, 0.00757 (largest / smallest 1.02)"),
            "{}",
            c.ours
        );
        assert_eq!(c.verdict, Verdict::Reproduced);
        // The same means with a spread that closes the 5 % margin: not reproduced.
        let c = drape_claim(&with(cell("loose-sleeve", "trained-qs-mu0.1", 9.0, 0.5, 1.0)));
        assert_eq!(c.verdict, Verdict::NotReproduced);
        // Better but the stretching error cut only 3×: not reproduced.
        let c = drape_claim(&with(cell("loose-sleeve", "trained-qs-mu0.1", 9.0, 0.2, 2.0)));
        assert_eq!(c.verdict, Verdict::NotReproduced);
        // μ from the three starts 2× apart: not reproduced.
        let mut r = with(cell("loose-sleeve", "trained-qs-mu0.1", 9.0, 0.2, 1.0));
        r.retain(|x| !(x.scene == "loose-sleeve" && x.metric == "learned-mu"));
        r.extend(mu("loose-sleeve", [0.1, 0.2, 0.15]));
        assert_eq!(drape_claim(&r).verdict, Verdict::NotReproduced);
        // A postprocess (not trained through the layer) does not count.
        let c = drape_claim(&with(cell("loose-sleeve", "postprocess-qs-mu0.1", 9.0, 0.2, 1.0)));
        assert_eq!(c.verdict, Verdict::NotMeasured);
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
        assert_eq!(c.paper_figure, "lower on 1 of 1 scenes (Table I)");
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
