//! Layers against per-vertex loops, custom ops against
//! finite differences of the f64 physics, the stop-gradient of Eq. 9–10, checkpoint round
//! trips, and a training smoke test on the quick sheet.

use std::sync::Arc;

use candle_core::{DType, Device, Tensor, Var};
use nalgebra::Vector3;
use weft_acap::{AcapFeatures, AcapSettings, FeatureNormalization, PoissonPseudoInverse};
use weft_nn::adam::{Adam, AdamSettings};
use weft_nn::embed::{AutoencoderSettings, MeshAutoencoder};
use weft_nn::graph::MeshGraph;
use weft_nn::layers::GraphConv;
use weft_nn::ops::{AcapInverse, LPhys};
use weft_nn::params::ParamStore;
use weft_nn::{Error, checkpoint};
use weft_sim::{ClothScene, ClothSimulation};
use weft_testkit::{TestRng, max_norm_rel_error};

fn cpu() -> Device {
    Device::Cpu
}

fn to_vec3(t: &Tensor) -> Vec<f32> {
    t.flatten_all().unwrap().to_vec1().unwrap()
}

#[test]
fn graph_conv_matches_a_per_vertex_loop_and_its_weights_do_not_depend_on_the_mesh() {
    let small = weft_mesh::generators::sheet(4, 1.0).unwrap();
    let big = weft_mesh::generators::sheet(7, 1.0).unwrap();
    let mut counts = Vec::new();
    for mesh in [&small, &big] {
        let graph = Arc::new(MeshGraph::new(mesh, &cpu()).unwrap());
        let mut params = ParamStore::new(&cpu(), 5);
        let conv = GraphConv::new(&mut params, "c", graph, 3, 2).unwrap();
        counts.push(params.num_parameters());
        let v = mesh.num_vertices();
        let mut rng = TestRng::new(1);
        let x: Vec<f32> = (0..2 * v * 3).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let xt = Tensor::from_vec(x.clone(), (2, v, 3), &cpu()).unwrap();
        let y = to_vec3(&conv.forward(&xt).unwrap());
        let m = to_vec3(params.vars()["c.m"].as_tensor());
        let mn = to_vec3(params.vars()["c.m_n"].as_tensor());
        let topo = weft_mesh::Topology::new(mesh);
        for b in 0..2 {
            for i in 0..v {
                let nb = topo.one_ring.neighbors(i);
                for o in 0..2 {
                    let mut expect = 0.0f64;
                    for c in 0..3 {
                        let mean = nb.iter().map(|&j| x[(b * v + j) * 3 + c] as f64).sum::<f64>() / nb.len() as f64;
                        expect += m[c * 2 + o] as f64 * x[(b * v + i) * 3 + c] as f64 + mn[c * 2 + o] as f64 * mean;
                    }
                    let got = y[(b * v + i) * 2 + o] as f64;
                    assert!(
                        (got - expect).abs() < 1e-5,
                        "b {b} vertex {i} out {o}: {got} vs {expect}"
                    );
                }
            }
        }
    }
    assert_eq!(
        counts[0], counts[1],
        "parameter count must not depend on the vertex count"
    );
    assert_eq!(counts[0], 3 * 2 + 3 * 2 + 2);
}

/// A 5 × 5 sheet, its extractor, the pseudo-inverse pinned at two corners, a per-block
/// normalisation, and normalised features of three deformed frames.
struct AcapCase {
    inverse: Arc<PoissonPseudoInverse>,
    normalization: FeatureNormalization,
    features: Vec<f32>,
    pins: Vec<Vec<Vector3<f64>>>,
    v: usize,
}

fn acap_case() -> AcapCase {
    let n = 5;
    let sheet = weft_mesh::generators::sheet(n, 1.0).unwrap();
    let acap = AcapFeatures::new(&sheet, AcapSettings::default()).unwrap();
    let pin_ids = vec![0, n - 1];
    let inverse = Arc::new(PoissonPseudoInverse::new(&acap, &pin_ids).unwrap());
    let frames: Vec<Vec<Vector3<f64>>> = [0.4, 0.9, 1.4]
        .iter()
        .map(|&a: &f64| {
            sheet
                .positions()
                .iter()
                .map(|q| {
                    let t = a * (q.x + 0.5);
                    Vector3::new(q.x, q.y * t.cos(), q.y * t.sin() + 0.1 * q.x * q.x)
                })
                .collect()
        })
        .collect();
    let feats = acap.encode_batch(&frames).unwrap();
    let normalization = FeatureNormalization::fit_per_block(feats.iter().flatten()).unwrap();
    let features: Vec<f32> = feats
        .iter()
        .flat_map(|f| normalization.normalize_all(f))
        .flat_map(|f| f.map(|x| x as f32))
        .collect();
    let pins = frames.iter().map(|p| pin_ids.iter().map(|&i| p[i]).collect()).collect();
    AcapCase {
        inverse,
        normalization,
        features,
        pins,
        v: n * n,
    }
}

#[test]
fn acap_inverse_op_decodes_like_weft_acap_and_its_gradient_matches_finite_differences() {
    let c = acap_case();
    let op = AcapInverse::new(c.inverse.clone(), c.normalization.clone(), c.pins.clone());
    let x = Var::from_vec(c.features.clone(), (3, c.v, 9), &cpu()).unwrap();
    let p = op.apply(x.as_tensor()).unwrap();
    // Forward: the f64 decode of the same (f32-rounded) features.
    let f64_loss = |flat: &[f64]| -> (Vec<f64>, f64) {
        let mut all = Vec::new();
        for b in 0..3 {
            let frame: Vec<[f64; 9]> = flat[b * c.v * 9..(b + 1) * c.v * 9]
                .chunks_exact(9)
                .map(|f| c.normalization.denormalize(&std::array::from_fn(|d| f[d])))
                .collect();
            let dec = c.inverse.decode(&frame, &c.pins[b]).unwrap();
            all.extend(dec.iter().flat_map(|q| [q.x, q.y, q.z]));
        }
        let loss = all
            .iter()
            .enumerate()
            .map(|(i, v)| (0.3 + (i as f64 * 0.7).sin()) * v)
            .sum();
        (all, loss)
    };
    let x64: Vec<f64> = c.features.iter().map(|&v| v as f64).collect();
    let (reference, _) = f64_loss(&x64);
    let got: Vec<f64> = to_vec3(&p).iter().map(|&v| v as f64).collect();
    assert!(max_norm_rel_error(&got, &reference) < 1e-6);
    // Backward of Σ w ⊙ p against central differences of the f64 path.
    let w: Vec<f32> = (0..3 * c.v * 3).map(|i| 0.3 + (i as f32 * 0.7).sin()).collect();
    let wt = Tensor::from_vec(w, (3, c.v, 3), &cpu()).unwrap();
    let grads = (p * wt).unwrap().sum_all().unwrap().backward().unwrap();
    let analytic: Vec<f64> = to_vec3(grads.get(x.as_tensor()).unwrap())
        .iter()
        .map(|&v| v as f64)
        .collect();
    let fd = weft_testkit::fd_gradient(|y| f64_loss(y).1, &x64, 1e-6);
    let err = max_norm_rel_error(&analytic, &fd);
    assert!(err < 1e-4, "ACAP⁻¹ op gradient vs FD: {err:e}");
}

#[test]
fn acap_inverse_op_rejects_wrong_shapes_and_nan_features() {
    let c = acap_case();
    let op = AcapInverse::new(c.inverse.clone(), c.normalization.clone(), c.pins.clone());
    let wrong = Tensor::zeros((2, c.v, 9), DType::F32, &cpu()).unwrap();
    assert!(matches!(op.apply(&wrong), Err(Error::Shape { .. })));
    let mut bad = c.features.clone();
    bad[17] = f32::NAN;
    let t = Tensor::from_vec(bad, (3, c.v, 9), &cpu()).unwrap();
    let e = op.apply(&t).unwrap_err().to_string();
    assert!(e.contains("non-finite"), "{e}");
}

/// Three frames of the quick `sheet-ms` and its integrator.
fn lphys_case() -> (Arc<weft_sim::ImplicitEuler>, Vec<Vec<f64>>) {
    let mut sim = ClothSimulation::new(ClothScene::builtin("sheet-ms", true).unwrap(), None).unwrap();
    let mut frames = vec![sim.integrator().positions().to_vec()];
    for _ in 0..3 {
        frames.push(sim.step().unwrap().positions);
    }
    (Arc::new(sim.into_integrator()), frames)
}

#[test]
fn l_phys_op_matches_weft_sim_and_stops_the_gradient_into_previous_frames() {
    let (ie, frames) = lphys_case();
    let v = frames[0].len() / 3;
    let mut rng = TestRng::new(9);
    // Off the simulated frame, so the gradient is not zero.
    let p: Vec<f64> = frames[3].iter().map(|x| x + rng.uniform(-1e-3, 1e-3)).collect();
    let as_var = |x: &[f64]| Var::from_vec(x.iter().map(|&v| v as f32).collect::<Vec<_>>(), (1, v, 3), &cpu()).unwrap();
    let (t2, t1, tp) = (as_var(&frames[1]), as_var(&frames[2]), as_var(&p));
    let op = LPhys::new(ie.clone());
    let value = op.apply(t2.as_tensor(), t1.as_tensor(), tp.as_tensor()).unwrap();
    let round = |x: &[f64]| x.iter().map(|&v| v as f32 as f64).collect::<Vec<_>>();
    let (r2, r1, rp) = (round(&frames[1]), round(&frames[2]), round(&p));
    let expect = ie.l_phys(&r2, &r1, &rp).unwrap();
    let got: Vec<f32> = value.to_vec1().unwrap();
    assert!(
        (got[0] as f64 - expect).abs() <= 1e-6 * expect.abs().max(1e-12),
        "{} vs {expect}",
        got[0]
    );
    let grads = value.sum_all().unwrap().backward().unwrap();
    let analytic: Vec<f64> = to_vec3(grads.get(tp.as_tensor()).unwrap())
        .iter()
        .map(|&x| x as f64)
        .collect();
    let fd = weft_testkit::fd_gradient(|y| ie.l_phys(&r2, &r1, y).unwrap(), &rp, 1e-7);
    let err = max_norm_rel_error(&analytic, &fd);
    assert!(err < 1e-4, "∂L_phys/∂p_m vs FD: {err:e}");
    // Eq. 9–10: nothing flows into p_{m−1} or p_{m−2}, although L_phys depends on them.
    assert!(grads.get(t1.as_tensor()).is_none() && grads.get(t2.as_tensor()).is_none());
    let fd_prev = weft_testkit::fd_gradient(|y| ie.l_phys(&r2, y, &rp).unwrap(), &r1, 1e-7);
    assert!(
        fd_prev.iter().any(|g| g.abs() > 1e-3),
        "L_phys should depend on p_(m-1)"
    );
}

#[test]
fn checkpoint_round_trip_resumes_training_bit_for_bit() {
    let sheet = weft_mesh::generators::sheet(4, 1.0).unwrap();
    let config = AutoencoderSettings {
        conv_layers: 1,
        latent: 4,
    };
    let build = |seed| {
        let graph = Arc::new(MeshGraph::new(&sheet, &cpu()).unwrap());
        let mut params = ParamStore::new(&cpu(), seed);
        let model = MeshAutoencoder::new(&mut params, graph, config).unwrap();
        let adam = Adam::new(&params, AdamSettings::default()).unwrap();
        (params, model, adam)
    };
    let mut rng = TestRng::new(4);
    let x: Vec<f32> = (0..2 * 16 * 9).map(|_| rng.uniform(-0.9, 0.9) as f32).collect();
    let x = Tensor::from_vec(x, (2, 16, 9), &cpu()).unwrap();
    let train = |params: &ParamStore, model: &MeshAutoencoder, adam: &mut Adam, steps: usize| {
        for _ in 0..steps {
            let loss = (model.decode(&model.encode(&x).unwrap()).unwrap() - &x)
                .unwrap()
                .sqr()
                .unwrap()
                .mean_all()
                .unwrap();
            adam.step(params, &loss.backward().unwrap()).unwrap();
        }
        to_vec3(&model.decode(&model.encode(&x).unwrap()).unwrap())
    };
    let dir = std::env::temp_dir().join(format!("weft-nn-ckpt-{}", std::process::id()));
    let (p1, m1, mut a1) = build(3);
    train(&p1, &m1, &mut a1, 3);
    checkpoint::save(&dir, &p1, &a1, &serde_json::json!({"epoch": 3})).unwrap();
    assert!(checkpoint::exists(&dir));
    let straight = train(&p1, &m1, &mut a1, 2);
    // A different seed, then the checkpoint: weights and moments both come from it.
    let (p2, m2, mut a2) = build(99);
    let extra = checkpoint::load(&dir, &p2, &mut a2).unwrap();
    assert_eq!(extra["epoch"], 3);
    assert_eq!(a2.steps(), 3);
    let resumed = train(&p2, &m2, &mut a2, 2);
    assert_eq!(
        straight, resumed,
        "resumed training must match the uninterrupted run bit for bit"
    );
    // A checkpoint of another model is a typed error naming the problem.
    let graph = Arc::new(MeshGraph::new(&sheet, &cpu()).unwrap());
    let mut other = ParamStore::new(&cpu(), 1);
    MeshAutoencoder::new(
        &mut other,
        graph,
        AutoencoderSettings {
            conv_layers: 1,
            latent: 5,
        },
    )
    .unwrap();
    let e = checkpoint::load_params(&dir, &other).unwrap_err().to_string();
    assert!(e.contains("shape"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn training_the_autoencoder_on_the_quick_sheet_lowers_every_loss() {
    // Smoke test: L_recon + L_vert + λ L_ephys on frames of the quick sheet-ms, through
    // both custom ops; every term must fall.
    let mut sim = ClothSimulation::new(ClothScene::builtin("sheet-ms", true).unwrap(), None).unwrap();
    let mesh = sim.mesh().clone();
    let grasp = sim.grasp_vertices().to_vec();
    let mut frames = vec![sim.integrator().positions().to_vec()];
    for _ in 0..8 {
        frames.push(sim.step().unwrap().positions);
    }
    let ie = Arc::new(sim.into_integrator());
    let points =
        |x: &[f64]| -> Vec<Vector3<f64>> { x.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect() };
    let acap = AcapFeatures::new(&mesh, AcapSettings::default()).unwrap();
    let inverse = Arc::new(PoissonPseudoInverse::new(&acap, &grasp).unwrap());
    let seq: Vec<Vec<Vector3<f64>>> = frames.iter().map(|f| points(f)).collect();
    let feats = acap.encode_sequence(&seq).unwrap();
    let norm = FeatureNormalization::fit_per_block(feats.iter().flatten()).unwrap();
    let v = mesh.num_vertices();
    // Frames 2..8 as targets, with their two predecessors for L_phys.
    let targets: Vec<usize> = (2..frames.len()).collect();
    let b = targets.len();
    let x: Vec<f32> = targets
        .iter()
        .flat_map(|&m| norm.normalize_all(&feats[m]))
        .flat_map(|f| f.map(|x| x as f32))
        .collect();
    let x = Tensor::from_vec(x, (b, v, 9), &cpu()).unwrap();
    let stack = |offset: usize| {
        let vals: Vec<f32> = targets
            .iter()
            .flat_map(|&m| frames[m - offset].iter().map(|&x| x as f32))
            .collect();
        Tensor::from_vec(vals, (b, v, 3), &cpu()).unwrap()
    };
    let (p_true, p1, p2) = (stack(0), stack(1), stack(2));
    let pins = targets
        .iter()
        .map(|&m| grasp.iter().map(|&i| seq[m][i]).collect())
        .collect();
    let decode = AcapInverse::new(inverse, norm, pins);
    let lphys = LPhys::new(ie.clone());
    // L_phys at the ground truth: the floor L_ephys can approach.
    let floor: f32 = lphys
        .apply(&p2, &p1, &p_true)
        .unwrap()
        .mean_all()
        .unwrap()
        .to_scalar()
        .unwrap();

    let graph = Arc::new(MeshGraph::new(&mesh, &cpu()).unwrap());
    let mut params = ParamStore::new(&cpu(), 11);
    let model = MeshAutoencoder::new(
        &mut params,
        graph,
        AutoencoderSettings {
            conv_layers: 1,
            latent: 16,
        },
    )
    .unwrap();
    let mut adam = Adam::new(
        &params,
        AdamSettings {
            learning_rate: 2e-3,
            ..AdamSettings::default()
        },
    )
    .unwrap();
    let losses = |model: &MeshAutoencoder| {
        let y = model.decode(&model.encode(&x).unwrap()).unwrap();
        let recon = (&y - &x).unwrap().sqr().unwrap().mean_all().unwrap();
        let p = decode.apply(&y).unwrap();
        let vert = (&p - &p_true).unwrap().sqr().unwrap().mean_all().unwrap();
        let ephys = (lphys.apply(&p2, &p1, &p).unwrap().mean_all().unwrap() - floor as f64).unwrap();
        (recon, vert, ephys)
    };
    let scalar = |t: &Tensor| -> f32 { t.to_scalar().unwrap() };
    let (r0, v0, e0) = losses(&model);
    let (r0, v0, e0) = (scalar(&r0), scalar(&v0), scalar(&e0));
    for _ in 0..300 {
        let (r, vt, e) = losses(&model);
        let total = ((r + (vt * 10.0).unwrap()).unwrap() + (e * 1e-3).unwrap()).unwrap();
        adam.step(&params, &total.backward().unwrap()).unwrap();
    }
    let (r1, v1, e1) = losses(&model);
    let (r1, v1, e1) = (scalar(&r1), scalar(&v1), scalar(&e1));
    eprintln!("recon {r0} → {r1}, vert {v0} → {v1}, ephys {e0} → {e1} (floor {floor})");
    // Measured: L_recon 1.36 → 0.0053, L_vert 0.13 → 3.9e-5, L_ephys 601 → 0.33 J.
    assert!(r1 < 0.05 * r0, "L_recon {r0} → {r1}");
    assert!(v1 < 0.01 * v0, "L_vert {v0} → {v1}");
    assert!(e1 < 0.01 * e0, "L_ephys {e0} → {e1}");
}

#[test]
fn latent_rollout_decodes_like_the_ops_and_feeds_its_codes_back() {
    use weft_nn::embed::LatentRollout;
    use weft_nn::embed::{LatentSimulator, LatentSimulatorSettings};
    let c = acap_case();
    let sheet = weft_mesh::generators::sheet(5, 1.0).unwrap();
    let graph = Arc::new(MeshGraph::new(&sheet, &cpu()).unwrap());
    let mut params = ParamStore::new(&cpu(), 21);
    let ae = MeshAutoencoder::new(
        &mut params,
        graph,
        AutoencoderSettings {
            conv_layers: 1,
            latent: 6,
        },
    )
    .unwrap();
    let sim = LatentSimulator::new(
        &mut params,
        LatentSimulatorSettings {
            latent: 6,
            controls: 6,
            hidden: vec![8],
        },
    )
    .unwrap();
    let z1 = vec![0.1, -0.2, 0.3, 0.0, 0.5, -0.1];
    let z2 = vec![0.2, -0.1, 0.2, 0.1, 0.4, 0.0];
    let q: Vec<f64> = c.pins[0].iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    let mut rollout = LatentRollout::new(&ae, &sim, c.inverse.clone(), c.normalization.clone(), &z1, &z2).unwrap();
    let (first, profile) = rollout.step_profiled(&q).unwrap();
    let second = rollout.step(&q).unwrap();
    assert!(profile.solve > std::time::Duration::ZERO);
    // The same frames through the tensor path: MLP, decoder, then the ACAP⁻¹ op.
    let t = |z: &[f64]| Tensor::from_vec(z.iter().map(|&v| v as f32).collect::<Vec<_>>(), (1, 6), &cpu()).unwrap();
    let qt = Tensor::from_vec(q.iter().map(|&v| v as f32).collect::<Vec<_>>(), (1, 6), &cpu()).unwrap();
    let z3 = sim.step(&t(&z1), &t(&z2), &qt).unwrap();
    let z4 = sim.step(&t(&z2), &z3, &qt).unwrap();
    let op = AcapInverse::new(c.inverse.clone(), c.normalization.clone(), vec![c.pins[0].clone()]);
    for (z, got) in [(z3, first), (z4, second)] {
        let expect: Vec<f64> = to_vec3(&op.apply(&ae.decode(&z).unwrap()).unwrap())
            .iter()
            .map(|&v| v as f64)
            .collect();
        assert!(max_norm_rel_error(&got, &expect) < 1e-5);
    }
    assert!(matches!(rollout.step(&q[..3]), Err(Error::Shape { .. })));
}

#[test]
fn cloth_potential_op_is_the_elastic_terms_and_its_gradient_matches_finite_differences() {
    use weft_nn::ops::ClothPotential;
    let (ie, frames) = lphys_case();
    let v = frames[0].len() / 3;
    let mut rng = TestRng::new(31);
    let p: Vec<f64> = frames[3].iter().map(|x| x + rng.uniform(-2e-3, 2e-3)).collect();
    let p = p.iter().map(|&x| x as f32 as f64).collect::<Vec<_>>();
    let elastic = |x: &[f64]| -> f64 {
        ie.terms()
            .iter()
            .filter(|t| weft_sim::is_cloth_elastic(t.as_ref()))
            .map(|t| t.value(x))
            .sum()
    };
    // Gravity is in the integrator but not in P_s + P_b.
    let all: f64 = ie.terms().iter().map(|t| t.value(&p)).sum();
    assert!((all - elastic(&p)).abs() > 1e-6 * all.abs());
    let var = Var::from_vec(p.iter().map(|&x| x as f32).collect::<Vec<_>>(), (1, v, 3), &cpu()).unwrap();
    let op = ClothPotential::new(ie.clone());
    let value = op.apply(var.as_tensor()).unwrap();
    let got = value.to_vec1::<f32>().unwrap()[0] as f64;
    assert!(
        (got - elastic(&p)).abs() <= 1e-6 * elastic(&p).abs(),
        "{got} vs {}",
        elastic(&p)
    );
    let grads = value.sum_all().unwrap().backward().unwrap();
    let analytic: Vec<f64> = to_vec3(grads.get(var.as_tensor()).unwrap())
        .iter()
        .map(|&x| x as f64)
        .collect();
    let fd = weft_testkit::fd_gradient(elastic, &p, 1e-7);
    let err = max_norm_rel_error(&analytic, &fd);
    assert!(err < 1e-4, "∂(P_s + P_b)/∂p vs FD: {err:e}");
    let wrong = Tensor::zeros((1, v + 1, 3), DType::F32, &cpu()).unwrap();
    assert!(matches!(op.apply(&wrong), Err(Error::Shape { .. })));
}

/// The quick `sheet-ms` simulated for `frames` frames, as an in-memory dataset.
pub(crate) fn quick_sheet_dataset(frames: usize) -> weft_data::ClothDataset {
    weft_data::ClothDataset::simulate("sheet-ms", ClothScene::builtin("sheet-ms", true).unwrap(), frames).unwrap()
}

/// The embedding's default configuration with a one-convolution, 8-wide autoencoder: the
/// size the quick sheet's tests train and differentiate.
pub(crate) fn small_embed_config() -> weft_nn::embed::EmbedTrainingSettings {
    weft_nn::embed::EmbedTrainingSettings {
        autoencoder: AutoencoderSettings {
            conv_layers: 1,
            latent: 8,
        },
        ..Default::default()
    }
}

#[test]
fn latent_inverse_kinematics_lowers_the_potential_and_keeps_the_pins() {
    use weft_nn::embed::{EmbedData, EmbedModel, FrameRef};
    use weft_nn::ik::{IkSettings, decode_pinned, full_space_ik, latent_ik};
    let data = EmbedData::new(quick_sheet_dataset(20)).unwrap();
    let model = EmbedModel::new(small_embed_config(), &data).unwrap();
    let z0 = model
        .codes(&data, &[FrameRef { sequence: 0, frame: 0 }])
        .unwrap()
        .remove(0);
    // New grasp positions: frame 15's corners, moved 5 cm towards each other.
    let q = data.dataset.sequences[0].control(15);
    let mut pins: Vec<Vector3<f64>> = q.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect();
    let mid = (pins[0] + pins[1]) / 2.0;
    for p in &mut pins {
        *p += (mid - *p).normalize() * 0.05;
    }
    let settings = IkSettings {
        iterations: 60,
        learning_rate: 0.05,
    };
    let latent = latent_ik(&model, &data, &z0, &pins, settings).unwrap();
    assert!(
        latent.energy < 0.9 * latent.start_energy,
        "{} → {}",
        latent.start_energy,
        latent.energy
    );
    let elastic = |x: &[f64]| -> f64 {
        data.integrator
            .terms()
            .iter()
            .filter(|t| weft_sim::is_cloth_elastic(t.as_ref()))
            .map(|t| t.value(x))
            .sum()
    };
    assert!((elastic(&latent.positions) - latent.energy).abs() <= 1e-4 * latent.energy);
    for (k, &g) in data.dataset.grasp.iter().enumerate() {
        let got = Vector3::new(
            latent.positions[3 * g],
            latent.positions[3 * g + 1],
            latent.positions[3 * g + 2],
        );
        assert!((got - pins[k]).norm() < 1e-5, "pin {k} moved to {got:?}");
    }
    // The full space, from the same start, reaches a lower potential.
    let x0 = decode_pinned(&model, &data, &z0, &pins).unwrap();
    assert!((elastic(&x0) - latent.start_energy).abs() <= 1e-4 * latent.start_energy);
    let (full, converged) = full_space_ik(&data.integrator, &x0, 300).unwrap();
    assert!(converged);
    assert!(full.energy < latent.energy, "{} vs {}", full.energy, latent.energy);
    assert!(matches!(
        latent_ik(&model, &data, &z0[..3], &pins, settings),
        Err(Error::Shape { .. })
    ));
}

/// A 4 × 2 × 2-cell beam and its nodes at x = 0 (the clamped end).
fn clamped_small_beam() -> (weft_mesh::TetMesh, Vec<usize>) {
    let beam = weft_mesh::generators::beam(&weft_mesh::generators::BeamParams {
        cells: [4, 2, 2],
        size: [1.0, 0.4, 0.4],
    })
    .unwrap();
    let anchors = (0..beam.num_vertices())
        .filter(|&i| beam.positions()[i].x.abs() < 1e-12)
        .collect();
    (beam, anchors)
}

/// `n` seeded NNWarp input rows and outputs in plausible ranges.
fn random_pairs(seed: u64, n: usize) -> (Vec<[f64; weft_nn::nnwarp::INPUTS]>, Vec<[f64; 3]>) {
    let mut rng = TestRng::new(seed);
    let rows = (0..n)
        .map(|_| std::array::from_fn(|_| rng.uniform(-2.0, 2.0)))
        .collect();
    let outs = (0..n)
        .map(|_| std::array::from_fn(|_| rng.uniform(-0.3, 0.3)))
        .collect();
    (rows, outs)
}

#[test]
fn nnwarp_plain_rust_forward_matches_candle_and_pairs_are_frame_consistent() {
    use nalgebra::Rotation3;
    use weft_nn::nnwarp::{NnWarp, Standardization, WarpContext, WarpMlp, hidden_layers};
    use weft_sim::warp::FieldDirection;
    let mut params = ParamStore::new(&cpu(), 3);
    let (rows, outs) = random_pairs(17, 40);
    let standardization = Standardization::fit(&rows, &outs).unwrap();
    let mlp = WarpMlp::new(&mut params, &hidden_layers("stvk"), &standardization).unwrap();
    let (x, _) = weft_nn::nnwarp::pair_tensors(&rows, &outs, &standardization, &cpu()).unwrap();
    let candle_out: Vec<f32> = mlp.forward(&x).unwrap().flatten_all().unwrap().to_vec1().unwrap();
    let node = mlp.to_node_mlp(standardization.clone()).unwrap();
    for (k, r) in rows.iter().enumerate() {
        let got = node.forward(r);
        let want = standardization.unoutput(&std::array::from_fn(|d| candle_out[3 * k + d] as f64));
        for d in 0..3 {
            assert!(
                (got[d] - want[d]).abs() < 1e-5 * (1.0 + want[d].abs()),
                "{k}/{d}: {got:?} vs {want:?}"
            );
        }
    }
    // Pairs: a registered shape equal to the linear one needs no correction; and the
    // runtime puts an aligned correction back in the world frame (u = ũ + Qᵀ δu).
    let (beam, anchors) = clamped_small_beam();
    let ctx = WarpContext::new(
        &beam,
        &anchors,
        FieldDirection::Directional(-nalgebra::Vector3::y()),
        0.3,
    )
    .unwrap();
    let lin: Vec<f64> = beam
        .positions()
        .iter()
        .flat_map(|p| [0.0, -0.2 * p.x * p.x, 0.05 * p.x])
        .collect();
    let (inputs, targets) = ctx.pairs(&lin, &lin).unwrap();
    assert_eq!(inputs.len(), ctx.free_nodes().len());
    assert!(targets.iter().flatten().all(|v| v.abs() < 1e-15));
    let moved: Vec<f64> = lin.iter().enumerate().map(|(k, v)| v + 0.01 * (k % 3) as f64).collect();
    let (_, targets) = ctx.pairs(&lin, &moved).unwrap();
    let frames = ctx.inputs(&lin).unwrap().rotations;
    let (_, scale) = weft_sim::warp::unit_sphere_normalization(beam.positions());
    for ((&i, t), q) in ctx.free_nodes().iter().zip(&targets).zip(&frames) {
        let world: Rotation3<f64> = q.inverse();
        let back = world * nalgebra::Vector3::new(t[0], t[1], t[2]) / scale;
        for d in 0..3 {
            assert!((back[d] - (moved[3 * i + d] - lin[3 * i + d])).abs() < 1e-12);
        }
    }
    let warp = NnWarp::new(ctx, node);
    let out = warp.warp(&lin).unwrap();
    for &a in &anchors {
        assert_eq!(&out[3 * a..3 * a + 3], &lin[3 * a..3 * a + 3]);
    }
    assert!(matches!(warp.warp(&lin[3..]), Err(Error::Shape { .. })));
}

#[test]
fn the_batched_correction_is_the_node_by_node_network_on_small_and_large_bodies() {
    use weft_nn::nnwarp::{NnWarp, Standardization, WarpContext, WarpMlp, hidden_layers};
    use weft_sim::warp::{FieldDirection, NodalGradients, aligned_kinematics};
    let (rows, outs) = random_pairs(29, 64);
    let standardization = Standardization::fit(&rows, &outs).unwrap();
    let mut params = ParamStore::new(&cpu(), 5);
    let mlp = WarpMlp::new(&mut params, &hidden_layers("neo-hookean"), &standardization).unwrap();
    let node = mlp.to_node_mlp(standardization).unwrap();
    // 225 and 2 511 nodes: the second above the size where the runtime splits the
    // correction into chunks on all threads.
    for cells in [[8, 4, 4], [30, 8, 8]] {
        let beam = weft_mesh::generators::beam(&weft_mesh::generators::BeamParams {
            cells,
            size: [1.0, 0.25, 0.25],
        })
        .unwrap();
        let anchors: Vec<usize> = (0..beam.num_vertices())
            .filter(|&i| beam.positions()[i].x.abs() < 1e-12)
            .collect();
        let field = FieldDirection::Directional(-Vector3::y());
        let ctx = WarpContext::new(&beam, &anchors, field, 0.3).unwrap();
        let lin: Vec<f64> = beam
            .positions()
            .iter()
            .flat_map(|p| [0.02 * p.y, -0.3 * p.x * p.x, 0.1 * p.x * p.z])
            .collect();
        let (out, w) = NnWarp::new(ctx.clone(), node.clone())
            .warp_with_rotations(&lin)
            .unwrap();
        let gradients = NodalGradients::new(&beam).unwrap();
        let (_, scale) = weft_sim::warp::unit_sphere_normalization(beam.positions());
        let inputs = ctx.inputs(&lin).unwrap();
        for (k, &i) in ctx.free_nodes().iter().enumerate() {
            let u = Vector3::new(lin[3 * i], lin[3 * i + 1], lin[3 * i + 2]);
            let wi = weft_sim::warp::rotation_vector(&gradients.gradient(&lin, i));
            assert!((w[i] - wi).norm() <= 1e-12 * (1.0 + wi.norm()), "node {i}: w");
            let (q, _) = aligned_kinematics(&(u * scale), &wi);
            let d = node.forward(&inputs.features[k]);
            let want = u + q.inverse() * Vector3::new(d[0], d[1], d[2]) / scale;
            let got = Vector3::new(out[3 * i], out[3 * i + 1], out[3 * i + 2]);
            // The same f32 network; the batch's products may sum in another order.
            assert!(
                (got - want).norm() <= 1e-6 * (want - u).norm() + 1e-12,
                "{cells:?} node {i}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn ephys_ramps_over_its_warmup_and_legacy_configurations_keep_their_meaning() {
    use weft_nn::embed::{EmbedTrainingSettings, PhysScale, Progress};
    let mut c = EmbedTrainingSettings::default();
    c.weights.ephys = 0.5;
    c.ephys_warmup = 4;
    let at_with = |c: &EmbedTrainingSettings, stage: u8, epoch: usize, fraction: f64| {
        c.ephys_weight(Progress { stage, epoch }, fraction)
    };
    let at = |stage: u8, epoch: usize, fraction: f64| at_with(&c, stage, epoch, fraction);
    assert_eq!(at(1, 0, 0.0), 0.0);
    assert!((at(1, 1, 0.5) - 0.5 * 1.5 / 4.0).abs() < 1e-15);
    assert_eq!(at(1, 4, 0.0), 0.5);
    assert_eq!(at(1, 9, 0.9), 0.5);
    // The ramp is stage 1's: stage 3 fine-tunes at the full weight from its first batch.
    assert_eq!(at(3, 0, 0.0), 0.5);
    let none = EmbedTrainingSettings {
        ephys_warmup: 0,
        ..c.clone()
    };
    assert_eq!(at_with(&none, 1, 0, 0.0), 0.5);
    // A configuration stored before the fields existed: inertial scale, no ramp.
    let mut v = serde_json::to_value(EmbedTrainingSettings::default()).unwrap();
    let o = v.as_object_mut().unwrap();
    o.remove("phys_scale");
    o.remove("ephys_warmup");
    o["schedule"].as_object_mut().unwrap().remove("warmup_steps");
    let legacy: EmbedTrainingSettings = serde_json::from_value(v).unwrap();
    assert_eq!(legacy.phys_scale, PhysScale::Inertial);
    assert_eq!(legacy.ephys_warmup, 0);
    // Stored before the learning-rate warm-up: none; new configurations ramp.
    assert_eq!(legacy.schedule.warmup_steps, 0);
    assert_eq!(
        EmbedTrainingSettings::default().schedule.warmup_steps,
        weft_nn::embed::WARMUP_STEPS
    );
}

#[test]
fn nnwarp_runtime_rotates_each_load_by_the_previous_frame_and_corrects_it() {
    use weft_nn::nnwarp::{NnWarp, NnWarpSimulation, Standardization, WarpBody, WarpContext, WarpMlp, hidden_layers};
    use weft_sim::warp::{FieldDirection, loads_in_rest_frames};
    let (rows, outs) = random_pairs(5, 30);
    let standardization = Standardization::fit(&rows, &outs).unwrap();
    let mut params = ParamStore::new(&cpu(), 9);
    let mlp = WarpMlp::new(&mut params, &hidden_layers("neo-hookean"), &standardization).unwrap();
    let node = || mlp.to_node_mlp(standardization.clone()).unwrap();
    let (beam, anchors) = clamped_small_beam();
    let field = FieldDirection::Directional(nalgebra::Vector3::new(0.0, 1.0, 0.5));
    let forces: Vec<f64> = (0..beam.num_vertices()).flat_map(|_| [0.0, 40.0, 20.0]).collect();
    let solve = weft_sim::LinearSolve::Static;
    let mut runtime = NnWarpSimulation::from_body(
        WarpBody {
            mesh: &beam,
            anchors: &anchors,
            young: 1e5,
            poisson: 0.3,
            density: 1000.0,
            forces: &forces,
            solve,
            field,
            frames: 3,
        },
        node(),
    )
    .unwrap();
    // The same frames composed by hand: load ramp k/3, rotated by the previous linear
    // displacement's own gradient fit (all nodes), solved, corrected.
    let lame = weft_sim::energies::LameParameters::from_young_poisson(1e5, 0.3).unwrap();
    let energy = weft_sim::energies::TetElasticity::new(&beam, weft_sim::energies::Material::Linear, lame).unwrap();
    let masses = weft_mesh::geometry::lumped_masses_tet(beam.positions(), beam.tets(), 1000.0);
    let fixed = weft_sim::anchors::fixed_dofs(beam.num_vertices(), &anchors).unwrap();
    let mut linear =
        weft_sim::PrefactorizedLinear::new(&beam.flat_positions(), &[&energy], masses, fixed, solve).unwrap();
    let warp = NnWarp::new(WarpContext::new(&beam, &anchors, field, 0.3).unwrap(), node());
    let gradients = weft_sim::warp::NodalGradients::new(&beam).unwrap();
    let mut rotated_any = false;
    for k in 1..=3 {
        let load: Vec<f64> = forces.iter().map(|f| f * k as f64 / 3.0).collect();
        let rotated = loads_in_rest_frames(&gradients, linear.displacements(), &load).unwrap();
        rotated_any |= rotated.iter().zip(&load).any(|(a, b)| (a - b).abs() > 1e-6);
        linear.step(&rotated, &[]).unwrap();
        let want = warp.warp(linear.displacements()).unwrap();
        let frame = runtime.step().unwrap();
        assert_eq!(frame.linear.len(), want.len());
        for (a, b) in frame.linear.iter().zip(linear.displacements()) {
            assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "frame {k}: linear {a} vs {b}");
        }
        for (a, b) in frame.warped.iter().zip(&want) {
            assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "frame {k}: warped {a} vs {b}");
        }
    }
    assert!(rotated_any, "the load should be large enough to rotate");
    // A body whose forces do not match its mesh is refused.
    assert!(
        NnWarpSimulation::from_body(
            WarpBody {
                mesh: &beam,
                anchors: &anchors,
                young: 1e5,
                poisson: 0.3,
                density: 1000.0,
                forces: &forces[3..],
                solve,
                field,
                frames: 3,
            },
            node(),
        )
        .is_err()
    );
}

/// Issue 70: the network's inputs at runtime and in training come from the same linear
/// solve. A training sequence (weft-sim's ramp) replayed by the runtime under the same
/// loads gives the same linear displacements frame by frame, hence the same inputs as the
/// trainer reads from the stored sequence. Before the fix the ramp solved `K ũ = f` while
/// the runtime solves with the loads in the rest frames: the frames differed from the
/// second one on, and with them the inputs.
#[test]
fn nnwarp_runtime_and_training_see_the_same_linear_solve() {
    use weft_nn::nnwarp::{NnWarpSimulation, Standardization, WarpBody, WarpMlp, collect_pairs, hidden_layers};
    use weft_sim::energies::Material;
    use weft_sim::warp::{
        FieldDirection, SequenceSettings, field_forces, register_sequence, unit_sphere_normalization,
    };
    let (beam, anchors) = clamped_small_beam();
    let (center, scale) = unit_sphere_normalization(beam.positions());
    let body = weft_mesh::TetMesh::new(
        beam.positions().iter().map(|p| (p - center) * scale).collect(),
        beam.tets().to_vec(),
    )
    .unwrap();
    let field = FieldDirection::Directional(Vector3::new(0.2, -1.0, 0.4));
    let (poisson, settings) = (
        0.35,
        SequenceSettings {
            ramp_frames: 6,
            ..SequenceSettings::default()
        },
    );
    let seq = register_sequence(&body, &anchors, field, poisson, &[Material::NeoHookean], settings).unwrap();
    assert_eq!(seq.error, None);
    let frames = seq.linear.len();
    assert!(frames > 3, "{frames} frames");
    // What the trainer reads: the stored sequence's pairs.
    let dataset = weft_data::WarpDataset {
        dir: std::path::PathBuf::new(),
        body: body.clone(),
        anchors: anchors.clone(),
        material: "neo-hookean".into(),
        sequences: vec![weft_data::WarpSequence {
            index: 0,
            split: "train".into(),
            field,
            poisson,
            linear: seq.linear.clone(),
            nonlinear: seq.nonlinear[0].clone(),
        }],
        dropped_frames: 0,
    };
    let (trained, _) = collect_pairs(&dataset, "train").unwrap();
    // The runtime on the same body, its solve the ramp's, stepped under the ramp's loads.
    let (rows, outs) = random_pairs(3, 30);
    let standardization = Standardization::fit(&rows, &outs).unwrap();
    let mut params = ParamStore::new(&cpu(), 4);
    let mlp = WarpMlp::new(&mut params, &hidden_layers("neo-hookean"), &standardization).unwrap();
    let rest = body.flat_positions();
    let masses = weft_mesh::geometry::lumped_masses_tet(body.positions(), body.tets(), settings.density);
    let unit = field_forces(&rest, &masses, field).unwrap();
    let mut runtime = NnWarpSimulation::from_body(
        WarpBody {
            mesh: &body,
            anchors: &anchors,
            young: settings.young,
            poisson,
            density: settings.density,
            forces: &unit,
            solve: seq.solve,
            field,
            frames: 1,
        },
        mlp.to_node_mlp(standardization).unwrap(),
    )
    .unwrap();
    let free = trained.len() / (frames - 1);
    for k in 1..frames {
        let load: Vec<f64> = unit.iter().map(|f| f * seq.accelerations[k]).collect();
        let frame = runtime.step_with_load(&load).unwrap();
        let reach = seq.linear[k].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (a, b) in frame.linear.iter().zip(&seq.linear[k]) {
            assert!((a - b).abs() <= 1e-9 * reach, "frame {k}: runtime {a} vs training {b}");
        }
        let inputs = runtime.warp().context().inputs(&frame.linear).unwrap().features;
        assert_eq!(inputs.len(), free);
        for (a, b) in inputs.iter().zip(&trained[(k - 1) * free..k * free]) {
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() <= 1e-7 * (1.0 + y.abs()), "frame {k}: input {x} vs {y}");
            }
        }
    }
}

/// The PCA + MLP roll-out against steps computed by hand: a one-component PCA of two
/// vertices moving along a known direction, one grasped vertex, and a latent MLP with no
/// hidden layer and chosen weights, so `z_m = w·[z_{m−2}, z_{m−1}, q_m] + b` and
/// `x_m = x̄ + (z_m / s) d`.
#[test]
fn the_pca_simulator_rolls_out_the_hand_computed_steps() {
    use std::collections::BTreeMap;
    use weft_nn::embed::{LatentSimulator, LatentSimulatorSettings};
    use weft_nn::pca::PositionPca;
    use weft_nn::pca_simulator::PcaSimulator;
    let r = std::f64::consts::FRAC_1_SQRT_2;
    let mean = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let d = [r, 0.0, 0.0, 0.0, r, 0.0];
    let along = |t: f64| -> Vec<f64> { (0..6).map(|i| mean[i] + t * d[i]).collect() };
    let pca = PositionPca::fit(&[-1.0, -0.5, 0.5, 1.0].map(along), 1).unwrap();
    // The basis is d up to its sign.
    let sign = pca.encode(&along(1.0))[0];
    assert!((sign.abs() - 1.0).abs() < 1e-12, "{sign}");
    let mut params = ParamStore::new(&Device::Cpu, 0);
    let mlp = LatentSimulator::new(
        &mut params,
        LatentSimulatorSettings {
            latent: 1,
            controls: 3,
            hidden: vec![],
        },
    )
    .unwrap();
    let (w, b) = ([0.5f32, 0.25, 1.0, -2.0, 0.1], 0.05f32);
    let tensors = BTreeMap::from([
        (
            "latent_sim.fc0.w".to_string(),
            Tensor::from_vec(w.to_vec(), (5, 1), &Device::Cpu).unwrap(),
        ),
        (
            "latent_sim.fc0.b".to_string(),
            Tensor::from_vec(vec![b], 1, &Device::Cpu).unwrap(),
        ),
    ]);
    params.assign(&tensors, "test weights").unwrap();
    let scale = 2.0;
    let sim = PcaSimulator {
        pca,
        scale,
        params,
        mlp,
    };
    let (ta, tb) = (0.3, -0.2);
    let controls: [&[f64]; 2] = [&[0.1, 0.2, 0.3], &[-0.4, 0.0, 0.5]];
    let rolled = sim.rollout(&along(ta), &along(tb), &controls).unwrap();
    // By hand: codes s·sign·t, then the linear step twice.
    let w: Vec<f64> = w.iter().map(|&v| f64::from(v)).collect();
    let step =
        |z2: f64, z1: f64, q: &[f64]| w[0] * z2 + w[1] * z1 + w[2] * q[0] + w[3] * q[1] + w[4] * q[2] + f64::from(b);
    let (z2, z1) = (scale * sign * ta, scale * sign * tb);
    let z3 = step(z2, z1, controls[0]);
    let z4 = step(z1, z3, controls[1]);
    for (got, z) in rolled.iter().zip([z3, z4]) {
        let want = along(sign * z / scale);
        assert!(max_norm_rel_error(got, &want) < 1e-6, "{got:?} vs {want:?}");
    }
}

/// The latent MLP on a PCA subspace trains through the trainer (its validation loss falls
/// below the untrained one's) and rolls out frames of the right size from two frames and
/// the controls.
#[test]
fn the_pca_simulator_learns_the_codes_and_rolls_out() {
    use weft_nn::embed::EmbedData;
    use weft_nn::pca::PositionPca;
    use weft_nn::pca_simulator::{PcaSimulatorSettings, train};
    let data = EmbedData::new(quick_sheet_dataset(34)).unwrap();
    let seq = &data.dataset.sequences[0];
    let frames: Vec<Vec<f64>> = data.train_windows.iter().map(|f| seq.frame(f.frame).to_vec()).collect();
    let pca = PositionPca::fit(&frames, 8).unwrap();
    let dir = std::env::temp_dir().join(format!("weft-pca-sim-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = PcaSimulatorSettings {
        hidden: vec![32],
        epochs: 15,
        batch: 4,
        adam: weft_nn::adam::AdamSettings {
            learning_rate: 3e-3,
            ..Default::default()
        },
        ..PcaSimulatorSettings::default()
    };
    let sim = train(&dir, &data, pca, &config, &mut weft_nn::trainer::Silent).unwrap();
    let state = weft_nn::trainer::TrainingState::read(&dir).unwrap();
    assert!(
        state.best_validation < 0.5 * state.initial_validation,
        "{} → {}",
        state.initial_validation,
        state.best_validation
    );
    let controls: Vec<&[f64]> = (2..6).map(|m| seq.control(m)).collect();
    let out = sim.rollout(seq.frame(0), seq.frame(1), &controls).unwrap();
    assert_eq!(out.len(), 4);
    assert!(
        out.iter()
            .all(|p| p.len() == seq.frame(0).len() && p.iter().all(|v| v.is_finite()))
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `‖a − b‖ / ‖b‖` of two gradients.
fn relative_gap(a: &Tensor, b: &Tensor) -> f32 {
    let norm = |t: &Tensor| t.sqr().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap().sqrt();
    norm(&(a - b).unwrap()) / norm(b)
}

/// A two-convolution autoencoder on an `n × n` sheet with `latent` codes, its weights from
/// `param_seed` and its biases drawn non-zero (so every leaky ReLU sees both signs); the
/// generator that drew them, to draw the test's inputs; and the vertex count.
fn autoencoder_with_random_biases(
    n: usize,
    latent: usize,
    param_seed: u64,
    rng_seed: u64,
) -> (ParamStore, MeshAutoencoder, TestRng, usize) {
    let mesh = weft_mesh::generators::sheet(n, 1.0).unwrap();
    let v = mesh.num_vertices();
    let graph = Arc::new(MeshGraph::new(&mesh, &cpu()).unwrap());
    let mut params = ParamStore::new(&cpu(), param_seed);
    let config = AutoencoderSettings { conv_layers: 2, latent };
    let autoencoder = MeshAutoencoder::new(&mut params, graph, config).unwrap();
    let mut rng = TestRng::new(rng_seed);
    for (name, var) in params.vars() {
        if name.ends_with(".b") {
            let n = var.as_tensor().elem_count();
            let b: Vec<f32> = (0..n).map(|_| rng.uniform(-0.3, 0.3) as f32).collect();
            var.set(&Tensor::from_vec(b, var.as_tensor().shape(), &cpu()).unwrap())
                .unwrap();
        }
    }
    (params, autoencoder, rng, v)
}

/// A variable of `shape` with entries uniform in (−0.9, 0.9).
fn random_var(rng: &mut TestRng, shape: &[usize]) -> Var {
    let n: usize = shape.iter().product();
    let x: Vec<f32> = (0..n).map(|_| rng.uniform(-0.9, 0.9) as f32).collect();
    Var::from_tensor(&Tensor::from_vec(x, shape, &cpu()).unwrap()).unwrap()
}

#[test]
fn the_fused_autoencoder_has_the_autograd_values_and_gradients() {
    // A sheet whose boundary vertices have fewer neighbours, a batch of three, random
    // weights with non-zero biases (so every leaky ReLU sees both signs), and a loss that
    // weighs every output differently: the encoder's and decoder's outputs and the
    // gradients of every parameter and of both inputs agree with candle's autograd. 196
    // vertices × 3 frames = 588 rows: two of the kernels' 512-row tasks, the second
    // partial, so the per-task products and their sum over tasks are both exercised.
    let (params, fused, mut rng, v) = autoencoder_with_random_biases(14, 7, 8, 3);
    assert!(3 * v > 512 && 3 * v < 1024);
    let reference = fused.clone().with_kernels(weft_nn::Kernels::Autograd);
    let x = random_var(&mut rng, &[3, v, 9]);
    let z_in = random_var(&mut rng, &[3, 7]);
    let weights_z = random_var(&mut rng, &[3, 7]);
    let weights_y = random_var(&mut rng, &[3, v, 9]);
    let run = |ae: &MeshAutoencoder| {
        let z = ae.encode(x.as_tensor()).unwrap();
        let y = ae.decode(z_in.as_tensor()).unwrap();
        let loss = ((&z * weights_z.as_tensor()).unwrap().sum_all().unwrap()
            + (&y * weights_y.as_tensor()).unwrap().sqr().unwrap().sum_all().unwrap())
        .unwrap();
        (z, y, loss.backward().unwrap())
    };
    let (z_f, y_f, g_f) = run(&fused);
    let (z_r, y_r, g_r) = run(&reference);
    assert!(relative_gap(&z_f, &z_r) < 1e-5, "codes differ");
    assert!(relative_gap(&y_f, &y_r) < 1e-5, "decoded features differ");
    let mut checked = 0;
    for (name, var) in params
        .vars()
        .iter()
        .map(|(n, v)| (n.as_str(), v))
        .chain([("x", &x), ("z", &z_in)])
    {
        let (f, r) = (g_f.get(var.as_tensor()).unwrap(), g_r.get(var.as_tensor()).unwrap());
        let gap = relative_gap(f, r);
        assert!(gap < 1e-4, "{name}: gradients differ by {gap:.2e} relative");
        checked += 1;
    }
    assert_eq!(checked, params.vars().len() + 2);
}

#[test]
fn the_fused_autoencoder_batched_with_frames_without_gradient_has_the_autograd_gradients() {
    // `encode_all` / `decode_all` send several batches through the fused ops as one, whose
    // backward passes skip the frames that receive no gradient. Here the loss reads only
    // the middle batch's codes (frames 2–3 of 6) and only the last batch's decoded
    // features (frames 5–5): every parameter's and input's gradient must still equal
    // autograd's, which runs each batch alone, and the inputs of the skipped frames must
    // get exactly zero.
    let (params, fused, mut rng, v) = autoencoder_with_random_biases(9, 6, 5, 9);
    let reference = fused.clone().with_kernels(weft_nn::Kernels::Autograd);
    let xs = [
        random_var(&mut rng, &[2, v, 9]),
        random_var(&mut rng, &[2, v, 9]),
        random_var(&mut rng, &[2, v, 9]),
    ];
    let zs = [
        random_var(&mut rng, &[2, 6]),
        random_var(&mut rng, &[3, 6]),
        random_var(&mut rng, &[1, 6]),
    ];
    let weights_z = random_var(&mut rng, &[2, 6]);
    let weights_y = random_var(&mut rng, &[1, v, 9]);
    let run = |ae: &MeshAutoencoder| {
        let codes = ae
            .encode_all(&[xs[0].as_tensor(), xs[1].as_tensor(), xs[2].as_tensor()])
            .unwrap();
        let decoded = ae
            .decode_all(&[zs[0].as_tensor(), zs[1].as_tensor(), zs[2].as_tensor()])
            .unwrap();
        let loss = ((&codes[1] * weights_z.as_tensor()).unwrap().sum_all().unwrap()
            + (&decoded[2] * weights_y.as_tensor())
                .unwrap()
                .sqr()
                .unwrap()
                .sum_all()
                .unwrap())
        .unwrap();
        (codes, decoded, loss.backward().unwrap())
    };
    let (codes_f, decoded_f, g_f) = run(&fused);
    let (codes_r, decoded_r, g_r) = run(&reference);
    for (f, r) in codes_f.iter().zip(&codes_r).chain(decoded_f.iter().zip(&decoded_r)) {
        assert_eq!(f.dims(), r.dims());
        assert!(relative_gap(f, r) < 1e-5, "outputs differ");
    }
    let inputs = xs.iter().chain(&zs).enumerate().map(|(k, x)| (format!("input {k}"), x));
    let mut checked = 0;
    for (name, var) in params.vars().iter().map(|(n, v)| (n.clone(), v)).chain(inputs) {
        let r = g_r.get(var.as_tensor());
        let f = g_f.get(var.as_tensor()).unwrap();
        match r {
            Some(r) => {
                let gap = relative_gap(f, r);
                assert!(gap < 1e-4, "{name}: gradients differ by {gap:.2e} relative");
            }
            // Autograd never reached this batch; the fused op must give it exact zeros.
            None => {
                let max = f.abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
                assert_eq!(max, 0.0, "{name}: a skipped frame got gradient {max}");
            }
        }
        checked += 1;
    }
    assert_eq!(checked, params.vars().len() + 6);
}

/// A synthetic `nnwarp` dataset on the small clamped beam where more training data must
/// help: the registered shape is the linear one shrunk by `1 − 3|u|²` (a correction that
/// grows with the cube of the displacement), training sequence 0 holds only small loads
/// and sequences 1–4 and the validation ones span loads six times larger. A network that
/// has seen sequence 0 alone never saw the large-load correction it is scored on.
fn warp_dataset_where_more_data_helps() -> weft_data::WarpDataset {
    use weft_sim::warp::FieldDirection;
    let (beam, anchors) = clamped_small_beam();
    let directions = [
        Vector3::new(0.0, -1.0, 0.0),
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.0, 1.0, 1.0).normalize(),
        Vector3::new(0.0, 1.0, -1.0).normalize(),
        Vector3::new(0.0, -1.0, 0.5).normalize(),
        Vector3::new(0.0, 0.5, -1.0).normalize(),
        Vector3::new(0.0, -1.0, -1.0).normalize(),
    ];
    let splits = ["train", "train", "train", "train", "train", "validation", "validation"];
    let sequences = directions
        .iter()
        .zip(splits)
        .enumerate()
        .map(|(index, (dir, split))| {
            let peak = if index == 0 { 0.05 } else { 0.3 };
            let mut linear = Vec::new();
            let mut nonlinear = Vec::new();
            for f in 0..=6 {
                let a = peak * f as f64 / 6.0;
                let lin: Vec<f64> = beam
                    .positions()
                    .iter()
                    .flat_map(|p| (dir * (a * p.x * p.x)).as_slice().to_vec())
                    .collect();
                let non: Vec<f64> = lin
                    .chunks_exact(3)
                    .flat_map(|u| {
                        let shrink = 1.0 - 3.0 * (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
                        u.iter().map(move |v| v * shrink)
                    })
                    .collect();
                linear.push(lin);
                nonlinear.push(non);
            }
            weft_data::WarpSequence {
                index,
                split: split.into(),
                field: FieldDirection::Directional(*dir),
                poisson: 0.3,
                linear,
                nonlinear,
            }
        })
        .collect();
    weft_data::WarpDataset {
        dir: std::env::temp_dir(),
        body: beam,
        anchors,
        material: "neo-hookean".into(),
        sequences,
        dropped_frames: 0,
    }
}

#[test]
fn an_nnwarp_model_continues_under_a_longer_patience_and_refuses_a_shorter_one() {
    use weft_nn::nnwarp::{WarpTrainingSettings, train_model};
    let data = warp_dataset_where_more_data_helps().with_training_prefix(1);
    let dir = std::env::temp_dir().join(format!("weft-nnwarp-patience-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let with = |epochs: usize, patience: usize| {
        let mut c = WarpTrainingSettings {
            hidden: vec![8],
            batch: 32,
            epochs,
            ..WarpTrainingSettings::default()
        };
        c.schedule.early_stopping_patience = Some(patience);
        c
    };
    let silent = &mut weft_nn::trainer::Silent;
    let (first, _, _) = train_model(&dir, &data, &with(2, 1), silent).unwrap();
    let (longer, _, _) = train_model(&dir, &data, &with(4, 3), silent).unwrap();
    assert!(longer.epochs_done > first.epochs_done || longer.stopped_early);
    assert_eq!(longer.config.schedule.early_stopping_patience, Some(3));
    let e = train_model(&dir, &data, &with(6, 1), silent).unwrap_err().to_string();
    assert!(e.contains("early_stopping_patience: 3 vs 1"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn nnwarp_trained_on_more_sequences_scores_better_on_validation_where_few_miss_the_loads() {
    use weft_nn::nnwarp::{WarpTrainingSettings, collect_pairs, correction_rms, load_model, train_model};
    let full = warp_dataset_where_more_data_helps();
    let (vx, vy) = collect_pairs(&full, "validation").unwrap();
    let mut rms = Vec::new();
    let mut last = None;
    for k in [1, 5] {
        let dir = std::env::temp_dir().join(format!("weft-nnwarp-size-{k}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let config = WarpTrainingSettings {
            hidden: vec![16, 16],
            batch: 32,
            epochs: 150,
            adam: AdamSettings {
                learning_rate: 3e-3,
                ..AdamSettings::default()
            },
            ..WarpTrainingSettings::default()
        };
        let subset = full.with_training_prefix(k);
        assert_eq!(subset.training_count(), k);
        let (state, pairs, _) = train_model(&dir, &subset, &config, &mut weft_nn::trainer::Silent).unwrap();
        assert_eq!(pairs, k * 6 * 36, "six loaded frames of 36 free nodes per sequence");
        assert!(
            state.best_epoch > 0,
            "k = {k}: training never beat the starting weights"
        );
        let (_, mlp) = load_model(&dir).unwrap();
        rms.push(correction_rms(&mlp, &vx, &vy).unwrap());
        last = Some(mlp);
        std::fs::remove_dir_all(&dir).unwrap();
    }
    // The correction's own size on the validation pairs: predicting zero scores this.
    let scale = (vy.iter().flatten().map(|v| v * v).sum::<f64>() / (3 * vy.len()) as f64).sqrt();
    assert!(
        rms[1] < 0.5 * rms[0],
        "five sequences {:.3e} vs one {:.3e}",
        rms[1],
        rms[0]
    );
    assert!(
        rms[1] < 0.3 * scale,
        "five sequences {:.3e} against the correction's {scale:.3e}",
        rms[1]
    );
    assert!(matches!(
        correction_rms(&last.unwrap(), &vx[1..], &vy),
        Err(Error::Shape { .. })
    ));
}

#[test]
fn the_published_nnwarp_models_load_and_correct_nothing_at_rest() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/results/models/nnwarp");
    for material in ["co-rotational", "stvk", "neo-hookean"] {
        let (config, mlp) = weft_nn::nnwarp::load_model(&root.join(material)).unwrap();
        assert_eq!(config.material, material);
        assert_eq!(config.hidden, weft_nn::nnwarp::hidden_layers(material));
        // Kinematic inputs zero (a node that does not move): no correction; moved: some.
        let still = [0.0, 0.0, 0.0, 0.5, 0.4, 1.0, 0.3];
        assert!(mlp.forward(&still).iter().all(|c| c.abs() < 1e-12), "{material}");
        let moved = [0.8, 0.1, 0.2, 0.5, 0.4, 1.0, 0.3];
        let c = mlp.forward(&moved);
        assert!(
            c.iter().all(|v| v.is_finite()) && c.iter().any(|v| v.abs() > 1e-6),
            "{material}: {c:?}"
        );
    }
}

/// Stage 2 reads the frozen autoencoder's codes and predecessor positions from a cache
/// built once per stage; its losses, every term, and the latent simulator's gradients equal
/// the uncached computation's (`EmbedModel::losses`), on windows taken out of order.
#[test]
fn stage_two_with_the_frozen_autoencoder_cached_has_the_uncached_losses_and_gradients() {
    use weft_nn::embed::{EmbedData, EmbedModel, EmbedStage, EmbedTrainingSettings};
    use weft_nn::trainer::{BatchAt, BatchLoss, Trainable};
    let data = EmbedData::new(quick_sheet_dataset(20)).unwrap();
    let config = EmbedTrainingSettings {
        latent_hidden: vec![16],
        ..small_embed_config()
    };
    assert!(config.weights.mphys != 0.0 && config.weights.sim != 0.0);
    let model = EmbedModel::new(config, &data).unwrap();
    let n = data.train_windows.len();
    assert!(n >= 6, "{n} training windows");
    let batch: Vec<usize> = vec![n - 1, 0, n / 2, 2];
    let frames: Vec<_> = batch.iter().map(|&i| data.train_windows[i]).collect();
    let sim_grads = |loss: &Tensor| -> Vec<Tensor> {
        let grads = loss.backward().unwrap();
        model
            .simulator_params
            .vars()
            .values()
            .map(|v| grads.get(v.as_tensor()).unwrap().clone())
            .collect()
    };
    let (want, want_terms) = model.losses(&data, &frames, 2, model.config.weights.ephys).unwrap();
    let want_grads = sim_grads(&want);
    let mut stage = EmbedStage::new(&model, &data, 2);
    let at = BatchAt {
        epoch: 0,
        batch: 0,
        batches: 1,
    };
    let BatchLoss::Loss { loss, terms } = stage.batch_loss(&batch, at).unwrap() else {
        panic!("stage 2 skipped a batch")
    };
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-5 * b.abs().max(1e-12);
    let got = loss.to_scalar::<f32>().unwrap() as f64;
    assert!(close(got, want_terms.total), "{got} vs {}", want_terms.total);
    for (name, value) in terms {
        let reference = match name {
            "sim" => want_terms.sim,
            "mphys" => want_terms.mphys,
            _ => continue,
        };
        assert!(
            reference > 0.0 && close(value, reference),
            "{name}: {value} vs {reference}"
        );
    }
    for (g, w) in sim_grads(&loss).iter().zip(&want_grads) {
        assert!(
            relative_gap(g, w) < 1e-5,
            "simulator gradient off by {}",
            relative_gap(g, w)
        );
    }
    // The validation score reads the same cache.
    let windows = &data.validation_windows;
    let mut sum = 0.0;
    for chunk in windows.chunks(model.config.batch) {
        sum += model
            .losses(&data, chunk, 2, model.config.weights.ephys)
            .unwrap()
            .1
            .total
            * chunk.len() as f64;
    }
    let score = stage.validation_score().unwrap();
    assert!(
        close(score, sum / windows.len() as f64),
        "{score} vs {}",
        sum / windows.len() as f64
    );
}

#[test]
fn a_later_embedding_stage_without_its_earlier_one_or_stages_out_of_order_are_refused() {
    use weft_nn::embed::{EmbedData, EmbedModel, EmbedTrainingSettings, train_stages};
    let data = EmbedData::new(quick_sheet_dataset(20)).unwrap();
    let config = small_embed_config();
    let model = EmbedModel::new(config.clone(), &data).unwrap();
    let dir = std::env::temp_dir().join(format!("weft-nn-stages-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let silent = &mut weft_nn::trainer::Silent;
    // Stage 3 alone on an empty directory would train the simulator on an untrained
    // autoencoder.
    let e = train_stages(&dir, &model, &data, &[3], "t", silent).unwrap_err();
    assert!(matches!(e, Error::MissingStage { stage: 1, .. }), "{e}");
    // The command line's path refuses it before writing anything, so a retry is not
    // blocked by a half-made model directory.
    let e = weft_nn::embed::train_model(&dir, &data, &config, &[2, 3], silent).unwrap_err();
    assert!(matches!(e, Error::MissingStage { stage: 1, .. }), "{e}");
    assert!(!dir.exists(), "a refused request writes nothing");
    for stages in [&[3, 1][..], &[1, 1], &[2, 1, 3], &[4]] {
        let e = train_stages(&dir, &model, &data, stages, "t", silent).unwrap_err();
        assert!(
            matches!(&e, Error::InvalidSettings { field, .. } if field == "stages"),
            "{stages:?}: {e}"
        );
    }
    // A stage the configuration skips (0 epochs) is not needed before a later one.
    let skip_one = EmbedModel::new(
        EmbedTrainingSettings {
            epochs: [0, 0, 0],
            ..config
        },
        &data,
    )
    .unwrap();
    assert!(
        train_stages(&dir, &skip_one, &data, &[3], "t", silent)
            .unwrap()
            .is_empty()
    );
    assert!(!dir.join("stage-1").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every stage of the embeddings in `a` and `b` trained the same epochs, bit for bit.
fn assert_same_stage_histories(a: &std::path::Path, b: &std::path::Path) {
    use weft_nn::embed::stage_dir;
    for stage in 1..=3u8 {
        let history = |dir: &std::path::Path| -> Vec<(u64, u64)> {
            weft_nn::trainer::TrainingState::read(&stage_dir(dir, stage))
                .unwrap()
                .history
                .iter()
                .map(|h| (h.loss.to_bits(), h.validation.to_bits()))
                .collect()
        };
        assert_eq!(history(a), history(b), "stage {stage}");
    }
}

#[test]
fn an_embedding_trained_on_with_more_stage_1_epochs_is_the_model_a_fresh_run_trains() {
    use weft_nn::embed::{EmbedData, EmbedTrainingSettings, train_model};
    let data = EmbedData::new(quick_sheet_dataset(20)).unwrap();
    let short = EmbedTrainingSettings {
        epochs: [1, 1, 1],
        ..small_embed_config()
    };
    let long = EmbedTrainingSettings {
        epochs: [2, 1, 1],
        ..short.clone()
    };
    let base = std::env::temp_dir().join(format!("weft-nn-train-on-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let (fresh, extended) = (base.join("fresh"), base.join("extended"));
    let silent = &mut weft_nn::trainer::Silent;
    train_model(&fresh, &data, &long, &[1, 2, 3], silent).unwrap();
    train_model(&extended, &data, &short, &[1, 2, 3], silent).unwrap();
    assert!(weft_nn::embed::continues_exactly(&extended, &long));
    assert!(!weft_nn::embed::continues_exactly(&fresh, &short));
    train_model(&extended, &data, &long, &[1, 2, 3], silent).unwrap();
    // Stages 2 and 3 started from stage 1's one-epoch weights; they are trained again from
    // its two-epoch ones, so every stage matches the fresh run's.
    assert_same_stage_histories(&fresh, &extended);
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn an_embedding_under_another_stage_3_learning_rate_keeps_stages_1_and_2_and_trains_stage_3_afresh() {
    use weft_nn::embed::{EmbedData, EmbedTrainingSettings, continues_exactly, stage_dir, train_model};
    let data = EmbedData::new(quick_sheet_dataset(20)).unwrap();
    let before = EmbedTrainingSettings {
        epochs: [1, 1, 2],
        ..small_embed_config()
    };
    let after = EmbedTrainingSettings {
        fine_tune_learning_rate: Some(1e-4),
        ..before.clone()
    };
    assert_eq!(before.stages_continuing_as(&after), 2);
    assert_eq!(after.stages_continuing_as(&before), 2);
    assert_eq!(after.stages_continuing_as(&after), 3);
    let reseeded = EmbedTrainingSettings {
        seed: 7,
        ..after.clone()
    };
    assert_eq!(before.stages_continuing_as(&reseeded), 0);
    assert_eq!(before.stage_adam(1), before.adam);
    assert_eq!(after.stage_adam(3).learning_rate, 1e-4);
    assert_eq!(after.stage_adam(2), before.adam);
    assert!(
        EmbedTrainingSettings {
            fine_tune_learning_rate: Some(-1.0),
            ..after.clone()
        }
        .validate()
        .is_err()
    );

    let base = std::env::temp_dir().join(format!("weft-nn-fine-tune-rate-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let (fresh, switched) = (base.join("fresh"), base.join("switched"));
    let silent = &mut weft_nn::trainer::Silent;
    train_model(&fresh, &data, &after, &[1, 2, 3], silent).unwrap();
    train_model(&switched, &data, &before, &[1, 2, 3], silent).unwrap();
    let state = |dir: &std::path::Path, stage: u8| std::fs::read(stage_dir(dir, stage).join("training.json")).unwrap();
    let (stage_1, stage_2, old_stage_3) = (state(&switched, 1), state(&switched, 2), state(&switched, 3));
    assert!(continues_exactly(&switched, &after));
    train_model(&switched, &data, &after, &[1, 2, 3], silent).unwrap();
    // Stages 1 and 2 were kept as they were, stage 3 trained again at the new rate: the
    // model is the one a fresh run at that rate trains, stage by stage and bit for bit.
    assert_eq!(state(&switched, 1), stage_1);
    assert_eq!(state(&switched, 2), stage_2);
    assert_ne!(state(&switched, 3), old_stage_3);
    assert_same_stage_histories(&fresh, &switched);
    // Without the field, a stored configuration reads as before it existed.
    let text = serde_json::to_string(&before).unwrap();
    assert!(!text.contains("fine_tune_learning_rate"));
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn a_partial_configuration_keeps_the_defaults_of_the_fields_it_omits_at_every_depth() {
    use weft_nn::embed::EmbedTrainingSettings;
    let c: EmbedTrainingSettings =
        serde_json::from_str(r#"{"adam": {"learning_rate": 2e-4}, "autoencoder": {"latent": 64}}"#).unwrap();
    let d = EmbedTrainingSettings::default();
    assert_eq!(
        c.adam,
        AdamSettings {
            learning_rate: 2e-4,
            ..d.adam
        }
    );
    assert_eq!(
        c.autoencoder,
        AutoencoderSettings {
            latent: 64,
            ..d.autoencoder
        }
    );
    assert_eq!(c.epochs, d.epochs);
    // A full configuration reads back as written.
    let round: EmbedTrainingSettings = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
    assert_eq!(round, c);
}

#[test]
fn continuing_a_model_under_another_configuration_names_each_differing_field() {
    let stored = small_embed_config();
    let mut asked = stored.clone();
    asked.autoencoder.latent = 16;
    asked.adam.learning_rate = 5e-4;
    let path = std::path::Path::new("m/config.json");
    assert!(checkpoint::check_continues(path, true, &stored, &asked).is_ok());
    let e = checkpoint::check_continues(path, false, &stored, &asked)
        .unwrap_err()
        .to_string();
    assert!(e.contains("m/config.json"), "{e}");
    assert!(e.contains("autoencoder.latent: 8 vs 16"), "{e}");
    assert!(e.contains("adam.learning_rate: 0.001 vs 0.0005"), "{e}");
    assert!(
        !e.contains("epochs:") && !e.contains("seed:"),
        "only the differing fields are named: {e}"
    );
}

#[test]
fn a_model_directory_of_another_kind_is_named_by_its_kind() {
    use weft_nn::checkpoint::{check_model_kind, stored_model_kind};
    let kinds = [
        (
            serde_json::json!({"config": {"batch": 16}, "layer": "None", "init_weights_sha256": null}),
            "drape",
        ),
        (serde_json::to_value(small_embed_config()).unwrap(), "embed"),
        (
            serde_json::json!({"variant": "Alt", "steps": 20, "hidden": [8]}),
            "altconv",
        ),
        (serde_json::json!({"material": "stvk", "hidden": []}), "nnwarp"),
    ];
    let dir = std::env::temp_dir().join(format!("weft-nn-kinds-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (config, kind) in &kinds {
        assert_eq!(stored_model_kind(config), Some(*kind));
        std::fs::write(dir.join("config.json"), config.to_string()).unwrap();
        assert!(check_model_kind(&dir, kind).is_ok());
        for (_, other) in kinds.iter().filter(|(_, k)| k != kind) {
            let e = check_model_kind(&dir, other).unwrap_err().to_string();
            assert!(e.contains(&format!("a `{kind}` model, not a `{other}` one")), "{e}");
        }
    }
    // Unrecognised or missing configurations are left to the loaders.
    assert_eq!(stored_model_kind(&serde_json::json!({"x": 1})), None);
    std::fs::remove_file(dir.join("config.json")).unwrap();
    assert!(check_model_kind(&dir, "drape").is_ok());
    std::fs::remove_dir_all(&dir).unwrap();
}
