//! The `nnwarp` dataset (NNWarp §3.2 and §5): damped quasi-static linear sequences on the
//! training beam, scaled into the unit sphere and clamped at its −x end, each registered
//! (Eq. 6–7) to the co-rotational, StVK and Neo-Hookean materials by
//! `weft_sim::warp::register_sequence`.
//!
//! Sequence `i` is directional unless `i % 4 == 3` (a quarter are circular), so every
//! split holds both kinds. A directional field points along
//! `[sin β cos α, cos β, sin β sin α]` with `α, β` uniform on `[0, π/2]` (§5); a circular
//! one turns about an axis through the clamped face's centre, the axis drawn the same way.
//! The Poisson ratio is uniform on `[0.2, 0.45]`, since the network takes ν as an input.
//! All draws come from the sequence's seed.

use std::collections::HashMap;

use crate::error::Context;
use nalgebra::Vector3;
use weft_mesh::TetMesh;
use weft_sim::energies::Material;
use weft_sim::rng::SplitMix64;
use weft_sim::warp::{FieldDirection, SequenceSettings, register_sequence, unit_sphere_normalization};

use crate::files::Array;
use crate::spec::{DatasetSpec, StoredSequence};

/// The dataset's name.
pub const NAME: &str = crate::spec::NNWARP;

/// The revision of what the dataset stores (the manifest's `revision`). 2: the linear
/// frames are solved in the runtime's regime (loads turned into the rest frames by the
/// previous frame's rotations, `weft_sim::warp::RestFrameSolve`) and every sequence
/// records where each material's registrations left their branch (`off_branch`); the
/// unrevised datasets (absent, read as 0) registered plain-load solves (issue 70).
pub const REVISION: u32 = 2;

/// The materials every linear frame is registered to, in the stored order.
pub const MATERIALS: [Material; 3] = [Material::CoRotational, Material::StVK, Material::NeoHookean];

/// The array name of a material's registered displacements.
pub fn material_key(m: Material) -> &'static str {
    match m {
        Material::CoRotational => "co-rotational",
        Material::StVK => "stvk",
        Material::NeoHookean => "neo-hookean",
        Material::Linear => "linear",
    }
}

/// The training beam scaled into the unit sphere, and its clamped nodes (the −x face).
pub fn training_body(spec: &DatasetSpec) -> crate::Result<(TetMesh, Vec<usize>)> {
    let weft_sim::AnyScene::Volume(scene) = &spec.scene else {
        return Err(crate::Error::Invalid(
            "the nnwarp dataset is built on a volumetric scene".into(),
        ));
    };
    let mesh = scene.build_mesh(None)?;
    let (center, scale) = unit_sphere_normalization(mesh.positions());
    let unit = TetMesh::new(
        mesh.positions().iter().map(|p| (p - center) * scale).collect(),
        mesh.tets().to_vec(),
    )?;
    let x_min = unit.positions().iter().map(|p| p.x).fold(f64::INFINITY, f64::min);
    let anchors = (0..unit.num_vertices())
        .filter(|&i| (unit.positions()[i].x - x_min).abs() < 1e-9)
        .collect();
    Ok((unit, anchors))
}

/// The force field and Poisson ratio of sequence `i` drawn from its seed.
pub fn sequence_field(body: &TetMesh, anchors: &[usize], seed: u64, i: usize) -> (FieldDirection, f64) {
    let mut rng = SplitMix64::new(seed);
    let quarter = std::f64::consts::FRAC_PI_2;
    let alpha = quarter * rng.unit();
    let beta = quarter * rng.unit();
    let e = Vector3::from(weft_sim::energies::hemisphere_direction(alpha, beta));
    let poisson = 0.2 + 0.25 * rng.unit();
    let field = if i % 4 == 3 {
        let center = anchors.iter().map(|&a| body.positions()[a]).sum::<Vector3<f64>>() / anchors.len().max(1) as f64;
        FieldDirection::Circular { center, axis: e }
    } else {
        FieldDirection::Directional(e)
    };
    (field, poisson)
}

fn field_json(field: FieldDirection) -> serde_json::Value {
    match field {
        FieldDirection::Directional(d) => serde_json::json!({"kind": "directional", "direction": [d.x, d.y, d.z]}),
        FieldDirection::Circular { center, axis } => serde_json::json!({
            "kind": "circular",
            "center": [center.x, center.y, center.z],
            "axis": [axis.x, axis.y, axis.z],
        }),
    }
}

/// Per material, where its registrations left the sequence's branch
/// (`weft_sim::warp::OffBranch`), or null: `{"co-rotational": {"frame": 23, "inverted": 2,
/// "warp_error": [0.04, 0.23]}, "stvk": null, ...}`. The reader drops a material's frames
/// from `frame` on.
fn off_branch_json(off: &[Option<weft_sim::warp::OffBranch>]) -> serde_json::Value {
    MATERIALS
        .iter()
        .zip(off)
        .map(|(m, o)| {
            let v = o.map_or(
                serde_json::Value::Null,
                |o| serde_json::json!({"frame": o.frame, "inverted": o.inverted, "warp_error": o.warp_error}),
            );
            (material_key(*m).to_string(), v)
        })
        .collect::<serde_json::Map<_, _>>()
        .into()
}

/// Generates sequence `i` (seeded by `seed`, the sequence's own seed).
pub fn sequence(spec: &DatasetSpec, seed: u64, i: usize) -> crate::Result<StoredSequence> {
    let (body, anchors) = training_body(spec)?;
    let (field, poisson) = sequence_field(&body, &anchors, seed, i);
    let settings = SequenceSettings {
        ramp_frames: spec.frames,
        ..SequenceSettings::default()
    };
    let start = std::time::Instant::now();
    let seq = register_sequence(&body, &anchors, field, poisson, &MATERIALS, settings)
        .with_context(|| format!("nnwarp sequence {i}"))?;
    let seconds = start.elapsed().as_secs_f64();
    let (f, v) = (seq.linear.len(), body.num_vertices());
    let mut arrays = vec![
        Array::f64("accelerations", vec![f], &seq.accelerations),
        Array::f64("linear", vec![f, v, 3], &seq.linear.concat()),
    ];
    for (m, frames) in MATERIALS.iter().zip(&seq.nonlinear) {
        arrays.push(Array::f64(material_key(*m), vec![f, v, 3], &frames.concat()));
    }
    let mut metadata = HashMap::new();
    metadata.insert("field".into(), field_json(field).to_string());
    metadata.insert("poisson".into(), format!("{poisson}"));
    metadata.insert("young".into(), format!("{}", settings.young));
    metadata.insert("anchors".into(), serde_json::to_string(&anchors)?);
    metadata.insert("newton_iterations".into(), seq.newton_iterations.to_string());
    metadata.insert("off_branch".into(), off_branch_json(&seq.off_branch).to_string());
    metadata.insert(
        "units".into(),
        "linear and per-material displacements [frames, vertices, 3] of the training beam scaled into the unit \
         sphere (rest.node); accelerations [frames] the field's magnitude (m/s²) per frame, frame 0 at rest"
            .into(),
    );
    Ok(StoredSequence {
        arrays,
        metadata,
        frames: f,
        solver_seconds: seconds,
        simulated_frames: f - 1,
        error: seq.error,
    })
}
