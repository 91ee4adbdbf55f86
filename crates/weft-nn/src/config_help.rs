//! The help on each model's training configuration file, shown after `--help` by the
//! command line that reads it: one line per field with its default and range. The fields
//! themselves, their defaults and checks are the `*TrainingConfig` types'; a test holds this
//! text to them.

/// The embed (`embed::EmbedTrainingSettings`) configuration file.
pub const EMBED: &str = "\
Configuration file (--config, JSON; omitted fields keep their defaults):
  autoencoder      {\"conv_layers\": 2, \"latent\": 128}: graph convolutions (1-16), latent width
  latent_hidden    [256, 256]: hidden widths of the latent simulator (1-65536 each)
  weights          {\"recon\": 1, \"vert\": 1, \"ephys\": 0.5, \"sim\": 1, \"mphys\": 0.5} (>= 0)
  adam             {\"learning_rate\": 1e-3, \"beta1\": 0.9, \"beta2\": 0.999, \"epsilon\": 1e-8}
  batch            8 windows per step
  epochs           [30, 30, 10]: epochs of stages 1, 2, 3 (0 skips a stage)
  seed             0
  phys_scale       \"curvature\" | \"inertial\": how L_phys is scaled against L_vert
  ephys_warmup     0: stage-1 epochs over which lambda_ephys ramps from 0
  schedule         {\"decay\": {\"kind\": \"constant\"}, \"warmup_epochs\": 0,
                    \"clip_grad_norm\": null, \"early_stopping_patience\": null}
                   decay kinds: constant | exponential {per_epoch} | reduce-on-plateau {factor, patience}
  fine_tune_learning_rate  null: stage 3's Adam learning rate (null: adam.learning_rate);
                   a model continued under another value keeps stages 1 and 2 and retrains stage 3
Validation: the last two training frames of every 17 (frames 10 and 11 mod 17).";

/// The NNWarp (`nnwarp::WarpTrainingSettings`) configuration file.
pub const NNWARP: &str = "\
Configuration file (--config, JSON; omitted fields keep their defaults, unknown ones are refused):
  hidden           []: hidden widths (empty: the paper's, 2 x 16, 3 x 16 for StVK; 1-4096 each)
  adam             {\"learning_rate\": 1e-3, \"beta1\": 0.9, \"beta2\": 0.999, \"epsilon\": 1e-8}
  batch            1024 node pairs per step
  epochs           10
  seed             0
  schedule         as for every model: decay (constant | exponential | reduce-on-plateau),
                   warmup_epochs, clip_grad_norm, early_stopping_patience
Validation: the pairs of the dataset's validation sequences.";

/// The Alt-ConvLSTM (`altconv::AltConvTrainingSettings`) configuration file.
pub const ALTCONV: &str = "\
Configuration file (--config, JSON; omitted fields keep their defaults, unknown ones are refused):
  hidden           [32, 64, 128, 64, 32]: cell widths (1-4096 each, at most 64 cells)
  steps            20 teacher-forced steps per sequence (sequences need steps + 1 frames)
  epochs           60
  batch            2 sequences per step
  adam             {\"learning_rate\": 1e-3, \"beta1\": 0.9, \"beta2\": 0.999, \"epsilon\": 1e-8}
  seed             0
  schedule         {\"decay\": {\"kind\": \"exponential\", \"per_epoch\": 0.995}, \"warmup_epochs\": 0,
                    \"clip_grad_norm\": null, \"early_stopping_patience\": null}
  recipe           {\"sampling_max\": 0, \"sampling_epochs\": [0, 0], \"curriculum_start\": 0,
                    \"curriculum_epochs\": 0, \"validation_rollout\": false}: scheduled sampling
                   (feed the model's own previous prediction back with a probability rising to
                   sampling_max over those epochs), a window growing from curriculum_start steps
                   to steps, and validation scored as a roll-out; off by default
Validation: Eq. 12 on the dataset's validation sequences over `steps` steps, teacher-forced
(or rolled out with recipe.validation_rollout); the best epoch's weights are kept.";

/// The drape (`drape::DrapeTrainingSettings`) configuration file.
pub const DRAPE: &str = "\
Configuration file (--config, JSON; omitted fields keep the standard evaluation's values,
unknown ones are refused):
  net              {\"hidden\": [64, 256], \"offset_scale\": 0.01}
  pretrain_epochs  200 (network-only)      finetune_epochs  5 (with --init)
  batch            16                      learning_rate    1e-3
  mu_learning_rate 0.1 (Adam on log mu)    epsilon          0.1 (inextensibility bound)
  quasistatic      the quasistatic layer's spring stiffnesses
  seed             1
  schedule         decay (constant | exponential | reduce-on-plateau), warmup_epochs,
                   clip_grad_norm, early_stopping_patience
Validation: mean SqrtMSE over the dataset's validation examples.";

/// The nonlinear inertial correction (`inertial_correction_mlp::InertialCorrectionMlpSettings`)
/// configuration file.
pub const INERTIAL_CORRECTION_MLP: &str = "\
Configuration file (--config, JSON; omitted fields keep their defaults, unknown ones are refused):
  linear           {\"position_components\": 32, \"correction_components\": 32,
                    \"ridge\": [1e-8, 1e-6, 1e-4, 1e-2, 1]}: the linear correction whose features,
                   basis and clip the network shares (`train inertial-correction`'s settings)
  base             \"linear\" | \"predictor\": what the network adds to (the linear correction's
                   codes, or nothing)
  hidden           [128, 128]: hidden widths (1-65536 each)
  adam             {\"learning_rate\": 1e-3, \"beta1\": 0.9, \"beta2\": 0.999, \"epsilon\": 1e-8}
  batch            16 windows per step
  epochs           200
  seed             0
  schedule         as for every model: decay (constant | exponential | reduce-on-plateau),
                   warmup_epochs, clip_grad_norm; early_stopping_patience 30
Validation: one-step M_rms (mm) of the validation frames (10 and 11 mod 17) from the true
history; the best epoch's weights are kept (epoch 0 is the base model).";

#[cfg(test)]
mod tests {
    /// `train embed --help` lists every field a configuration file may set (the kernels
    /// are the `--autograd` flag's).
    #[test]
    fn the_embed_configuration_help_names_every_field() {
        let config = crate::embed::EmbedTrainingSettings {
            fine_tune_learning_rate: Some(1e-4),
            ..Default::default()
        };
        let fields = serde_json::to_value(&config).unwrap();
        for key in fields.as_object().unwrap().keys().filter(|k| *k != "kernels") {
            assert!(super::EMBED.contains(&format!("  {key} ")), "{key} is not in the help");
        }
    }

    #[test]
    fn the_inertial_correction_mlp_configuration_help_names_every_field() {
        let config = crate::inertial_correction_mlp::InertialCorrectionMlpSettings::default();
        let fields = serde_json::to_value(&config).unwrap();
        for key in fields.as_object().unwrap().keys() {
            assert!(
                super::INERTIAL_CORRECTION_MLP.contains(&format!("  {key} ")),
                "{key} is not in the help"
            );
        }
    }
}
