"""weft's cloth ground truth against NVIDIA Newton on the CPU: the speed-accuracy plane.

The scene is weft's built-in `sheet-ms` (Tan et al.'s mass-spring sheet: 65 x 65 vertices on
a 1 m square hung in the XZ plane, 0.2 kg/m^2 lumped masses, 12,416 stretch springs of
1000 N/m on the mesh edges and 32,384 bend springs of 20 N/m on the 2-ring pairs, gravity
9.81 m/s^2, the two top corners driven by the scene's grasp program, 0.02 s frames). The
same model is built in Newton (`newton` and `warp-lang` from the package registry) with
`ModelBuilder.add_particles` / `add_spring`, no damping, no contact, the grasped particles
kinematic (mass 0) and driven to the program's analytic position at every substep.

Every method's frames are scored against one reference computed in this run: weft's implicit
Euler at a quarter of the frame time (0.005 s) with the Newton tolerance at 1e-6 of the
heaviest vertex's weight (the reference of the evaluation's `sim` experiment). The error is
M_rms (1000 x the per-coordinate RMS of the position difference in metres, over every vertex
and every frame 1..N: mm), the same over frames 1..15 alone (after about frame 15 the sheet's
folds swing one of two ways, and which way a run takes then dominates the whole window's
error), and the largest vertex distance (mm). Time is wall time per 0.02 s
frame of the stepping alone: weft's from its own per-frame report (its solver threads: both
cores), Newton's around the substep loop after a warm-up that compiles the kernels (Warp's
CPU backend runs one thread).

Before timing anything the script checks its Newton model against weft's: the spring forces,
masses and gravity it builds must make weft's first frame an implicit-Euler equilibrium to
weft's own tolerance, and the analytic grasp program must reproduce weft's recorded controls.

    python3 benches/python/cloth_vs_newton.py --xtask target/release/xtask --frames 60 \
        --out out/cloth-vs-newton [--json out/evaluate-standard/peers/cloth-vs-newton.json] \
        [--weft 1x1e-3:b2 1x1e-3:b4f1 ...]

Needs numpy, `newton==1.8.0` and `warp-lang==1.19.0` (docs/BENCHMARKS.md has the command
that made the committed figures). The frames and the reference go to --out; the points to
--json (`cargo xtask evaluate` draws them on the `sim` / sheet-ms Pareto plot when the file is in
its output directory's peers/, and publishes them with the report) and a table to stdout.
"""

import argparse
import json
import math
import os
import struct
import subprocess
import sys
import time

import numpy as np

FRAME_DT = 0.02
GRASP = [4160, 4224]


# ---------------------------------------------------------------- weft's files and scene

def read_safetensors(path):
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        header = json.loads(f.read(n))
        data = f.read()
    out = {}
    kinds = {"F64": "<f8", "F32": "<f4", "I64": "<i8", "U8": "u1"}
    for k, v in header.items():
        if k == "__metadata__":
            continue
        a, b = v["data_offsets"]
        out[k] = np.frombuffer(data[a:b], dtype=kinds[v["dtype"]]).reshape(v["shape"])
    return out


def read_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            p = line.split()
            if not p:
                continue
            if p[0] == "v":
                v.append([float(x) for x in p[1:4]])
            elif p[0] == "f":
                f.append([int(x.split("/")[0]) - 1 for x in p[1:4]])
    return np.array(v, dtype=np.float64), np.array(f, dtype=np.int64)


def scene_toml(base, dt, frames, relative_tolerance, budget=None, factorizations=None):
    """weft's resolved scene file with the step, frame count and tolerance replaced; with a
    budget, inexact steps: that many Newton iterations per step on projected Hessians, of
    which at most `factorizations` factorise (the others reuse the last factor)."""
    out, seen = [], set()
    for line in base.splitlines():
        key = line.split("=")[0].strip()
        if key == "dt":
            line, _ = f"dt = {dt!r}", seen.add(key)
        elif key == "frames":
            line, _ = f"frames = {frames}", seen.add(key)
        elif key == "relative_tolerance":
            line, _ = f"relative_tolerance = {relative_tolerance!r}", seen.add(key)
            if budget is not None:
                line += f'\nhessian = "always"\nnewton_budget = {budget}'
                if factorizations is not None:
                    line += f"\nnewton_factorizations = {factorizations}"
        elif key in ("hessian", "newton_budget", "newton_factorizations") and budget is not None:
            continue
        out.append(line)
    if seen != {"dt", "frames", "relative_tolerance"}:
        sys.exit(f"scene file lacks {sorted({'dt', 'frames', 'relative_tolerance'} - seen)}")
    return "\n".join(out) + "\n"


def run_weft(xtask, scene, frames, out):
    os.makedirs(out, exist_ok=True)
    cmd = [xtask, "simulate", scene, "--frames", str(frames), "--out", out, "--quiet"]
    print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)
    stats = json.load(open(os.path.join(out, "stats.json")))
    frames_ = read_safetensors(os.path.join(out, "frames.safetensors"))
    return stats, frames_


# ---------------------------------------------------------------- the model in numpy

def unique_edges(faces):
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


def two_ring_pairs(edges, n):
    """Pairs (i, j), i < j, with j a neighbour of a neighbour of i but neither i nor one of
    its neighbours: weft's bend springs."""
    nb = [set() for _ in range(n)]
    for a, b in edges:
        nb[a].add(b)
        nb[b].add(a)
    pairs = set()
    for i in range(n):
        ring2 = set()
        for j in nb[i]:
            ring2 |= nb[j]
        ring2 -= nb[i]
        ring2.discard(i)
        pairs.update((i, j) for j in ring2 if i < j)
    return np.array(sorted(pairs), dtype=np.int64)


def lumped_masses(v, f, density):
    a = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    m = np.zeros(len(v))
    for k in range(3):
        np.add.at(m, f[:, k], density * a / 3.0)
    return m


def spring_gradient(x, pairs, rest, k):
    d = x[pairs[:, 0]] - x[pairs[:, 1]]
    length = np.linalg.norm(d, axis=1)
    f = (k * (length - rest) / length)[:, None] * d
    g = np.zeros_like(x)
    np.add.at(g, pairs[:, 0], f)
    np.add.at(g, pairs[:, 1], -f)
    return g


def splitmix64(seed):
    state = seed & 0xFFFFFFFFFFFFFFFF
    while True:
        state = (state + 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF
        z = state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
        yield z ^ (z >> 31)


def grasp_program(scene, rest_grasp):
    """q(t) for the grasped vertices: the scene's segments in order, repeated, each amplitude
    jittered by 1 + 0.1 (2u - 1) with u from SplitMix64(seed) (weft's ClothSimulation)."""
    rng = splitmix64(scene["seed"])
    program = scene["program"]
    jitter = [1.0 + 0.1 * (2.0 * ((next(rng) >> 11) / float(1 << 53)) - 1.0) for _ in program]
    total = sum(s["period"] * s["cycles"] for s in program)
    centroid = rest_grasp.mean(axis=0)

    def q(time_):
        t = math.fmod(time_, total)
        for i, s in enumerate(program):
            length = s["period"] * s["cycles"]
            if t < length or i + 1 == len(program):
                break
            t -= length
        offset = s["amplitude"] * jitter[i] * math.sin(2.0 * math.pi / s["period"] * t)
        m = s["motion"]
        if m.startswith("translate"):
            axis = np.zeros(3)
            axis["xyz".index(m[-1])] = 1.0
            return rest_grasp + offset * axis
        if m == "rotate-z":
            c, sn = math.cos(offset), math.sin(offset)
            r = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
            return centroid + (rest_grasp - centroid) @ r.T
        sys.exit(f"unknown motion {m}")

    return q


# ---------------------------------------------------------------- Newton

def newton_run(kind, substeps, iterations, frames, model_data, q, warmup=True):
    import newton
    import warp as wp

    rest, x0, masses, pairs, ke = model_data
    builder = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=(0.0, 0.0, -9.81))
    m = masses.copy()
    m[GRASP] = 0.0  # kinematic: driven below
    builder.add_particles(
        pos=[tuple(p) for p in rest], vel=[(0.0, 0.0, 0.0)] * len(rest), mass=m.tolist(),
        radius=[0.0] * len(rest),
    )
    for (i, j), k in zip(pairs.tolist(), ke.tolist()):
        builder.add_spring(i=i, j=j, ke=k, kd=0.0, control=0.0)
    if kind == "vbd":
        builder.color()  # VBD solves vertex by vertex, one colour group at a time
    model = builder.finalize(device="cpu")
    assert model.particle_count == len(rest) and model.spring_count == len(pairs)
    if kind == "semi-implicit":
        solver = newton.solvers.SolverSemiImplicit(model)
    elif kind == "xpbd":
        solver = newton.solvers.SolverXPBD(model, iterations=iterations)
    elif kind == "vbd":
        solver = newton.solvers.SolverVBD(model, iterations=iterations)
    else:
        sys.exit(f"unknown Newton solver {kind}")
    h = FRAME_DT / substeps
    steps = frames * substeps
    targets = np.stack([q(k * h) for k in range(steps + 1)]).astype(np.float32)
    targets_wp = wp.array(targets, dtype=wp.vec3, device="cpu")
    idx = wp.array(np.array(GRASP, dtype=np.int32), dtype=wp.int32, device="cpu")

    @wp.kernel
    def drive(idx: wp.array(dtype=wp.int32), targets: wp.array2d(dtype=wp.vec3), k: int, inv_h: float,
              x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3)):
        t = wp.tid()
        x[idx[t]] = targets[k, t]
        v[idx[t]] = (targets[k + 1, t] - targets[k, t]) * inv_h

    control = model.control()

    def simulate(n_frames, record):
        s0, s1 = model.state(), model.state()
        s0.particle_q.assign(x0.astype(np.float32))
        s0.particle_qd.zero_()
        out = np.empty((n_frames + 1, len(rest), 3))
        out[0] = s0.particle_q.numpy()
        wp.synchronize_device("cpu")
        t0 = time.perf_counter()
        for f in range(n_frames):
            for s in range(substeps):
                wp.launch(drive, dim=len(GRASP), inputs=[idx, targets_wp, f * substeps + s, 1.0 / h,
                                                          s0.particle_q, s0.particle_qd], device="cpu")
                s0.clear_forces()
                solver.step(s0, s1, control, None, h)
                s0, s1 = s1, s0
            if record:
                out[f + 1] = s0.particle_q.numpy()
        wp.synchronize_device("cpu")
        return out, time.perf_counter() - t0

    if warmup:
        simulate(1, False)  # compiles the kernels
    return simulate(frames, True)


# ---------------------------------------------------------------- scoring

DIVERGED_M = 1.0


def score(x, reference):
    """M_rms (mm) over frames 1..N and every vertex, and the largest vertex distance (mm);
    None for a run that diverged: non-finite positions, or a vertex more than DIVERGED_M
    (the sheet's width) from the reference."""
    d = x[1:] - reference[1:]
    if not np.all(np.isfinite(d)) or np.max(np.linalg.norm(d, axis=2)) > DIVERGED_M:
        return None, None
    return 1000.0 * math.sqrt(np.mean(d * d)), 1000.0 * float(np.max(np.linalg.norm(d, axis=2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--xtask", default="target/release/xtask", help="weft's xtask binary (cargo build --release -p xtask)")
    ap.add_argument("--frames", type=int, default=60,
                    help="0.02 s frames simulated by every method (60: the standard evaluation's `sim` window)")
    ap.add_argument("--out", default="out/cloth-vs-newton", help="directory for weft's frames and the reference")
    ap.add_argument("--json", help="write the points here (OUT/peers/cloth-vs-newton.json of an evaluation directory: its sim / sheet-ms Pareto plot)")
    ap.add_argument("--semi-implicit", type=int, nargs="*", default=[150, 200, 400, 800],
                    help="substeps per frame of Newton's semi-implicit solver")
    ap.add_argument("--xpbd", nargs="*", default=["1x200", "1x400", "2x200", "4x100"],
                    help="ITERATIONSxSUBSTEPS settings of Newton's XPBD solver")
    ap.add_argument("--vbd", nargs="*", default=["1x1", "2x100"],
                    help="ITERATIONSxSUBSTEPS settings of Newton's VBD solver")
    ap.add_argument("--weft", nargs="*", default=[],
                    help="further weft settings, STEPSxTOLERANCE[:bBUDGET]: implicit Euler with STEPS steps per frame and "
                         "Newton tolerance TOLERANCE x the heaviest vertex's weight (the scene's own, 1x1e-3, always "
                         "runs); with :bBUDGET, inexact steps of at most BUDGET Newton iterations on projected Hessians, "
                         "and with :bBUDGETfF at most F of them factorising (chord steps with the last factor after)")
    ap.add_argument("--early-frames", type=int, default=15,
                    help="also score frames 1..EARLY alone (m-rms-frames-1-EARLY): after about frame 15 the sheet's "
                         "folds swing one of two ways, and which way a run takes dominates the whole window's error")
    ap.add_argument("--reuse-reference", action="store_true", help="keep OUT/reference if it is there")
    args = ap.parse_args()
    n = args.frames
    os.makedirs(args.out, exist_ok=True)

    # weft at the scene's step: its frames, its time and the scene file it resolved.
    weft_stats, weft = run_weft(args.xtask, "sheet-ms", n, os.path.join(args.out, "weft"))
    if weft_stats["error"]:
        sys.exit(f"weft stopped: {weft_stats['error']}")
    base = open(os.path.join(args.out, "weft", "scene.toml")).read()
    import tomllib
    scene = tomllib.loads(base)
    if abs(scene["dt"] - FRAME_DT) > 1e-15:
        sys.exit(f"sheet-ms has dt = {scene['dt']}, the script assumes {FRAME_DT}")

    # The reference: a quarter of the step, a tight tolerance.
    ref_dir = os.path.join(args.out, "reference")
    ref_file = os.path.join(ref_dir, "frames.safetensors")
    if not (args.reuse_reference and os.path.exists(ref_file)):
        os.makedirs(ref_dir, exist_ok=True)
        toml = os.path.join(args.out, "reference.toml")
        with open(toml, "w") as fh:
            fh.write(scene_toml(base, FRAME_DT / 4.0, 4 * n, 1e-6))
        run_weft(args.xtask, toml, 4 * n, ref_dir)
    reference = read_safetensors(ref_file)["positions"][::4]
    if reference.shape[0] < n + 1:
        sys.exit(f"the reference has {reference.shape[0] - 1} frames, fewer than {n}")
    reference = reference[: n + 1]

    # The model in numpy, checked against weft's first frame.
    rest, faces = read_obj(os.path.join(args.out, "weft", "rest.obj"))
    x = weft["positions"]
    model = scene["model"]
    if model["kind"] != "mass-spring" or scene["mesh"]["generator"] != "sheet":
        sys.exit("the script builds the mass-spring sheet only")
    edges = unique_edges(faces)
    bends = two_ring_pairs(edges, len(rest))
    pairs = np.concatenate([edges, bends])
    ke = np.concatenate([np.full(len(edges), model["stretch_stiffness"] * scene["stretch_scale"]),
                         np.full(len(bends), model["bend_stiffness"] * scene["bend_scale"])])
    rest_len = np.linalg.norm(rest[pairs[:, 0]] - rest[pairs[:, 1]], axis=1)
    masses = lumped_masses(rest, faces, scene["density"])
    g = np.array(scene["gravity"])
    free = np.ones(len(rest), bool)
    free[GRASP] = False
    residual = (masses[:, None] * (x[1] - x[0]) / FRAME_DT**2 + spring_gradient(x[1], pairs, rest_len, ke)
                - masses[:, None] * g)[free]
    tolerance = 1e-3 * masses.max() * 9.81
    print(f"model: {len(rest)} vertices, {len(edges)} stretch + {len(bends)} bend springs, "
          f"{masses.sum():.6f} kg; weft's frame 1 residual under it {np.abs(residual).max():.3e} N "
          f"(weft's tolerance {tolerance:.3e} N)")
    if np.abs(residual).max() > 2.0 * tolerance:
        sys.exit("the numpy model does not reproduce weft's equations")
    q = grasp_program(scene, rest[GRASP])
    controls = weft["controls"]
    ctl_err = max(np.abs(q(m * FRAME_DT) - controls[m]).max() for m in range(n + 1))
    print(f"grasp program against weft's controls: max |diff| {ctl_err:.2e} m")
    if ctl_err > 1e-12:
        sys.exit("the grasp program does not reproduce weft's controls")

    import newton
    import warp as wp
    wp.config.quiet = True
    wp.init()
    points = []
    seconds = [f["seconds"] for f in weft_stats["per_frame"]]
    err, mx = score(x, reference)
    runs = {"weft-implicit-euler": x}
    points.append({"method": "weft-implicit-euler", "solver": "weft", "setting": "dt 0.02 s, Newton 1e-3 x weight",
                   "seconds_per_frame": sum(seconds) / n, "threads": 2,
                   "errors": {"m-rms": err, "max-error": mx},
                   "newton_iterations_per_frame": weft_stats["mean_newton_iterations"]})
    print(f"weft implicit Euler: {1000 * points[-1]['seconds_per_frame']:.1f} ms/frame, M_rms {err:.3f} mm", flush=True)
    for spec in args.weft:
        spec_main, _, budget = spec.partition(":b")
        budget, _, factorizations = budget.partition("f")
        steps, tol = spec_main.split("x")
        steps, tol = int(steps), float(tol)
        budget = int(budget) if budget else None
        factorizations = int(factorizations) if factorizations and budget else None
        tag = f"{steps}x{tol:g}" + (f"-budget-{budget}" if budget else "") + (
            f"-factorizations-{factorizations}" if factorizations else "")
        d = os.path.join(args.out, f"weft-{tag}")
        os.makedirs(d, exist_ok=True)
        toml = os.path.join(d, "scene-in.toml")
        with open(toml, "w") as fh:
            fh.write(scene_toml(base, FRAME_DT / steps, steps * n, tol, budget, factorizations))
        stats, frames_ = run_weft(args.xtask, toml, steps * n, d)
        if stats["error"]:
            print(f"weft {spec}: stopped ({stats['error']})", flush=True)
            continue
        err, mx = score(frames_["positions"][::steps], reference)
        secs = sum(f["seconds"] for f in stats["per_frame"]) / n
        method = f"weft-implicit-euler-{tag}"
        runs[method] = frames_["positions"][::steps]
        setting = f"dt {FRAME_DT / steps:g} s, " + (
            f"{budget} projected Newton iteration(s) per step" if budget else f"Newton {tol:g} x weight") + (
            f", {factorizations} factorisation(s) (chord steps after)" if factorizations else "")
        points.append({"method": method, "solver": "weft",
                       "setting": setting, "seconds_per_frame": secs,
                       "threads": 2, "errors": {"m-rms": err, "max-error": mx},
                       "newton_iterations_per_frame": stats["mean_newton_iterations"] * steps})
        print(f"weft {spec}: {1000 * secs:.1f} ms/frame, M_rms {err:.3f} mm", flush=True)
    settings = [("semi-implicit", s, 1) for s in args.semi_implicit]
    for kind, specs in (("xpbd", args.xpbd), ("vbd", args.vbd)):
        for spec in specs:
            it, sub = (int(v) for v in spec.split("x"))
            settings.append((kind, sub, it))
    for kind, sub, it in settings:
        frames_, wall = newton_run(kind, sub, it, n, (rest, x[0], masses, pairs, ke), q)
        err, mx = score(frames_, reference)
        name = f"nvidia-newton-{kind}-{sub}" if kind == "semi-implicit" else f"nvidia-newton-{kind}-{it}x{sub}"
        runs[name] = frames_
        points.append({"method": name, "solver": f"NVIDIA Newton {newton.__version__} {kind}",
                       "setting": f"{sub} substeps" + ("" if kind == "semi-implicit" else f", {it} iterations"),
                       "seconds_per_frame": wall / n, "threads": 1, "errors": {"m-rms": err, "max-error": mx}})
        shown = "diverged" if err is None else f"M_rms {err:.3f} mm, max {mx:.1f} mm"
        print(f"{name}: {1000 * wall / n:.1f} ms/frame, {shown}", flush=True)

    # The second reference: the finest semi-implicit run, which has no numerical damping
    # (backward Euler's, shared by weft's points and the reference, is part of the first
    # reference's distance).
    finest = [p["method"] for p in points if p["method"].startswith("nvidia-newton-semi-implicit-")
              and p["errors"]["m-rms"] is not None]
    if finest:
        finest = max(finest, key=lambda m: int(m.rsplit("-", 1)[1]))
        for p in points:
            p["errors"]["m-rms-vs-" + finest] = score(runs[p["method"]], runs[finest])[0]
    # The early window: before the folds' swing (docs/BENCHMARKS.md, "Chord steps").
    early = min(args.early_frames, n)
    for p in points:
        p["errors"][f"m-rms-frames-1-{early}"] = score(runs[p["method"]][: early + 1], reference[: early + 1])[0]
    doc = {
        "experiment": "sim", "scene": "sheet-ms", "frames": n, "frame_dt_s": FRAME_DT,
        "reference": "weft implicit Euler at dt 0.005 s, Newton tolerance 1e-6 x the heaviest vertex's weight "
                     "(m-rms: 1000 x per-coordinate RMS over frames 1..N and every vertex, mm; max-error: largest "
                     "vertex distance, mm)",
        "baseline": "weft-implicit-euler",
        "versions": {"newton": newton.__version__, "warp": wp.__version__, "numpy": np.__version__},
        "command": " ".join(["python3", "benches/python/cloth_vs_newton.py"] + sys.argv[1:]),
        "points": points,
    }
    if args.json:
        os.makedirs(os.path.dirname(args.json) or ".", exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump(doc, fh, indent=1)
    keys = list(points[0]["errors"])
    print("\n| method | setting | ms per frame | " + " | ".join(f"{k} (mm)" for k in keys) + " |")
    print("|---|---|---|" + "---|" * len(keys))
    for p in points:
        cells = ["diverged" if p["errors"].get(k) is None else f"{p['errors'][k]:.3f}" for k in keys]
        print(f"| {p['method']} | {p['setting']} | {1000 * p['seconds_per_frame']:.1f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
