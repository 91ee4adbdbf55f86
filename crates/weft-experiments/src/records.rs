//! The evaluation's data: tidy records (one per measured figure, the rows of
//! `results.json`), roll-out curves and energies for the plots, and shared error metrics.

use crate::error::ensure;
use serde::{Deserialize, Serialize};

use weft_data::Size;

/// A table: title, caption, header and rows of cells.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table {
    pub title: String,
    pub caption: String,
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

impl Table {
    pub fn markdown(&self) -> String {
        let mut s = format!("### {}\n\n{}\n\n", self.title, self.caption);
        s.push_str(&format!("| {} |\n", self.header.join(" | ")));
        s.push_str(&format!("|{}\n", "---|".repeat(self.header.len())));
        for r in &self.rows {
            s.push_str(&format!("| {} |\n", r.join(" | ")));
        }
        s.push('\n');
        s
    }
}

/// One measured figure. Field names and meanings are documented in `docs/RESULTS.md`;
/// fields that do not apply are `null`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub experiment: String,
    pub scene: String,
    pub method: String,
    pub metric: String,
    pub split: Option<String>,
    pub value: f64,
    pub unit: String,
    /// The paper's figure for the same quantity, where a paper prints one.
    pub paper_value: Option<f64>,
    /// The method's wall time per frame (per example for projections), in seconds.
    pub seconds_per_frame: Option<f64>,
    /// The ground-truth solver's wall time per frame, measured in the same run (s).
    pub ground_truth_seconds_per_frame: Option<f64>,
    /// The training seed of a learned model's figure; `null` on a figure over seeds (the
    /// mean and its `-sd` twin, both derived from the per-seed records beside them) and on
    /// figures of methods that train nothing.
    #[serde(default)]
    pub seed: Option<u64>,
}

impl Record {
    /// Whether the figure is on the test split, the only split a claim or table reports.
    pub fn is_test(&self) -> bool {
        self.split.as_deref() == Some("test")
    }
}

/// Roll-out error of one method against the reference, frame by frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    pub scene: String,
    pub method: String,
    /// Scene frames (time / the scene's frame time).
    pub frames: Vec<f64>,
    /// Per-frame RMS error per coordinate (mm, M_rms of that frame); for a curve over
    /// seeds ([`Curve::over_seeds`]), their mean.
    pub error_mm: Vec<f64>,
    /// The seeds' spread of `error_mm` (population standard deviation per frame); empty
    /// for a single run.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub error_mm_sd: Vec<f64>,
}

impl Curve {
    /// One method's roll-out over several seeds: per frame the seeds' mean and spread (as
    /// [`mean_sd`]), so the plot carries the spread every table does. The seeds must share
    /// scene, method and frames; `None` for no seeds.
    pub fn over_seeds(seeds: &[Curve]) -> crate::Result<Option<Curve>> {
        let Some(first) = seeds.first() else {
            return Ok(None);
        };
        for c in seeds {
            ensure!(
                c.scene == first.scene && c.method == first.method && c.frames == first.frames,
                "roll-out curves of {} / {} and {} / {} over different frames cannot be averaged",
                first.scene,
                first.method,
                c.scene,
                c.method
            );
        }
        let (error_mm, error_mm_sd) = (0..first.frames.len())
            .map(|k| mean_sd(seeds.iter().map(|c| c.error_mm[k])))
            .unzip();
        Ok(Some(Curve {
            error_mm,
            error_mm_sd: if seeds.len() > 1 { error_mm_sd } else { Vec::new() },
            ..first.clone()
        }))
    }
}

/// One bar of an energy chart.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnergyBar {
    pub scene: String,
    pub method: String,
    /// What energy (`potential`, `kinetic`, `stretching`, `compression`).
    pub kind: String,
    pub value: f64,
    pub unit: String,
}

/// A labelled 2-D point set (Tan et al. Fig. 6's embedding plot): one colour per label.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scatter {
    pub scene: String,
    pub method: String,
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub points: Vec<[f64; 2]>,
    /// One label per point.
    pub labels: Vec<String>,
}

/// A line chart of quantities other than a roll-out's error against frame (NNWarp
/// Figs. 15, 18 and 19: a node's trajectory, error against load), one line per series.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinePlot {
    /// File-name stem under `plots/` (`<experiment>-<name>`).
    pub name: String,
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    /// Logarithmic y axis (errors spanning decades).
    pub log_y: bool,
    pub series: Vec<Series>,
}

/// One line of a [`LinePlot`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Series {
    /// The method (or reference) the line belongs to.
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
}

/// Everything one experiment measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExperimentOutput {
    pub experiment: String,
    pub size: Size,
    pub records: Vec<Record>,
    pub curves: Vec<Curve>,
    pub energies: Vec<EnergyBar>,
    /// Rendered error images, relative to the output directory.
    pub renders: Vec<String>,
    /// Methods that failed, with the typed error (never a NaN passed on).
    pub failures: Vec<String>,
    /// Settings and facts the tables cite (meshes, tolerances, time steps).
    pub notes: Vec<String>,
    /// Tables only this experiment can fill (ablations whose models are not methods of
    /// the records), in the papers' layouts.
    #[serde(default)]
    pub tables: Vec<Table>,
    #[serde(default)]
    pub scatters: Vec<Scatter>,
    #[serde(default)]
    pub lines: Vec<LinePlot>,
    /// Wall seconds of the experiment: the run's own, plus those an experiment that
    /// resumes across runs records for the work it read back instead of redoing.
    pub wall_seconds: f64,
    /// The command line and code version that produced this output (empty in outputs
    /// cached before they were recorded).
    #[serde(default)]
    pub command: String,
    #[serde(default)]
    pub code_version: String,
    /// Seeds each learned method was trained with (an output cached before the field was
    /// recorded trained one). A claim is decided only on [`MIN_SEEDS`] or more.
    #[serde(default = "one_seed")]
    pub seeds: usize,
}

/// The fewest seeds a claim is decided on (the brief: mean and spread of at least three).
pub const MIN_SEEDS: usize = 3;

fn one_seed() -> usize {
    1
}

impl ExperimentOutput {
    pub fn new(experiment: &str, size: Size) -> Self {
        Self {
            experiment: experiment.into(),
            size,
            records: Vec::new(),
            curves: Vec::new(),
            energies: Vec::new(),
            renders: Vec::new(),
            failures: Vec::new(),
            notes: Vec::new(),
            tables: Vec::new(),
            scatters: Vec::new(),
            lines: Vec::new(),
            wall_seconds: 0.0,
            command: String::new(),
            code_version: String::new(),
            seeds: 1,
        }
    }

    /// Adds a record with no paper value.
    pub fn record(&mut self, scene: &str, method: &str, metric: &str, value: f64, unit: &str, timing: Timing) {
        self.records.push(Record {
            experiment: self.experiment.clone(),
            scene: scene.into(),
            method: method.into(),
            metric: metric.into(),
            split: None,
            value,
            unit: unit.into(),
            paper_value: None,
            seconds_per_frame: timing.seconds_per_frame,
            ground_truth_seconds_per_frame: timing.ground_truth_seconds_per_frame,
            seed: None,
        });
    }

    /// A learned method's figure over its seeds: one record per seed (its `seed` set,
    /// its own time where `per_seed` gives one), then their mean (with the paper's figure
    /// and the method's time) and, with several seeds, their spread as the `-sd` twin.
    /// Every verdict is recomputed from the per-seed records ([`figure`]); the mean and
    /// `-sd` records are for a reader and must agree with them (`check-report`).
    /// Returns the mean and spread.
    pub fn record_over_seeds(&mut self, f: &SeedFigure, per_seed: &[(u64, f64)]) -> Figure {
        let (mean, sd) = mean_sd(per_seed.iter().map(|(_, v)| *v));
        for &(seed, value) in per_seed {
            self.record(f.scene, f.method, f.metric, value, f.unit, Timing::default());
            let r = self.records.last_mut().expect("just pushed");
            r.split = f.split.map(Into::into);
            r.seed = Some(seed);
        }
        self.record(f.scene, f.method, f.metric, mean, f.unit, f.timing);
        if let Some(p) = f.paper {
            self.paper(p);
        }
        if let Some(split) = f.split {
            self.split(split);
        }
        if per_seed.len() > 1 {
            self.record(
                f.scene,
                f.method,
                &format!("{}-sd", f.metric),
                sd,
                f.unit,
                Timing::default(),
            );
            if let Some(split) = f.split {
                self.split(split);
            }
        }
        (mean, sd)
    }

    /// Sets the paper value of the last record.
    pub fn paper(&mut self, value: f64) {
        if let Some(r) = self.records.last_mut() {
            r.paper_value = Some(value);
        }
    }

    /// Sets the split of the last record (`train`, `validation`, `test`, or an
    /// experiment's own such as `known` or `unseen-shape`).
    pub fn split(&mut self, split: &str) {
        if let Some(r) = self.records.last_mut() {
            r.split = Some(split.into());
        }
    }

    pub fn energy(&mut self, scene: &str, method: &str, kind: &str, value: f64, unit: &str) {
        self.energies.push(EnergyBar {
            scene: scene.into(),
            method: method.into(),
            kind: kind.into(),
            value,
            unit: unit.into(),
        });
    }
}

/// What names a figure [`ExperimentOutput::record_over_seeds`] writes over seeds.
#[derive(Debug, Clone, Copy)]
pub struct SeedFigure<'a> {
    pub scene: &'a str,
    pub method: &'a str,
    pub metric: &'a str,
    pub split: Option<&'a str>,
    pub unit: &'a str,
    /// The method's time per frame, on the mean record.
    pub timing: Timing,
    /// The paper's figure for the same quantity, on the mean record.
    pub paper: Option<f64>,
}

/// A method's time per frame beside the ground truth's, both from the same run.
#[derive(Debug, Clone, Copy, Default)]
pub struct Timing {
    pub seconds_per_frame: Option<f64>,
    pub ground_truth_seconds_per_frame: Option<f64>,
}

impl Timing {
    pub fn new(method: f64, ground_truth: f64) -> Self {
        Self {
            seconds_per_frame: Some(method),
            ground_truth_seconds_per_frame: Some(ground_truth),
        }
    }
}

/// Every name is lower-case kebab-case and every number finite: the checks CI runs on a
/// report (and `evaluate` runs before writing one).
/// The units a record may carry (docs/RESULTS.md).
pub const UNITS: [&str; 11] = ["mm", "m", "s", "1/s", "J", "mJ", "N", "N^2", "count", "code", "1"];

/// Units of quantities that are never negative: distances and errors, times, rates, force
/// norms and their squares, energy errors (mJ) and counts. Energies (J), codes and
/// dimensionless figures (1, e.g. a signed bound violation) may be negative.
const NON_NEGATIVE_UNITS: [&str; 8] = ["mm", "m", "s", "1/s", "mJ", "N", "N^2", "count"];

pub fn validate(records: &[Record]) -> crate::Result<()> {
    let kebab = |s: &str| {
        !s.is_empty()
            && s.chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-' || c == '.' || c == '/')
    };
    for r in records {
        for (field, v) in [
            ("experiment", r.experiment.as_str()),
            ("scene", &r.scene),
            ("method", &r.method),
            ("metric", &r.metric),
        ] {
            ensure!(kebab(v), "record {r:?}: {field} {v:?} is not lower-case kebab-case");
        }
        if let Some(s) = &r.split {
            ensure!(kebab(s), "record {r:?}: split {s:?} is not lower-case kebab-case");
        }
        ensure!(
            UNITS.contains(&r.unit.as_str()),
            "record {r:?}: unit {:?} is not one of {}",
            r.unit,
            UNITS.join(", ")
        );
        let finite = |x: Option<f64>| x.is_none_or(f64::is_finite);
        ensure!(
            r.value.is_finite()
                && finite(r.paper_value)
                && finite(r.seconds_per_frame)
                && finite(r.ground_truth_seconds_per_frame),
            "record {r:?}: a number is not finite"
        );
        ensure!(
            r.seconds_per_frame.is_none_or(|s| s >= 0.0) && r.ground_truth_seconds_per_frame.is_none_or(|s| s > 0.0),
            "record {r:?}: negative or zero time"
        );
        if NON_NEGATIVE_UNITS.contains(&r.unit.as_str()) {
            ensure!(
                r.value >= 0.0 && r.paper_value.is_none_or(|p| p >= 0.0),
                "record {r:?}: a figure in {} is never negative",
                r.unit
            );
        }
    }
    Ok(())
}

pub use weft_nn::metrics::RmsAccumulator;

/// Mean and (population) standard deviation of `samples`; (0, 0) for none.
pub fn mean_sd(samples: impl Iterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = samples.collect();
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// The first record of `method`'s `metric` among those `within` keeps (an experiment, a
/// scene, a split: the caller's choice) that is not one seed's: a figure over seeds or of a
/// method that trains nothing. Every table looks its figures up here; every verdict goes
/// through [`figure`], which recomputes them from the seeds.
pub fn find<'a>(
    records: &'a [Record],
    within: impl Fn(&Record) -> bool,
    method: &str,
    metric: &str,
) -> Option<&'a Record> {
    records
        .iter()
        .find(|r| r.seed.is_none() && r.method == method && r.metric == metric && within(r))
}

/// A figure over the seeds: their mean and spread (sd; 0 for a single run).
pub type Figure = (f64, f64);

/// `method`'s `metric` among the records `within` keeps, with its spread, recomputed
/// from the per-seed records (`seed` set) where the output has them — the mean and `-sd`
/// records beside them are for a reader, and a verdict never trusts them over the seeds.
/// An output from before per-seed records falls back to the mean record and its `-sd`
/// twin, 0 where there is none (one run, e.g. a PCA).
pub fn figure(records: &[Record], within: impl Fn(&Record) -> bool, method: &str, metric: &str) -> Option<Figure> {
    let seeds: Vec<f64> = records
        .iter()
        .filter(|r| r.seed.is_some() && r.method == method && r.metric == metric && within(r))
        .map(|r| r.value)
        .collect();
    if !seeds.is_empty() {
        return Some(mean_sd(seeds.into_iter()));
    }
    let mean = find(records, &within, method, metric)?.value;
    let sd = find(records, &within, method, &format!("{metric}-sd")).map_or(0.0, |r| r.value);
    Some((mean, sd))
}

/// How many seeds' records `method`'s `metric` has among those `within` keeps (0 in an
/// output from before per-seed records).
pub fn seed_count(records: &[Record], within: impl Fn(&Record) -> bool, method: &str, metric: &str) -> usize {
    records
        .iter()
        .filter(|r| r.seed.is_some() && r.method == method && r.metric == metric && within(r))
        .count()
}

/// Whether `a` is lower than `b` by more than the two spreads together — the rule a
/// difference must pass before a claim or a table counts it: a gap inside the seeds'
/// spread is a tie.
pub fn lower_beyond_spread(a: Figure, b: Figure) -> bool {
    a.0 + a.1 + b.1 < b.0
}

/// Decimals that print `x` with three significant digits in fixed notation: tables hold
/// figures that span decades (an energy error of 1.39 mJ beside one of 0.00707 mJ; μ of
/// 0.1 beside 0.0074), which a fixed number of decimals rounds to nothing.
pub fn three_significant_decimals(x: f64) -> usize {
    if x.is_finite() && x != 0.0 {
        (2 - x.abs().log10().floor() as i32).max(0) as usize
    } else {
        3
    }
}

/// `x` with three significant digits in fixed notation (`three_significant_decimals`).
pub fn three_significant(x: f64) -> String {
    let d = three_significant_decimals(x);
    format!("{x:.d$}")
}

/// A mean over seeds with three significant digits and their spread to the same decimals.
pub fn mean_and_spread(mean: f64, sd: f64) -> String {
    let d = three_significant_decimals(mean);
    format!("{mean:.d$}±{sd:.d$}")
}

/// The distinct names of `names`, in first-seen order.
pub fn distinct<'a>(names: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut v: Vec<&str> = Vec::new();
    for n in names {
        if !v.contains(&n) {
            v.push(n);
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_roll_out_over_seeds_is_the_mean_and_population_spread_of_each_frame() {
        let curve = |error_mm: Vec<f64>| Curve {
            scene: "sheet-ms".into(),
            method: "ours".into(),
            frames: vec![2.0, 3.0],
            error_mm,
            error_mm_sd: Vec::new(),
        };
        let c = Curve::over_seeds(&[curve(vec![1.0, 10.0]), curve(vec![3.0, 10.0]), curve(vec![5.0, 40.0])])
            .unwrap()
            .unwrap();
        assert_eq!(c.frames, vec![2.0, 3.0]);
        assert_eq!(c.error_mm, vec![3.0, 20.0]);
        // Population sd: √(8/3) and √(200).
        assert!((c.error_mm_sd[0] - (8.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((c.error_mm_sd[1] - 200.0f64.sqrt()).abs() < 1e-12);
        // One seed has no spread, no seed no curve, and other frames are refused.
        assert!(
            Curve::over_seeds(&[curve(vec![1.0, 2.0])])
                .unwrap()
                .unwrap()
                .error_mm_sd
                .is_empty()
        );
        assert!(Curve::over_seeds(&[]).unwrap().is_none());
        let mut shifted = curve(vec![1.0, 2.0]);
        shifted.frames = vec![3.0, 4.0];
        assert!(Curve::over_seeds(&[curve(vec![1.0, 2.0]), shifted]).is_err());
    }

    #[test]
    fn table_figures_keep_three_significant_digits_across_decades() {
        assert_eq!(three_significant(1.394), "1.39");
        assert_eq!(three_significant(0.007_07), "0.00707");
        assert_eq!(three_significant(-0.022), "-0.0220");
        assert_eq!(three_significant(123.4), "123");
        assert_eq!(three_significant(4519.7), "4520");
        assert_eq!(three_significant(0.0), "0.000");
        assert_eq!(mean_and_spread(4.0712, 0.0721), "4.07±0.07");
        assert_eq!(mean_and_spread(0.007_07, 0.002_1), "0.00707±0.00210");
    }

    #[test]
    fn validation_rejects_non_kebab_names_nan_unknown_units_and_negative_sizes() {
        let good = Record {
            experiment: "sim".into(),
            scene: "sheet-ms".into(),
            method: "dt-2x".into(),
            metric: "m-rms".into(),
            split: None,
            value: 1.0,
            unit: "mm".into(),
            paper_value: None,
            seconds_per_frame: Some(0.1),
            ground_truth_seconds_per_frame: Some(0.2),
            seed: None,
        };
        assert!(validate(std::slice::from_ref(&good)).is_ok());
        let bad_name = Record {
            method: "Dt 2x".into(),
            ..good.clone()
        };
        assert!(validate(&[bad_name]).is_err());
        let nan = Record {
            value: f64::NAN,
            ..good.clone()
        };
        assert!(validate(&[nan]).is_err());
        let zero_gt = Record {
            ground_truth_seconds_per_frame: Some(0.0),
            ..good.clone()
        };
        assert!(validate(&[zero_gt]).is_err());
        let ms = |unit: &str, value: f64, paper_value: Option<f64>| Record {
            unit: unit.into(),
            value,
            paper_value,
            ..good.clone()
        };
        let e = validate(&[ms("mm", -0.1, None)]).unwrap_err();
        assert!(e.to_string().contains("in mm is never negative"), "{e}");
        assert!(validate(&[ms("mm", 0.1, Some(-1.0))]).is_err());
        assert!(validate(&[ms("s", -1e-9, None)]).is_err());
        // A signed figure keeps its sign: an energy, a bound violation.
        assert!(validate(&[ms("J", -3.0, None)]).is_ok());
        assert!(validate(&[ms("1", -3e-11, None)]).is_ok());
        let e = validate(&[ms("furlongs", 1.0, None)]).unwrap_err();
        assert!(
            e.to_string().contains("unit \"furlongs\" is not one of mm, m, s"),
            "{e}"
        );
        assert!(validate(&[ms("", 1.0, None)]).is_err());
    }

    /// A figure is the first record the filter keeps with its `-sd` record's spread (0
    /// without one), and a difference counts only beyond both spreads: at the margin it is
    /// a tie, either way round.
    #[test]
    fn a_figure_carries_its_spread_and_a_gap_inside_the_spreads_is_a_tie() {
        let r = |scene: &str, metric: &str, split: Option<&str>, value: f64| Record {
            experiment: "embed".into(),
            scene: scene.into(),
            method: "ours".into(),
            metric: metric.into(),
            split: split.map(Into::into),
            value,
            unit: "mm".into(),
            paper_value: None,
            seconds_per_frame: None,
            ground_truth_seconds_per_frame: None,
            seed: None,
        };
        let records = [
            r("a", "m-rms", Some("validation"), 1.0),
            r("a", "m-rms", Some("test"), 5.0),
            r("a", "m-rms-sd", Some("test"), 0.5),
            r("b", "m-rms", Some("test"), 7.0),
        ];
        let test_of = |scene: &'static str| move |r: &Record| r.scene == scene && r.is_test();
        assert_eq!(figure(&records, test_of("a"), "ours", "m-rms"), Some((5.0, 0.5)));
        assert_eq!(figure(&records, test_of("b"), "ours", "m-rms"), Some((7.0, 0.0)));
        assert_eq!(figure(&records, test_of("b"), "pca", "m-rms"), None);
        assert_eq!(
            find(&records, |r| r.scene == "a", "ours", "m-rms").map(|r| r.value),
            Some(1.0)
        );
        assert!(lower_beyond_spread((5.0, 0.5), (7.0, 0.0)));
        assert!(!lower_beyond_spread((7.0, 0.0), (5.0, 0.5)));
        // A gap of exactly the two spreads is a tie, and so is one inside them.
        assert!(!lower_beyond_spread((5.0, 0.5), (6.0, 0.5)));
        assert!(!lower_beyond_spread((5.0, 0.5), (5.9, 0.5)));
        assert!(lower_beyond_spread((5.0, 0.5), (6.1, 0.5)));
    }

    #[test]
    fn figures_over_seeds_are_written_per_seed_and_recomputed_from_the_seeds_not_the_mean() {
        let mut out = ExperimentOutput::new("altconv", Size::Quick);
        let f = SeedFigure {
            scene: "limb",
            method: "alt-convlstm",
            metric: "error-mm-rollout50",
            split: Some("test"),
            unit: "mm",
            timing: Timing::new(0.01, 1.0),
            paper: Some(8.14),
        };
        let (mean, sd) = out.record_over_seeds(&f, &[(0, 1.0), (1, 2.0), (2, 6.0)]);
        assert_eq!((mean, sd), (3.0, (14.0f64 / 3.0).sqrt()));
        // Three per-seed records (no time, no paper figure), the mean (with both) and its -sd.
        let seeds: Vec<Option<u64>> = out.records.iter().map(|r| r.seed).collect();
        assert_eq!(seeds, [Some(0), Some(1), Some(2), None, None]);
        assert_eq!(out.records[3].paper_value, Some(8.14));
        assert_eq!(out.records[3].seconds_per_frame, Some(0.01));
        assert_eq!(out.records[4].metric, "error-mm-rollout50-sd");
        assert!(out.records.iter().all(|r| r.split.as_deref() == Some("test")));
        validate(&out.records).unwrap();
        // A verdict reads the seeds: a mean record that disagrees with them is not used.
        let test = |r: &Record| r.is_test();
        out.records[3].value = 100.0;
        out.records[4].value = 100.0;
        assert_eq!(
            figure(&out.records, test, "alt-convlstm", "error-mm-rollout50"),
            Some((mean, sd))
        );
        // A table reads the mean record, never one seed's.
        assert_eq!(
            find(&out.records, test, "alt-convlstm", "error-mm-rollout50").map(|r| r.value),
            Some(100.0)
        );
        assert_eq!(seed_count(&out.records, test, "alt-convlstm", "error-mm-rollout50"), 3);
        // One seed: its record and the mean, no spread record.
        let mut one = ExperimentOutput::new("drape", Size::Quick);
        one.record_over_seeds(
            &SeedFigure {
                method: "network-only",
                ..f
            },
            &[(1, 4.0)],
        );
        assert_eq!(one.records.len(), 2);
        assert_eq!(
            figure(&one.records, test, "network-only", "error-mm-rollout50"),
            Some((4.0, 0.0))
        );
    }
}
