//! The embedding's latent simulator (Tan et al., weft-nn's `EmbedSurrogate`) in the
//! `guarded` experiment, beside the inertial predictor (issue 73: "keep the four existing
//! models as surrogates too and report each one's one-step error beside the predictor's").
//!
//! The model is the one the `embed` experiment under the same OUT reported as `ours` on
//! `sheet-ms` (its first seed at the λ_ephys chosen on validation); nothing is trained
//! here. Without it (the embed experiment not run, or its weights not kept) a note says so
//! and the rows are skipped. With it: the one-step M_rms on the dataset's test frames from
//! the true history (method `embed`, split `test`, the frames of the inertial rows), the
//! estimate's honesty on the held-out sequence, and one guarded roll-out at
//! [`TOLERANCE_MM`] (`embed-tau-1000um`).

use weft_data::{ClothDataset, is_train_frame};
use weft_nn::embed::{EmbedSurrogate, stage_dir};
use weft_sim::ClothScene;
use weft_sim::guard::{GuardSettings, StepInput, Surrogate};

use super::{GroundTruth, Rollout, SCENE, estimate_honesty, guarded_rollout, rms};
use crate::evaluate::context::EvalContext;
use crate::records::{ExperimentOutput, Timing};

/// The method's name in the records.
const METHOD: &str = "embed";

/// The one guarded roll-out's tolerance (mm) and its name, as on the dial.
const TOLERANCE_MM: f64 = 1.0;
const TOLERANCE_NAME: &str = "tau-1000um";

/// The embed surrogate's rows of the experiment (module docs); `rows` gets its row of the
/// guarded roll-outs' table.
pub(super) fn embed_rows(
    ctx: &EvalContext,
    out: &mut ExperimentOutput,
    data: &ClothDataset,
    scene: &ClothScene,
    truth: &GroundTruth,
    rows: &mut Vec<Vec<String>>,
) -> crate::Result<()> {
    let Some(dir) = trained_model(ctx) else {
        out.notes.push(
            "guarded: no embed model with its weights under OUT/embed (run the `embed` experiment first, e.g. \
             `--only embed,guarded`); the embed surrogate's rows are skipped"
                .into(),
        );
        return Ok(());
    };
    let mut surrogate = EmbedSurrogate::load(&dir, data.clone())?;
    let errors = one_step_errors(&mut surrogate, data)?;
    let embed = rms(&errors);
    out.record(SCENE, METHOD, "one-step-m-rms", embed, "mm", Timing::default());
    out.split("test");
    let inertial = out
        .records
        .iter()
        .find(|r| r.method == "inertial" && r.metric == "one-step-m-rms" && r.is_test())
        .map(|r| r.value);
    let verdict = match inertial {
        Some(i) if embed < i => format!("beats the inertial predictor's {i:.3} mm"),
        Some(i) => format!(
            "does not beat the inertial predictor's {i:.3} mm ({:.1}×): its reconstruction floor alone is above it",
            embed / i
        ),
        None => "no inertial row to compare".into(),
    };
    out.notes.push(format!(
        "guarded: the embed surrogate (OUT/{}) has a one-step M_rms of {embed:.3} mm on the {} test frames of {}, and \
         {verdict}",
        dir.strip_prefix(&ctx.out).unwrap_or(&dir).display(),
        errors.len(),
        data.name
    ));
    estimate_honesty(out, scene, truth, METHOD, Box::new(surrogate.clone()))?;
    let method = format!("{METHOD}-{TOLERANCE_NAME}");
    let run = Rollout {
        scene,
        truth,
        method: &method,
        predictions: &ctx.out.join("predictions").join("guarded").join(SCENE),
    };
    let settings = GuardSettings::millimetres(TOLERANCE_MM)?;
    rows.push(guarded_rollout(out, &run, Box::new(surrogate), Some(settings))?);
    Ok(())
}

/// The model the embed experiment reported as `ours` on the scene, if its weights are here.
fn trained_model(ctx: &EvalContext) -> Option<std::path::PathBuf> {
    let dir = crate::evaluate::embed::reported_model(&ctx.out, SCENE, "ours")?;
    let runs: Vec<_> = (1..=3)
        .map(|s| stage_dir(&dir, s))
        .filter(|r| weft_nn::trainer::has_run(r))
        .collect();
    (!runs.is_empty() && runs.iter().all(|r| weft_nn::trainer::has_checkpoints(r))).then_some(dir)
}

/// Each test frame's one-step M_rms (mm): the surrogate's proposal from the true history
/// (`p_{−1} = p_0`) and the frame's controls, against the true frame — the windows of the
/// inertial rows (`InertialCorrection::one_step_errors`, split `test`).
fn one_step_errors(surrogate: &mut EmbedSurrogate, data: &ClothDataset) -> crate::Result<Vec<f64>> {
    let mut errors = Vec::new();
    for (s, seq) in data.sequences.iter().enumerate() {
        for m in (1..seq.num_frames()).filter(|&m| !is_train_frame(m)) {
            let prescribed = data.prescribed_at(s, m);
            let input = StepInput {
                frame: m,
                dt: data.scene.dt,
                current: seq.frame(m - 1),
                previous: seq.frame(m.saturating_sub(2)),
                prescribed: &prescribed,
            };
            let x = surrogate
                .propose(&input)
                .map_err(|e| crate::Error::Failed(format!("guarded: embed at sequence {s}, frame {m}: {e}")))?;
            let mm: Vec<f64> = x.iter().zip(seq.frame(m)).map(|(a, b)| 1e3 * (a - b)).collect();
            errors.push(rms(&mm));
        }
    }
    Ok(errors)
}
