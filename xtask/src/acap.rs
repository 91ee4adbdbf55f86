//! `cargo xtask acap`: ACAP features of meshes to `.npy`, and back to OBJ meshes.
//!
//! The work is weft-acap's (`AcapFeatures`, `PoissonPseudoInverse`) and the array files
//! weft-data's (`weft_data::arrays`); this module wires them together and shows progress.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail, ensure};
use indicatif::{ProgressBar, ProgressStyle};
use weft_acap::nalgebra::Vector3;
use weft_acap::{AcapFeatures, AcapSettings, PoissonPseudoInverse};
use weft_data::arrays::{
    pin_file, read_features, read_pin_positions, read_pin_record, read_safetensors_frames, safetensors_metadata,
    write_features,
};
use weft_mesh::TriMesh;

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
    let pins: Vec<usize> = if pins.is_empty() {
        let text = safetensors_metadata(&path, "grasp_vertices")?
            .context("no --pin given and no grasp_vertices in the frames' metadata")?;
        serde_json::from_str(&text).with_context(|| format!("grasp_vertices metadata {text:?}"))?
    } else {
        pins.to_vec()
    };
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

fn rest_mesh(path: &Path) -> Result<TriMesh> {
    let file = if path.is_dir() {
        path.join("rest.obj")
    } else {
        path.to_path_buf()
    };
    weft_mesh::io::read_obj(&file).with_context(|| format!("reading rest mesh {}", file.display()))
}

fn encode(rest_path: &Path, meshes: &[PathBuf], out: &Path, pins: &[usize], sequence: bool) -> Result<()> {
    let rest = rest_mesh(rest_path)?;
    let nv = rest.num_vertices();
    let mut frames: Vec<Vec<Vector3<f64>>> = Vec::new();
    if rest_path.is_dir() {
        frames.extend(read_safetensors_frames(&rest_path.join("frames.safetensors"), nv)?);
    }
    for m in meshes {
        let mesh = weft_mesh::io::read_obj(m).with_context(|| format!("reading {}", m.display()))?;
        ensure!(
            mesh.faces() == rest.faces(),
            "{} does not have the rest mesh's connectivity ({} faces vs {})",
            m.display(),
            mesh.num_faces(),
            rest.num_faces()
        );
        frames.push(mesh.positions().to_vec());
    }
    ensure!(
        !frames.is_empty(),
        "nothing to encode: give --mesh files or a simulate directory as --rest"
    );
    for (k, &p) in pins.iter().enumerate() {
        ensure!(p < nv, "pin {p} is out of range for {nv} vertices");
        ensure!(!pins[..k].contains(&p), "vertex {p} is pinned twice in --pin");
    }

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
    let recorded = read_pin_record(features_path)?;
    let pins: Vec<usize> = if !pins.is_empty() {
        pins.to_vec()
    } else if let Some(r) = &recorded {
        r.pins.clone()
    } else {
        bail!(
            "no --pin given and no {} from `acap encode`",
            pin_file(features_path, "json").display()
        )
    };
    let per_frame_pins: Vec<Vec<Vector3<f64>>> = match pin_positions {
        Some(text) => {
            let xyz = parse_pin_positions(text)?;
            ensure!(
                xyz.len() == pins.len(),
                "{} pin positions for {} pins",
                xyz.len(),
                pins.len()
            );
            vec![xyz; frames]
        }
        None => {
            let r = recorded.as_ref().with_context(|| {
                format!(
                    "no --pin-positions given and no {}",
                    pin_file(features_path, "json").display()
                )
            })?;
            ensure!(
                r.pins == pins,
                "--pin {pins:?} differs from the pins {:?} recorded at encode time",
                r.pins
            );
            read_pin_positions(features_path, frames, pins.len())?
        }
    };

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

/// `x,y,z;x,y,z;...` → points.
fn parse_pin_positions(text: &str) -> Result<Vec<Vector3<f64>>> {
    text.split(';')
        .filter(|s| !s.trim().is_empty())
        .map(|triple| {
            let c: Vec<f64> = triple
                .split(',')
                .map(|v| {
                    v.trim()
                        .parse::<f64>()
                        .with_context(|| format!("bad coordinate {v:?} in {triple:?}"))
                })
                .collect::<Result<_>>()?;
            ensure!(c.len() == 3, "pin position {triple:?} must have 3 coordinates");
            Ok(Vector3::new(c[0], c[1], c[2]))
        })
        .collect()
}
