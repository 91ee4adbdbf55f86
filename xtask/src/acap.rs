//! `cargo xtask acap`: ACAP features of meshes to `.npy`, and back to OBJ meshes.
//!
//! The work is weft-acap's (`AcapFeatures`, `PoissonPseudoInverse`) and the array files
//! weft-data's (`weft_data::arrays`); this module wires them together and shows progress.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use weft_acap::{AcapFeatures, AcapSettings, PoissonPseudoInverse};
use weft_data::acap_files::{decode_pins, frames_to_encode, rest_mesh, round_trip_pins};
use weft_data::arrays::{read_features, read_safetensors_frames, write_features};

/// ACAP features (Tan et al. §III-A) and their inverse (§IV-A, Eq. 6).
#[derive(Debug, clap::Subcommand)]
pub enum AcapCommand {
    /// Encode deformed meshes into ACAP features: an f64 .npy of shape [frames, vertices, 9]
    /// holding (K12, K13, K23, S11, S12, S13, S22, S23, S33) per vertex (docs/ACAP.md).
    Encode {
        /// Rest mesh (.obj), or a `simulate` output directory holding `rest.obj` and
        /// `frames.safetensors` (an f64 tensor `positions` of shape [frames, vertices, 3]),
        /// whose frames are then encoded before any --mesh.
        #[arg(long, value_name = "REST.obj|DIR")]
        rest: PathBuf,
        /// A deformed mesh (.obj) with the rest mesh's connectivity; repeat for several frames.
        #[arg(long = "mesh", value_name = "DEF.obj")]
        meshes: Vec<PathBuf>,
        /// Output features (.npy, [frames, vertices, 9], f64).
        #[arg(long, value_name = "F.npy")]
        out: PathBuf,
        /// Grasp-point vertex indices, comma-separated (e.g. `--pin 0,64`). Their positions in
        /// every frame are written beside the output as F.pins.npy ([frames, pins, 3], f64)
        /// and F.pins.json, so `acap decode` can place them where the input had them.
        #[arg(long, value_name = "I,J,...", value_delimiter = ',')]
        pin: Vec<usize>,
        /// Treat the frames as a time sequence: seed each frame's log-rotations from the
        /// previous frame so they do not jump when a rotation passes π (encoded serially).
        #[arg(long)]
        sequence: bool,
    },
    /// Decode ACAP features back to meshes: one OBJ per frame in the output directory.
    Decode {
        /// Rest mesh (.obj) the features were computed against, or a `simulate` output
        /// directory holding `rest.obj`.
        #[arg(long, value_name = "REST.obj|DIR")]
        rest: PathBuf,
        /// Features (.npy, [frames, vertices, 9] or [vertices, 9], f64; f32 is widened).
        #[arg(long, value_name = "F.npy")]
        features: PathBuf,
        /// Pinned vertex indices, comma-separated. Default: the pins recorded by `acap encode`
        /// in F.pins.json.
        #[arg(long, value_name = "I,J,...", value_delimiter = ',')]
        pin: Vec<usize>,
        /// Pin positions for every frame, `x,y,z;x,y,z;...` in metres, one triple per pin.
        /// Default: the per-frame positions recorded by `acap encode` in F.pins.npy.
        #[arg(long, value_name = "X,Y,Z;...", allow_hyphen_values = true)]
        pin_positions: Option<String>,
        /// Output directory; frame k is written as frame_<k>.obj (created if missing).
        #[arg(long, value_name = "DIR")]
        out_dir: PathBuf,
    },
    /// Measure the ACAP⁻¹(ACAP(p)) round trip on a `simulate` output directory: encode every
    /// frame, decode it with only the pins fixed, and print max and RMS vertex error over the
    /// bounding-box diagonal as JSON (per frame and worst case).
    Roundtrip {
        /// A `simulate` output directory (rest.obj, frames.safetensors).
        #[arg(long, value_name = "DIR")]
        sim: PathBuf,
        /// Pinned vertices, comma-separated (default: the scene's grasp vertices from the
        /// safetensors metadata).
        #[arg(long, value_name = "I,J,...", value_delimiter = ',')]
        pin: Vec<usize>,
    },
}

/// Runs one `acap` subcommand.
pub fn run(cmd: AcapCommand) -> Result<()> {
    match cmd {
        AcapCommand::Encode {
            rest,
            meshes,
            out,
            pin,
            sequence,
        } => encode(&rest, &meshes, &out, &pin, sequence),
        AcapCommand::Decode {
            rest,
            features,
            pin,
            pin_positions,
            out_dir,
        } => decode(&rest, &features, &pin, pin_positions.as_deref(), &out_dir),
        AcapCommand::Roundtrip { sim, pin } => roundtrip(&sim, &pin),
    }
}

fn roundtrip(dir: &Path, pins: &[usize]) -> Result<()> {
    let rest = rest_mesh(dir)?;
    let path = dir.join("frames.safetensors");
    let frames = read_safetensors_frames(&path, rest.num_vertices())?;
    let pins = round_trip_pins(&path, pins)?;
    let features = AcapFeatures::new(&rest, AcapSettings::default())?;
    let bar = progress(frames.len() as u64, "round trip");
    let round_trip = weft_acap::frames::round_trip(&features, &frames, &pins, || bar.inc(1))?;
    bar.finish_and_clear();
    let mut report = serde_json::to_value(round_trip)?;
    report["sim"] = serde_json::to_value(dir)?;
    report["vertices"] = rest.num_vertices().into();
    report["frames"] = frames.len().into();
    report["pins"] = serde_json::to_value(&pins)?;
    report["units"] = "fractions of the frame's bounding-box diagonal".into();
    outln!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

fn encode(rest_path: &Path, meshes: &[PathBuf], out: &Path, pins: &[usize], sequence: bool) -> Result<()> {
    let rest = rest_mesh(rest_path)?;
    let nv = rest.num_vertices();
    let frames = frames_to_encode(rest_path, &rest, meshes, pins)?;
    let acap = AcapFeatures::new(&rest, AcapSettings::default()).context("precomputing ACAP on the rest mesh")?;
    let bar = progress(frames.len() as u64, "encoding");
    let features = weft_acap::frames::encode_frames(&acap, &frames, sequence, |n| bar.inc(n))?;
    bar.finish();

    let positions = frames
        .iter()
        .flat_map(|p| pins.iter().flat_map(move |&i| [p[i].x, p[i].y, p[i].z]));
    write_features(out, &features, pins, positions)?;
    outln!(
        "wrote {} frames × {} vertices × 9 features to {}",
        frames.len(),
        nv,
        out.display()
    );
    Ok(())
}

fn decode(
    rest_path: &Path,
    features_path: &Path,
    pins: &[usize],
    pin_positions: Option<&str>,
    out_dir: &Path,
) -> Result<()> {
    let rest = rest_mesh(rest_path)?;
    let nv = rest.num_vertices();
    let features = read_features(features_path, nv)?;
    let frames = features.len();
    let (pins, per_frame_pins) = decode_pins(features_path, frames, pins, pin_positions)?;
    let acap = AcapFeatures::new(&rest, AcapSettings::default()).context("precomputing ACAP on the rest mesh")?;
    let inverse = PoissonPseudoInverse::new(&acap, &pins).context("factorising the pinned Poisson system")?;
    fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let bar = progress(frames as u64, "decoding");
    for (k, (f, x)) in features.iter().zip(&per_frame_pins).enumerate() {
        let p = inverse.decode(f, x).with_context(|| format!("decoding frame {k}"))?;
        let path = out_dir.join(format!("frame_{k:05}.obj"));
        weft_mesh::io::write_obj(&path, &p, rest.faces()).with_context(|| format!("writing {}", path.display()))?;
        bar.inc(1);
    }
    bar.finish();
    outln!("wrote {frames} meshes to {}", out_dir.display());
    Ok(())
}

fn progress(len: u64, what: &'static str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template("{msg} {bar:40} {pos}/{len} frames [{elapsed_precise}]") {
        bar.set_style(style);
    }
    bar.set_message(what);
    bar
}
