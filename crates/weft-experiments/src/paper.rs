//! The papers' tables in their layout, with the paper's numbers beside ours. A table is
//! plain data ([`Table`]) rendered to Markdown (`tables.md`) and HTML (`index.html`).
//! Paper figures are quoted as printed; ours come from the records of this run.

use crate::records::{ExperimentOutput, Record};

pub use crate::records::Table;

/// A table's figure: one experiment's records, looked up by scene.
fn find<'a>(records: &'a [Record], scene: &str, method: &str, metric: &str) -> Option<&'a Record> {
    crate::records::find(records, |r| r.scene == scene, method, metric)
}

/// Seconds as milliseconds with 3 significant digits, or "—" if not measured.
fn ms(r: Option<&Record>) -> String {
    r.map_or("—".into(), |r| format_ms(r.value))
}

pub fn format_ms(s: f64) -> String {
    let ms = 1e3 * s;
    // Three significant digits, but no more than two decimals below a millisecond.
    let d = crate::records::three_significant_decimals(ms).min(2);
    format!("{ms:.d$} ms")
}

/// Every table this run can fill.
pub fn tables(outputs: &[ExperimentOutput]) -> Vec<Table> {
    let mut out = Vec::new();
    for o in outputs {
        match o.experiment.as_str() {
            "sim" => {
                out.extend(legacy_nnwarp_table_1(&o.records));
                out.extend(speed_accuracy(o, "m-rms", "M_rms"));
            }
            "proj" => {
                out.push(geng_timings(&o.records));
                out.extend(speed_accuracy(o, "sqrt-mse", "SqrtMSE"));
            }
            "embed" => {
                out.push(tan_table_1(&o.records));
                out.push(tan_table_3(&o.records));
            }
            _ => {}
        }
        out.extend(o.tables.iter().cloned());
    }
    out
}

/// The resolution study's coarser sheets (Tan et al. Table III), not rows of Table I.
const RESOLUTION_SCENES: [(&str, usize); 3] = [("sheet-ms", 4225), ("sheet-ms-33", 1089), ("sheet-ms-17", 289)];

/// A `paper / ours` cell with `digits` after the point ("—" where the paper prints none).
pub fn paper_cell(paper: Option<f64>, ours: f64, digits: usize) -> String {
    match paper {
        Some(p) => format!("{p:.digits$} / {ours:.digits$}"),
        None => format!("— / {ours:.digits$}"),
    }
}

/// `paper / ours` for one record, `digits` after the point.
fn paper_and_ours(records: &[Record], scene: &str, method: &str, metric: &str, digits: usize) -> String {
    find(records, scene, method, metric).map_or("—".to_string(), |r| paper_cell(r.paper_value, r.value, digits))
}

/// The `paper / ours` cells of M_rms, M_STED and M_phys for one scene and method, with
/// the seeds' spread (`± sd`) where the evaluation trained several.
fn embed_cells(records: &[Record], scene: &str, method: &str) -> [String; 3] {
    [("m-rms", 3), ("m-sted", 5), ("m-phys", 2)].map(|(metric, digits)| {
        let sd = find(records, scene, method, &format!("{metric}-sd")).map(|r| r.value);
        with_spread(paper_and_ours(records, scene, method, metric, digits), sd, digits)
    })
}

/// `cell ± sd`, the spread with `digits` after the point; the cell alone without one (a
/// single seed).
pub(crate) fn with_spread(cell: String, sd: Option<f64>, digits: usize) -> String {
    match sd {
        Some(sd) => format!("{cell} ± {sd:.digits$}"),
        None => cell,
    }
}

/// Tan et al. Table I: the embedding's M_rms, M_STED and M_phys per scene and method on
/// the test split, the paper's figure beside ours where it prints one.
fn tan_table_1(records: &[Record]) -> Table {
    let mut scenes: Vec<&str> = Vec::new();
    for r in records.iter().filter(|r| r.experiment == "embed") {
        let coarse = RESOLUTION_SCENES[1..].iter().any(|(s, _)| *s == r.scene);
        if !coarse && !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
    }
    let mut rows = Vec::new();
    for scene in scenes {
        for (method, label) in [("ours", "ours (PB-loss)"), ("no-pb", "[46] + L_vert"), ("pca", "PCA")] {
            let mut row = vec![format!("`{scene}`"), label.to_string()];
            row.extend(embed_cells(records, scene, method));
            rows.push(row);
        }
    }
    Table {
        title: "Tan et al. Table I — embedding quality on the test split, paper / ours".into(),
        caption: "M_rms in mm (1000 × per-coordinate RMS), M_STED dimensionless, M_phys in N² (only ratios \
                  between methods of one scene are comparable). Paper rows: SHEET+[11] = `sheet-ms`, +holes = \
                  `sheet-ms-holes`, SHEET+[38] = `sheet-fem`, +obstacle = `sheet-fem-obstacle`, BALL+[11] = \
                  `ball-ms`, BALL+[38] = `ball-fem`, +0.1 P_s / +0.1 P_b = `ball-fem-soft-stretch` / \
                  `ball-fem-soft-bend`. Ours: the mean over seeds ± their spread where there are several. The \
                  paper's meshes, data sizes and training differ from ours (tables.md notes)."
            .into(),
        header: ["scene", "method", "M_rms", "M_STED", "M_phys"]
            .map(String::from)
            .to_vec(),
        rows,
    }
}

/// Tan et al. Table III: the embedding at three resolutions of the mass-spring sheet.
fn tan_table_3(records: &[Record]) -> Table {
    let mut rows = Vec::new();
    for (scene, vertices) in RESOLUTION_SCENES {
        for (method, label) in [("ours", "ours (PB-loss)"), ("no-pb", "[46] + L_vert")] {
            if find(records, scene, method, "m-rms").is_none() {
                continue;
            }
            let mut row = vec![format!("`{scene}`"), vertices.to_string(), label.to_string()];
            row.extend(embed_cells(records, scene, method));
            rows.push(row);
        }
    }
    Table {
        title: "Tan et al. Table III — robustness to mesh resolution, paper / ours".into(),
        caption: "The mass-spring sheet (SHEET+[11]) at 65 × 65, 33 × 33 and 17 × 17 vertices (the paper's K = \
                  4225, 1089, 289; quick runs use smaller meshes); test split, units as in Table I. The paper \
                  prints the 1089-vertex baseline's M_STED as 0.1648, likely 0.01648."
            .into(),
        header: ["scene", "vertices (paper)", "method", "M_rms", "M_STED", "M_phys"]
            .map(String::from)
            .to_vec(),
        rows,
    }
}

/// NNWarp Table 1 ("Time performance") from a `sim` output that still carries its timings.
/// NNWarp Table 1 is now the `nnwarp` experiment's own table, every column measured in its
/// run; `sim` measured the columns that need no network until 2026-12-07, so a `sim` output
/// published before then still has those records and its table is printed from them. A
/// `sim` run of today's code has none, and this prints nothing.
fn legacy_nnwarp_table_1(records: &[Record]) -> Option<Table> {
    find(records, "limb", "prefactorized-linear", "tetrahedra")?;
    let row = |paper_model: &str, paper: [&str; 3], scene: &str| {
        let tets = find(records, scene, "prefactorized-linear", "tetrahedra")
            .map_or("—".into(), |r| format!("{:.0}", r.value));
        vec![
            format!("{paper_model} / ours: {scene}"),
            format!("{} / {tets}", paper[0]),
            format!(
                "{} / {}",
                paper[1],
                ms(find(records, scene, "prefactorized-linear", "factorization-seconds"))
            ),
            format!(
                "{} / {}",
                paper[2],
                ms(find(records, scene, "prefactorized-linear", "solve-seconds"))
            ),
            ms(find(records, scene, "neo-hookean", "frame-seconds")),
        ]
    };
    Some(Table {
        title: "NNWarp (Luo et al.) Table 1 — time performance, paper / ours".into(),
        caption: "Pre-factorised linear FEM: factorisation of the system matrix, then one solve per frame (paper: \
                  Eigen SimplicialLLT on an 8-core i7 at 3.0 GHz; ours: weft-linalg's Cholesky on the 2-core machine \
                  of this run). The NNWarp correction columns are in experiment `nnwarp`'s own Table 1, with the trained network. The \
                  last column, ours only, is one full Neo-Hookean implicit-Euler frame on the same body."
            .into(),
        header: [
            "Model",
            "# Tetrahedra",
            "Factorization",
            "Solve",
            "Full Neo-Hookean frame (ours)",
        ]
        .map(String::from)
        .to_vec(),
        rows: vec![
            row("Beam", ["2,629", "6.9 ms", "< 1 ms"], "beam"),
            row("Dragon", ["51,850", "307 ms", "15 ms"], "limb"),
        ],
    })
}

/// Geng et al. §4.1 and §6.1: the layers' per-example cost.
fn geng_timings(records: &[Record]) -> Table {
    let scene = records
        .iter()
        .find(|r| r.method == "ipm")
        .map_or("", |r| r.scene.as_str());
    let mut rows = Vec::new();
    for (what, paper, method, metric) in [
        ("SOCP forward (our IPM)", "3–4 s", "ipm", "forward-seconds"),
        ("SOCP forward (Clarabel)", "3–4 s", "clarabel", "forward-seconds"),
        ("SOCP backward", "0.5 s", "ipm", "backward-seconds"),
        (
            "Quasistatic forward, μ = 1",
            "0.07 s",
            "quasistatic-mu-1",
            "forward-seconds",
        ),
        (
            "Quasistatic forward, μ = 0.1",
            "0.07 s",
            "quasistatic-mu-0.1",
            "forward-seconds",
        ),
        (
            "Quasistatic forward, μ = 0.01",
            "0.07 s",
            "quasistatic-mu-0.01",
            "forward-seconds",
        ),
        (
            "Quasistatic backward, μ = 0.1",
            "0.01 s",
            "quasistatic-mu-0.1",
            "backward-seconds",
        ),
    ] {
        rows.push(vec![
            what.into(),
            paper.into(),
            ms(find(records, scene, method, metric)),
        ]);
    }
    Table {
        title: format!("Geng et al. §4.1 and §6.1 — projection cost per example ({scene})"),
        caption:
            "Paper: a 2969-vertex shirt with 8787 edge constraints, its CPU not stated. Ours: a sheet of the same \
                  size under a stretched, noisy prediction, on this run's machine. The paper's errors (Tables 1–4) \
                  need the trained network (experiment `drape`)."
                .into(),
        header: ["Quantity", "Paper", "Ours"].map(String::from).to_vec(),
        rows,
    }
}

/// Ours only (no paper measures it): every method's time and error per scene.
fn speed_accuracy(o: &ExperimentOutput, metric: &str, label: &str) -> Vec<Table> {
    crate::records::distinct(
        o.records
            .iter()
            .filter(|r| r.metric == metric)
            .map(|r| r.scene.as_str()),
    )
    .into_iter()
    .map(|scene| {
        let rows = o
            .records
            .iter()
            .filter(|r| r.scene == scene && r.metric == metric)
            .map(|r| {
                let t = r.seconds_per_frame.unwrap_or(f64::NAN);
                let gt = r.ground_truth_seconds_per_frame.unwrap_or(f64::NAN);
                let max = o
                    .records
                    .iter()
                    .find(|q| {
                        q.scene == scene && q.method == r.method && (q.metric == "max-error" || q.metric == "max-dist")
                    })
                    .map_or("—".into(), |q| format!("{:.3e}", q.value));
                vec![
                    r.method.clone(),
                    format_ms(t),
                    format!("{:.3}", t / gt),
                    format!("{:.3e}", r.value),
                    max,
                ]
            })
            .collect();
        Table {
            title: format!(
                "Speed–accuracy, {} / {scene} (ours; no paper measures this)",
                o.experiment
            ),
            caption: format!(
                "Time per frame (per example for projections) and its ratio to the ground truth's, timed in the \
                     same run; {label} and the largest vertex error against the tight reference, in mm."
            ),
            header: [
                "Method",
                "Time",
                "Ratio to ground truth",
                &format!("{label} (mm)"),
                "Max error (mm)",
            ]
            .map(String::from)
            .to_vec(),
            rows,
        }
    })
    .collect()
}

/// The papers' tables that `experiments` (those in this report) do not fill yet, with the
/// experiment that will.
pub fn pending(experiments: &[&str]) -> Vec<(&'static str, &'static str)> {
    PENDING
        .iter()
        .filter(|(_, e, filled_when_run)| !(*filled_when_run && experiments.contains(e)))
        .map(|&(what, e, _)| (what, e))
        .collect()
}

/// The papers' tables that later experiments fill: what, the experiment, and whether
/// running that experiment as it is today fills it.
const PENDING: [(&str, &str, bool); 6] = [
    (
        "Tan et al. Table I (M_rms, M_STED, M_phys of the embedding)",
        "embed",
        true,
    ),
    (
        "Tan et al. Tables II–IV (loss weights, resolutions, 2nd vs 3rd stage), cloth IK and the 2-D embedding plot",
        "embed",
        true,
    ),
    (
        "Alt-ConvLSTM Tables 1–2 (per-vertex error, single-step and roll-out, known and unseen motions)",
        "altconv",
        true,
    ),
    (
        "NNWarp Table 1 (time performance) and the error curves (Figs. 13, 15, 18–19)",
        "nnwarp",
        true,
    ),
    (
        "Geng et al. Tables 1–3 (SqrtMSE, MaxDist of network, postprocess and trained postprocess)",
        "drape",
        true,
    ),
    (
        "Geng et al. Table 4 (compression and stretching energy errors)",
        "drape",
        true,
    ),
];

#[cfg(test)]
mod tests {
    use super::format_ms;

    #[test]
    fn milliseconds_keep_three_significant_digits_and_at_most_two_decimals() {
        assert_eq!(format_ms(0.000_234), "0.23 ms");
        assert_eq!(format_ms(0.006_25), "6.25 ms");
        assert_eq!(format_ms(0.023_14), "23.1 ms");
        assert_eq!(format_ms(0.943), "943 ms");
        assert_eq!(format_ms(1.18), "1180 ms");
    }
}
