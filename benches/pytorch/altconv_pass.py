"""PyTorch CPU peer of weft's Alt-ConvLSTM training step (one "sequence pass").

Mirrors, in weft:
  - crates/weft-nn/src/altconv/mod.rs: `Cell::new` (Glorot-uniform weights, forget bias 1,
    output cell at gain 0.01), `Cell::step` (Eq. 5 with peepholes on the accumulation Y),
    `mirrored_skips` (Eq. 10 skips between equal-width cells across the bottleneck),
    `AltConvNet::new` / `AltConvNet::run` for `Variant::Alt` (hidden widths
    [32, 64, 128, 64, 32], 9 input channels, 3-channel output cell, Eq. 11 output,
    teacher forcing, `Scaling::identity()`), and `mean_vertex_error` (Eq. 12);
  - crates/weft-nn/src/graph.rs: `NormalizedAdjacency` (Kipf-Welling D^-1/2 (A+I) D^-1/2
    of the mesh's vertex graph), here a torch sparse CSR float32 matrix;
  - benches/training.rs: `altconv_pass` (synthetic 21-frame sequence, batch 1, 20
    teacher-forced steps, backward, one Adam step at lr 1e-3).

One sequence pass = forward over the 20 teacher-forced steps, the Eq. 12 loss,
loss.backward(), one torch.optim.Adam step (lr 1e-3), zero_grad. Runs on 2 threads.

Usage (pip install torch):
    python3 benches/pytorch/altconv_pass.py --limb 8 40       # weft's 1410-vertex limb surface
    python3 benches/pytorch/altconv_pass.py --limb 14 116     # weft's 6890-vertex limb surface
    python3 benches/pytorch/altconv_pass.py rest.obj          # any OBJ surface (e.g. `cargo xtask simulate limb --frames 1 --out d` writes d/rest.obj)

`--limb ACROSS ALONG` rebuilds weft's limb boundary surface (a port of
weft_mesh::limb::limb, generators::grid_tets and TetMesh::boundary_surface); `--limb 8 40`
reproduces /tmp/limb-surface/rest.obj (1410 vertices), `--limb 14 116` is
LimbParams::smpl_resolution() (6890 vertices).

Prints the torch version, the vertex count, the parameter count (weft's: 271,179) and the
median (min, max) seconds per pass over 10 timed passes after 3 warm-up passes.
"""

import argparse
import math
import statistics
import sys
import time
import warnings

import torch

warnings.filterwarnings("ignore", message="Sparse CSR tensor support is in beta")

INPUT_CHANNELS = 9
HIDDEN = [32, 64, 128, 64, 32]
OUTPUT_INIT_GAIN = 0.01
STEPS = 20


# ----------------------------------------------------------------------------- mesh


def read_obj(path):
    """Vertices and (0-based) triangles of an OBJ's "v" and "f" lines."""
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                verts.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f":
                idx = [int(p.split("/")[0]) - 1 for p in parts[1:]]
                for k in range(1, len(idx) - 1):  # fan-triangulate any polygon
                    faces.append((idx[0], idx[k], idx[k + 1]))
    return verts, faces


def limb_surface(cells_across, cells_along, length=0.6, root_radius=0.06, tip_radius=0.04):
    """weft_mesh::limb::limb's boundary surface: a Kuhn-split hex grid over [0, L] x [-1, 1]^2
    mapped onto a tapered cylinder, then TetMesh::boundary_surface (same vertex order)."""
    nx, ny, nz = cells_along, cells_across, cells_across
    h = (length / nx, 2.0 / ny, 2.0 / nz)

    def vid(i, j, k):
        return (k * (ny + 1) + j) * (nx + 1) + i

    pos = []
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                x, y, z = i * h[0], j * h[1], k * h[2]
                s, t = y - 1.0, z - 1.0
                r2 = math.sqrt(s * s + t * t)
                scale = max(abs(s), abs(t)) / r2 if r2 > 0 else 0.0
                r = root_radius + (tip_radius - root_radius) * min(max(x / length, 0.0), 1.0)
                pos.append((x, r * s * scale, r * t * scale))

    def signed_volume(a, b, c, d):
        ab = [b[q] - a[q] for q in range(3)]
        ac = [c[q] - a[q] for q in range(3)]
        ad = [d[q] - a[q] for q in range(3)]
        cx = (ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2], ab[0] * ac[1] - ab[1] * ac[0])
        return (cx[0] * ad[0] + cx[1] * ad[1] + cx[2] * ad[2]) / 6.0

    perms = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    count = {}
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                for p in perms:
                    c = [i, j, k]
                    t = [vid(i, j, k)] * 4
                    for s, axis in enumerate(p):
                        c[axis] += 1
                        t[s + 1] = vid(*c)
                    if signed_volume(*(pos[v] for v in t)) < 0.0:
                        t[2], t[3] = t[3], t[2]
                    a, b, cc, d = t
                    for f in ((b, cc, d), (a, d, cc), (a, b, d), (a, cc, b)):
                        key = tuple(sorted(f))
                        e = count.get(key)
                        count[key] = (1, f) if e is None else (e[0] + 1, e[1])
    boundary = sorted(f for n, f in count.values() if n == 1)
    remap, verts, faces = {}, [], []
    for f in boundary:
        tri = []
        for v in f:
            if v not in remap:
                remap[v] = len(verts)
                verts.append(list(pos[v]))
            tri.append(remap[v])
        faces.append(tuple(tri))
    return verts, faces


def normalized_adjacency(num_vertices, faces):
    """NormalizedAdjacency::from_edges: D^-1/2 (A + I) D^-1/2 of the faces' edge graph, CSR f32."""
    rows = [{i} for i in range(num_vertices)]
    for a, b, c in faces:
        for u, v in ((a, b), (b, c), (c, a)):
            rows[u].add(v)
            rows[v].add(u)
    inv_sqrt = [1.0 / math.sqrt(len(r)) for r in rows]
    crow, col, val = [0], [], []
    for i, r in enumerate(rows):
        for j in sorted(r):
            col.append(j)
            val.append(inv_sqrt[i] * inv_sqrt[j])
        crow.append(len(col))
    return torch.sparse_csr_tensor(
        torch.tensor(crow, dtype=torch.int64),
        torch.tensor(col, dtype=torch.int64),
        torch.tensor(val, dtype=torch.float64).to(torch.float32),
        size=(num_vertices, num_vertices),
        check_invariants=False,
    )


class Adjacency:
    """`Â_n x` for x of shape [B, V, C] (NormalizedAdjacency::apply)."""

    def __init__(self, matrix):
        self.m = matrix
        self.v = matrix.shape[0]

    def __call__(self, x):
        b, v, c = x.shape
        flat = x.transpose(0, 1).reshape(v, b * c) if b > 1 else x.reshape(v, c)
        out = torch.sparse.mm(self.m, flat)
        return out.reshape(v, b, c).transpose(0, 1) if b > 1 else out.reshape(1, v, c)


# ----------------------------------------------------------------------------- model


class Cell(torch.nn.Module):
    """Cell::new / Cell::step with Peephole::Accumulation."""

    def __init__(self, c_in, c, gain):
        super().__init__()
        self.c = c

        def glorot(shape, fan_in, fan_out):
            bound = gain * math.sqrt(6.0 / (fan_in + fan_out))
            return torch.nn.Parameter(torch.empty(shape).uniform_(-bound, bound))

        self.wx = glorot((c_in, 4 * c), c_in, c)
        self.wh = glorot((c, 4 * c), c, c)
        bias = torch.zeros(4 * c)
        bias[c : 2 * c] = 1.0  # forget gate starts open
        self.b = torch.nn.Parameter(bias)
        self.wif = glorot((c, 2 * c), c, c)
        self.wo = glorot((c, c), c, c)

    def step(self, adj, ax, h, cst, y, skip, unit):
        c = self.c
        gates = ax @ self.wx + adj(h) @ self.wh + self.b
        p = adj(y) @ self.wif
        i = torch.sigmoid(gates[..., 0:c] + p[..., 0:c])
        f = torch.sigmoid(gates[..., c : 2 * c] + p[..., c : 2 * c])
        candidate = torch.tanh(gates[..., 2 * c : 3 * c])
        cell = f * cst + i * candidate
        y = y + cell if unit == 1.0 else y + cell * unit
        if skip is not None:
            y = y + skip
        o = gates[..., 3 * c :] + adj(y) @ self.wo
        h = torch.sigmoid(o) * torch.tanh(cell)
        return h, cell, y


def mirrored_skips(hidden):
    n = len(hidden)
    return [(n - 1 - k, k) for k in range(n // 2) if n - 1 - k > k + 1 and hidden[n - 1 - k] == hidden[k]]


class AltConvNet(torch.nn.Module):
    """AltConvNet::new(.., Variant::Alt, HIDDEN) with Scaling::identity()."""

    def __init__(self, hidden=HIDDEN):
        super().__init__()
        cells, c_in = [], INPUT_CHANNELS
        for c in hidden:
            cells.append(Cell(c_in, c, 1.0))
            c_in = c
        cells.append(Cell(c_in, 3, OUTPUT_INIT_GAIN))
        self.cells = torch.nn.ModuleList(cells)
        self.skips = dict(mirrored_skips(hidden))  # layer -> the layer whose C it adds
        self.register_buffer("input_mean", torch.zeros(INPUT_CHANNELS))
        self.register_buffer("input_inv_std", torch.ones(INPUT_CHANNELS))
        self.unit = 1.0

    def run(self, adj, skinned, initial, truth, steps):
        """AltConvNet::run: predictions Ŷ_1..Ŷ_steps, each [B, V, 3]; teacher-forced with truth."""
        b, _, v, _ = skinned.shape
        out = len(self.cells) - 1
        x0 = skinned[:, 0]
        offset0 = initial - x0
        states = [[torch.zeros(b, v, cell.c)] * 3 for cell in self.cells]  # h, c, y
        states[out][2] = initial
        x_prev, predictions = x0, []
        for t in range(1, steps + 1):
            xt = skinned[:, t]
            dx = xt - x_prev
            if t > 1 and truth is not None:
                states[out][2] = truth[:, t - 1]
            inp = (torch.cat([xt, dx, offset0], 2) - self.input_mean) * self.input_inv_std
            a_in = adj(inp)
            new = []
            for l, cell in enumerate(self.cells):
                if l == out:
                    skip = dx
                else:
                    skip = new[self.skips[l]][1] if l in self.skips else None
                h, c, y = cell.step(adj, a_in, *states[l], skip, self.unit if l == out else 1.0)
                if l < out:
                    a_in = adj(c)
                new.append([h, c, y])
            states = new
            predictions.append(states[out][2])
            x_prev = xt
        return predictions


def mean_vertex_error(predictions, truth):
    """Eq. 12, with weft's 1e-14 floor under the square root."""
    predicted = torch.stack(predictions, 1)
    target = truth[:, 1 : 1 + len(predictions)]
    return torch.sqrt(((predicted - target) ** 2).sum(3) + 1e-14).mean()


# ----------------------------------------------------------------------------- bench


def sequence(rest, steps):
    """benches/training.rs's synthetic frames: y += 3e-3 sin(0.3 (t - lag)), lag 0 / 1.5."""

    def frames(lag):
        out = []
        for t in range(steps + 1):
            f = rest.clone()
            f[:, 1] += 3e-3 * math.sin((t - lag) * 0.3)
            out.append(f)
        return torch.stack(out).unsqueeze(0).to(torch.float32)  # [1, T + 1, V, 3]

    rest = rest.to(torch.float64)
    skinned, truth = frames(0.0), frames(1.5)
    return skinned, truth[:, 0].clone(), truth


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("obj", nargs="?", help="surface mesh (OBJ)")
    ap.add_argument("--limb", nargs=2, type=int, metavar=("ACROSS", "ALONG"), help="build weft's limb surface")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--passes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    if (args.obj is None) == (args.limb is None):
        ap.error("give an OBJ path or --limb ACROSS ALONG")

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    verts, faces = read_obj(args.obj) if args.obj else limb_surface(*args.limb)
    adj = Adjacency(normalized_adjacency(len(verts), faces))
    skinned, initial, truth = sequence(torch.tensor(verts, dtype=torch.float64), STEPS)

    net = AltConvNet()
    n_params = sum(p.numel() for p in net.parameters())
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, betas=(0.9, 0.999), eps=1e-8)

    def sequence_pass():
        predictions = net.run(adj, skinned, initial, truth, STEPS)
        loss = mean_vertex_error(predictions, truth)
        loss.backward()
        opt.step()
        opt.zero_grad()
        return loss.item()

    for _ in range(args.warmup):
        sequence_pass()
    times = []
    for _ in range(args.passes):
        t0 = time.perf_counter()
        sequence_pass()
        times.append(time.perf_counter() - t0)

    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    print(f"mesh: {len(verts)} vertices, {len(faces)} triangles, Â nnz {adj.m.values().numel()}")
    print(f"parameters: {n_params:,}")
    print(
        f"sequence pass ({STEPS} teacher-forced steps, backward, Adam): median {statistics.median(times):.4f} s"
        f" (min {min(times):.4f}, max {max(times):.4f}) over {len(times)} passes"
    )


if __name__ == "__main__":
    sys.exit(main())
