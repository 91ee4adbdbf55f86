//! The drape experiment's studies: the network alone per seed, its data-size curve, the
//! fine-tuning rate chosen on validation, every `trained-*` model per seed, and the
//! learned global μ from three starts (Geng et al. §6.2).

use std::path::{Path, PathBuf};

use weft_nn::drape::{DrapeTrainingSettings, Fitted, Layer, Plan, fit};

use super::data::GarmentData;
use super::scoring::score;
use super::tables::paper_learned_mu;
use super::{CONTROL, FIXED_MU, MU_STARTS, finetune_rates};
use crate::error::Context;
use crate::evaluate::context::EvalContext;
use crate::evaluate::study::Study;
use crate::records::{ExperimentOutput, Timing};

/// Trains (or resumes) one model of the garment as `plan` says, into `dir`; training
/// batches the layer failed on go to `out`'s failures.
fn train_one(
    ctx: &EvalContext,
    g: &GarmentData,
    out: &mut ExperimentOutput,
    dir: &Path,
    plan: &Plan,
    config: &DrapeTrainingSettings,
) -> crate::Result<Fitted> {
    let (scene, name, seed) = (g.scene, plan.name, config.seed);
    let mut progress = crate::progress::TrainProgress::new(ctx.quiet, &format!("drape/{scene}/{name}/seed-{seed}"))?;
    let f = fit(
        dir,
        plan,
        config,
        &g.layers,
        &g.train,
        &g.validation,
        g.v,
        &mut progress,
    )
    .with_context(|| format!("training drape/{scene}/{name} (seed {seed})"))?;
    drop(progress);
    let (skipped, first) = f.state.skipped();
    if skipped > 0 {
        out.failures.push(format!(
            "drape/{scene}/{name}/seed-{seed}: {skipped} training batches skipped because the layer failed on \
             them; the first: {}",
            first.unwrap_or_default()
        ));
    }
    Ok(f)
}

/// The plan of a model trained from scratch (`init` `None`) or fine-tuned from `init`.
fn plan<'a>(name: &'a str, layer: Layer, init: Option<&'a Path>, epochs: usize) -> Plan<'a> {
    Plan {
        name,
        layer,
        init,
        epochs,
        retrain_on_mismatch: true,
    }
}

/// The network alone, per seed (pretraining at the base rate): `(seed, directory, model)`.
pub(super) fn networks(
    ctx: &EvalContext,
    g: &GarmentData,
    out: &mut ExperimentOutput,
) -> crate::Result<Vec<(u64, PathBuf, Fitted)>> {
    let mut networks = Vec::new();
    for &seed in &g.seeds {
        let dir = g.models_of(seed).join("network-only");
        let f = train_one(
            ctx,
            g,
            out,
            &dir,
            &plan("network-only", Layer::None, None, g.base.pretrain_epochs),
            &g.config_of(seed, g.base.learning_rate),
        )?;
        networks.push((seed, dir, f));
    }
    Ok(networks)
}

/// The network's data-size curve (first seed): `network-only` trained the same way on
/// the first quarter and half of the training examples, beside the whole set's
/// (`whole`); one table row per size.
pub(super) fn data_size_curve(ctx: &EvalContext, g: &GarmentData, whole: &Fitted) -> crate::Result<Vec<Vec<String>>> {
    let (scene, train) = (g.scene, &g.train);
    let mut size_rows = Vec::new();
    for n in [train.len() / 4, train.len() / 2, train.len()] {
        let seed = g.seeds[0];
        let owned;
        let fitted: &Fitted = if n == train.len() {
            whole
        } else {
            let subset = train.select(&(0..n).collect::<Vec<_>>())?;
            let mut progress =
                crate::progress::TrainProgress::new(ctx.quiet, &format!("drape/{scene}/network-only-{n}/seed-{seed}"))?;
            let f = fit(
                &g.models_of(seed).join("data-size").join(format!("n{n}")),
                &plan("network-only", Layer::None, None, g.base.pretrain_epochs),
                &g.config_of(seed, g.base.learning_rate),
                &g.layers,
                &subset,
                &g.validation,
                g.v,
                &mut progress,
            )
            .with_context(|| format!("training drape/{scene}/network-only on {n} examples (seed {seed})"))?;
            owned = f;
            &owned
        };
        let mut row = vec![format!("{n}")];
        for data in [&g.validation, &g.test] {
            let (s, _) =
                score(&fitted.model, data, &g.rest, g.k(), g.base.batch).context("scoring the data-size curve")?;
            row.push(format!("{:.3}", s.sqrtmse));
        }
        row.push(format!("{}", fitted.state.best_epoch));
        size_rows.push(row);
    }
    Ok(size_rows)
}

/// The fine-tuning rate chosen on validation, its table rows, and the chosen rate's
/// model (the first seed's `trained-qs-mu0.1`).
pub(super) struct RateChoice {
    pub rows: Vec<Vec<String>>,
    pub rate: f64,
    pub fitted: Option<Fitted>,
}

/// The fine-tuning rate, on validation: the quasistatic layer at μ = 0.1 from the first
/// seed's network `net0`, one directory per rate.
pub(super) fn finetune_rate(
    ctx: &EvalContext,
    g: &GarmentData,
    out: &mut ExperimentOutput,
    net0: &Path,
) -> crate::Result<RateChoice> {
    let seed0 = g.seeds[0];
    let rate_dir = |lr: f64| g.models_of(seed0).join(format!("lr-{lr}")).join("trained-qs-mu0.1");
    let study = Study::sweep(
        finetune_rates(ctx.size).iter().copied(),
        |&lr| {
            train_one(
                ctx,
                g,
                out,
                &rate_dir(lr),
                &plan(
                    "trained-qs-mu0.1",
                    Layer::Quasistatic(0.1),
                    Some(net0),
                    g.base.finetune_epochs,
                ),
                &g.config_of(seed0, lr),
            )
        },
        |f| f.state.best_validation,
    )?;
    let rate_rows = study
        .trials()
        .iter()
        .map(|(lr, f)| {
            let path: Vec<String> = f.state.history.iter().map(|h| format!("{:.3}", h.validation)).collect();
            vec![
                format!("{lr}"),
                format!("{:.4}", f.state.initial_validation),
                path.join(" → "),
                format!("{} ({:.4})", f.state.best_epoch, f.state.best_validation),
            ]
        })
        .collect();
    let finetune_lr = *study.chosen();
    // The chosen rate's model is the first seed's `trained-qs-mu0.1`: the same stamp
    // (configuration, layer, starting weights) and epochs, so it is not trained twice.
    // Its directory is copied to the method's place, so that every seed's model
    // directories hold what the tables score.
    let (trials, chosen) = study.into_parts();
    let chosen_fit = trials.into_iter().nth(chosen).map(|(_, f)| f);
    let method_dir = g.models_of(seed0).join("trained-qs-mu0.1");
    start_from_copy(&rate_dir(finetune_lr), &method_dir)?;
    check_same_run(&rate_dir(finetune_lr), &method_dir)?;
    Ok(RateChoice {
        rows: rate_rows,
        rate: finetune_lr,
        fitted: chosen_fit,
    })
}

/// Every `trained-*` model per seed, fine-tuned from that seed's network at the chosen
/// rate; the first seed's `trained-qs-mu0.1` is the rate study's. Beside them the
/// equal-budget control [`CONTROL`]: the same fine-tune without a layer, so that a
/// `trained-*` model's gain over it is the layer's and not its extra epochs' (issue 72).
pub(super) fn trained_per_seed(
    ctx: &EvalContext,
    g: &GarmentData,
    out: &mut ExperimentOutput,
    networks: Vec<(u64, PathBuf, Fitted)>,
    rate: RateChoice,
) -> crate::Result<Vec<SeedRun>> {
    let seed0 = g.seeds[0];
    let mut chosen_fit = rate.fitted;
    let mut trainings: Vec<(String, Layer)> = vec![(CONTROL.into(), Layer::None), ("trained-socp".into(), Layer::Socp)];
    for (mu, suffix) in FIXED_MU {
        trainings.push((format!("trained-qs-{suffix}"), Layer::Quasistatic(mu)));
    }
    trainings.push((
        "trained-qs-per-vertex-mu".into(),
        Layer::LearnedMu {
            start: 0.1,
            per_vertex: true,
        },
    ));
    trainings.push((
        "trained-qs-learned-mu".into(),
        Layer::LearnedMu {
            start: 0.1,
            per_vertex: false,
        },
    ));
    let mut runs = Vec::new();
    for (seed, net_dir, net) in networks {
        let config = g.config_of(seed, rate.rate);
        let mut fitted = vec![("network-only".to_string(), net)];
        for (name, layer) in &trainings {
            let reused = (seed == seed0 && *layer == Layer::Quasistatic(0.1))
                .then(|| chosen_fit.take())
                .flatten();
            let f = match reused {
                Some(f) => f,
                None => {
                    let dir = g.models_of(seed).join(name);
                    let plan = plan(name, *layer, Some(&net_dir), g.base.finetune_epochs);
                    train_one(ctx, g, out, &dir, &plan, &config)?
                }
            };
            fitted.push((name.clone(), f));
        }
        runs.push(SeedRun { seed, fitted });
    }
    Ok(runs)
}

/// The μ study's table rows and where μ ended from each start.
pub(super) struct MuStudy {
    pub rows: Vec<Vec<String>>,
    pub final_mu: Vec<f64>,
}

/// The μ study (Geng et al. §6.2): the learned global μ from three starts, first seed,
/// fine-tuned from `net0` at `rate`; records each start's last μ.
pub(super) fn mu_study(
    ctx: &EvalContext,
    g: &GarmentData,
    out: &mut ExperimentOutput,
    runs: &[SeedRun],
    rate: f64,
    net0: &Path,
) -> crate::Result<MuStudy> {
    let (scene, seed0) = (g.scene, g.seeds[0]);
    let mut mu_rows = Vec::new();
    let mut final_mu = Vec::new();
    for (start, label) in MU_STARTS {
        let name = format!("learned-mu-from-{label}");
        let layer = Layer::LearnedMu {
            start,
            per_vertex: false,
        };
        let owned;
        let f: &Fitted = if label == "0.1" && g.mu_study_epochs == g.base.finetune_epochs {
            // The method's own model is this start's run.
            &runs[0]
                .fitted
                .iter()
                .find(|(n, _)| n == "trained-qs-learned-mu")
                .context("learned-μ model")?
                .1
        } else {
            let dir = g.models_of(seed0).join(&name);
            if label == "0.1" {
                // The method's model is this run's first epochs (the same stamp), so
                // the study continues it rather than train them again.
                start_from_copy(&g.models_of(seed0).join("trained-qs-learned-mu"), &dir)?;
            }
            owned = train_one(
                ctx,
                g,
                out,
                &dir,
                &plan(&name, layer, Some(net0), g.mu_study_epochs),
                &g.config_of(seed0, rate),
            )?;
            &owned
        };
        let kept = f.mu.as_ref().and_then(|m| m.first().copied()).unwrap_or(f64::NAN);
        let mus: Vec<f64> = f
            .state
            .history
            .iter()
            .filter_map(|h| h.extra.get("mu").copied())
            .collect();
        let path: Vec<String> = mus.iter().map(|&m| crate::records::three_significant(m)).collect();
        let last = mus.last().copied().unwrap_or(kept);
        out.record(scene, &name, "learned-mu", last, "1", Timing::default());
        if let Some(p) = paper_learned_mu(label) {
            out.paper(p);
        }
        // Whether μ has settled: its change per epoch over the last epochs (issue 72).
        if let Some(change) = change_per_epoch(start, &mus, MU_DRIFT_EPOCHS) {
            out.record(
                scene,
                &name,
                "learned-mu-change-per-epoch",
                change,
                "1",
                Timing::default(),
            );
        }
        final_mu.push(last);
        mu_rows.push(vec![
            format!("{start}"),
            paper_learned_mu(label).map_or("—".into(), |p| format!("{p}")),
            crate::records::three_significant(kept),
            format!("{}", f.state.best_epoch),
            crate::records::three_significant(last),
            path.join(" → "),
        ]);
    }
    Ok(MuStudy {
        rows: mu_rows,
        final_mu,
    })
}

/// Epochs over which the μ study's last change of μ is measured.
const MU_DRIFT_EPOCHS: usize = 5;

/// The mean relative change per epoch, `(μ_n / μ_{n−k})^{1/k} − 1`, over the last
/// `k = min(epochs, n)` of the `n` values in `path` (μ after each epoch), `start` being μ
/// before the first: a learned μ still moving has a change far from 0. `None` without
/// epochs or with a μ that is not positive.
fn change_per_epoch(start: f64, path: &[f64], epochs: usize) -> Option<f64> {
    let k = epochs.min(path.len());
    let last = *path.last()?;
    let before = if k == path.len() {
        start
    } else {
        path[path.len() - 1 - k]
    };
    (k > 0 && before > 0.0 && last > 0.0).then(|| (last / before).powf(1.0 / k as f64) - 1.0)
}

/// One seed's trained models (by method name) and its network alone.
pub(super) struct SeedRun {
    pub seed: u64,
    pub fitted: Vec<(String, Fitted)>,
}

/// Starts the model directory `to` as a copy of `from` (a model trained under the same
/// stamp for fewer epochs, which `fit` then continues), unless `to` already holds a
/// model or `from` does not. The copy is made beside `to` and renamed into place, so an
/// interrupted copy leaves no partial model.
pub(super) fn start_from_copy(from: &Path, to: &Path) -> crate::Result<()> {
    if to.exists() || !from.join("config.json").exists() {
        return Ok(());
    }
    let mut name = to.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    let partial = to.with_file_name(name);
    if partial.exists() {
        std::fs::remove_dir_all(&partial)?;
    }
    crate::files::copy_tree(from, &partial)?;
    std::fs::rename(&partial, to)?;
    Ok(())
}

/// Checks that the model directory `copy` holds the run of `run` (their training records
/// are the same bytes): a directory left by another run under the method's name is a
/// typed error naming both, never scored under the wrong name.
pub(super) fn check_same_run(run: &Path, copy: &Path) -> crate::Result<()> {
    let record = |dir: &Path| {
        let path = dir.join("training.json");
        std::fs::read(&path).with_context(|| format!("reading {}", path.display()))
    };
    if record(run)? != record(copy)? {
        return Err(crate::Error::Invalid(format!(
            "{} holds another run than the chosen fine-tuning rate's {}; move it away and rerun",
            copy.display(),
            run.display()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    #[test]
    fn the_change_of_mu_per_epoch_is_over_the_last_epochs_from_the_start_if_needed() {
        // The loose sleeve's start 1 (docs/DRAPE.md): 0.00796 at epoch 15, 0.00741 at 20.
        let mut path = vec![0.02; 15];
        path[14] = 0.00796;
        path.extend([0.0077, 0.0076, 0.0075, 0.0074, 0.00741]);
        let c = change_per_epoch(1.0, &path, 5).unwrap();
        assert!((c - ((0.00741f64 / 0.00796).powf(0.2) - 1.0)).abs() < 1e-12, "{c}");
        // Fewer epochs than the window: measured from the start.
        let c = change_per_epoch(1.0, &[0.5, 0.25], 5).unwrap();
        assert!((c + 0.5).abs() < 1e-12, "{c}");
        assert_eq!(change_per_epoch(1.0, &[], 5), None);
        assert_eq!(change_per_epoch(0.0, &[0.1], 5), None);
    }

    #[test]
    fn a_model_directory_is_copied_whole_once_and_never_over_a_model() {
        let root = std::env::temp_dir().join(format!("weft-drape-copy-{}", std::process::id()));
        let (from, to) = (root.join("trained-qs-learned-mu"), root.join("learned-mu-from-0.1"));
        let write = |path: &Path, text: &str| {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, text).unwrap();
        };
        // No model to copy yet: nothing is made.
        start_from_copy(&from, &to).unwrap();
        assert!(!to.exists());
        write(&from.join("config.json"), "stamp");
        write(&from.join("last/net/params.safetensors"), "weights");
        write(&from.join("best/net/state.json"), "best");
        // A partial copy left by an interrupted run is replaced.
        write(&root.join("learned-mu-from-0.1.partial/config.json"), "stale");
        start_from_copy(&from, &to).unwrap();
        let read = |path: PathBuf| std::fs::read_to_string(path).unwrap();
        assert_eq!(read(to.join("config.json")), "stamp");
        assert_eq!(read(to.join("last/net/params.safetensors")), "weights");
        assert_eq!(read(to.join("best/net/state.json")), "best");
        assert!(!root.join("learned-mu-from-0.1.partial").exists());
        // A model already there (being continued) is never overwritten.
        write(&from.join("last/net/params.safetensors"), "newer");
        write(&to.join("last/net/params.safetensors"), "continued");
        start_from_copy(&from, &to).unwrap();
        assert_eq!(read(to.join("last/net/params.safetensors")), "continued");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn the_method_directory_must_hold_the_chosen_rate_run() {
        let root = std::env::temp_dir().join(format!("weft-drape-same-run-{}", std::process::id()));
        let (run, copy) = (root.join("lr-0.0001"), root.join("trained-qs-mu0.1"));
        for dir in [&run, &copy] {
            std::fs::create_dir_all(dir).unwrap();
        }
        std::fs::write(run.join("training.json"), "lr 1e-4 history").unwrap();
        // No record in the method's directory: an error, not a pass.
        assert!(check_same_run(&run, &copy).is_err());
        // Another rate's run left there (the layout before the rate directories).
        std::fs::write(copy.join("training.json"), "lr 1e-3 history").unwrap();
        let message = check_same_run(&run, &copy).unwrap_err().to_string();
        assert!(
            message.contains("trained-qs-mu0.1") && message.contains("lr-0.0001"),
            "{message}"
        );
        std::fs::write(copy.join("training.json"), "lr 1e-4 history").unwrap();
        check_same_run(&run, &copy).unwrap();
        std::fs::remove_dir_all(&root).unwrap();
    }
}
