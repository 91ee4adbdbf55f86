//! The embedding's latent simulator as a guard surrogate (`weft_nn::embed::EmbedSurrogate`,
//! docs/GUARD.md): one proposal is one step of `LatentRollout` from the encoded accepted
//! frames, and a surrogate of another scene or mesh is refused with a typed error.

use std::sync::Arc;

use weft_nn::embed::{EmbedData, EmbedModel, EmbedSurrogate, EmbedTrainingSettings, FrameRef, LatentRollout};
use weft_sim::guard::{Guard, GuardSettings, StepInput, Surrogate};
use weft_sim::{ClothScene, ClothSimulation, Error as SimError};

use crate::base::{quick_sheet_dataset, small_embed_config};

const FRAMES: usize = 20;

/// A one-epoch-per-stage embedding of the quick sheet trained into a temporary directory,
/// with its data and the directory `name` (removed by the caller).
fn trained(name: &str) -> (EmbedData, EmbedModel, std::path::PathBuf) {
    let data = EmbedData::new(quick_sheet_dataset(FRAMES)).unwrap();
    let config = EmbedTrainingSettings {
        epochs: [1, 1, 1],
        ..small_embed_config()
    };
    let dir = std::env::temp_dir().join(format!("weft-nn-embed-surrogate-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (model, _) =
        weft_nn::embed::train_model(&dir, &data, &config, &[1, 2, 3], &mut weft_nn::trainer::Silent).unwrap();
    (data, model, dir)
}

#[test]
fn a_proposal_is_one_latent_rollout_step_from_the_encoded_accepted_frames() {
    let (data, model, dir) = trained("step");
    // Loaded from the directory on a fresh copy of the dataset, as the experiment does.
    let mut surrogate = EmbedSurrogate::load(&dir, quick_sheet_dataset(FRAMES)).unwrap();
    let seq = &data.dataset.sequences[0];
    let mut checked = 0;
    for m in 2..FRAMES {
        let start = [
            FrameRef {
                sequence: 0,
                frame: m - 2,
            },
            FrameRef {
                sequence: 0,
                frame: m - 1,
            },
        ];
        let codes = model.codes(&data, &start).unwrap();
        let mut rollout = LatentRollout::new(
            &model.autoencoder,
            &model.simulator,
            data.inverse.clone(),
            data.normalization.clone(),
            &codes[0],
            &codes[1],
        )
        .unwrap();
        let expect = rollout.step(seq.control(m)).unwrap();
        // The prescribed DOFs in reverse: the surrogate orders them by its pins itself.
        let mut prescribed = data.dataset.prescribed_at(0, m);
        prescribed.reverse();
        let input = StepInput {
            frame: m,
            dt: data.dataset.scene.dt,
            current: seq.frame(m - 1),
            previous: seq.frame(m - 2),
            prescribed: &prescribed,
        };
        let got = surrogate.propose(&input).unwrap();
        assert_eq!(got.len(), expect.len());
        let worst = got
            .iter()
            .zip(&expect)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f64, f64::max);
        assert!(worst <= 1e-9, "frame {m}: {worst:e} m from the roll-out's step");
        // The frames' order matters: swapped, the step is another one.
        let swapped = surrogate
            .predict(input.current, input.previous, seq.control(m))
            .unwrap();
        let moved = swapped
            .iter()
            .zip(&expect)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f64, f64::max);
        checked += usize::from(moved > 1e-6);
    }
    assert!(
        checked > FRAMES / 2,
        "swapping the frames changed only {checked} proposals"
    );
    // Every grasped DOF is needed: one missing is the surrogate's typed error.
    let prescribed = data.dataset.prescribed_at(0, 5);
    let input = StepInput {
        frame: 5,
        dt: data.dataset.scene.dt,
        current: seq.frame(4),
        previous: seq.frame(3),
        prescribed: &prescribed[1..],
    };
    let err = surrogate.propose(&input).unwrap_err();
    assert!(
        matches!(
            err.downcast_ref::<weft_nn::Error>(),
            Some(weft_nn::Error::InvalidParameter { name: "controls", .. })
        ),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_surrogate_of_another_scene_or_mesh_is_refused_by_the_guard() {
    let (data, model, dir) = trained("mismatch");
    let surrogate = EmbedSurrogate::new(Arc::new(model), &data);
    let quick = ClothScene::builtin("sheet-ms", true).unwrap();
    let sim = ClothSimulation::new(quick.clone(), None).unwrap();
    let guard = |scene: &str, integrator: &weft_sim::ImplicitEuler| {
        Guard::new(
            integrator,
            scene,
            Box::new(surrogate.clone()),
            GuardSettings::ground_truth(),
        )
    };
    assert!(guard(&quick.name, sim.integrator()).is_ok());
    let err = guard("sheet-fem", sim.integrator()).unwrap_err();
    assert!(
        matches!(err, SimError::SurrogateMismatch { what: "scene", .. }),
        "{err}"
    );
    // The standard-size sheet: another mesh.
    let full = ClothSimulation::new(ClothScene::builtin("sheet-ms", false).unwrap(), None).unwrap();
    let err = guard(&quick.name, full.integrator()).unwrap_err();
    assert!(
        matches!(
            err,
            SimError::SurrogateMismatch {
                what: "mesh DOF count",
                ..
            }
        ),
        "{err}"
    );
    // A directory without a trained model is a typed error, not a panic.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert!(EmbedSurrogate::load(&empty, quick_sheet_dataset(FRAMES)).is_err());
    std::fs::remove_dir_all(&dir).ok();
}
