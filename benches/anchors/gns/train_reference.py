"""A reference GNS trainer in plain PyTorch, for side-by-side runs with `phi train`.

It reads a phi dataset (`DIR/metadata.json`, `DIR/{split}/traj_NNNNN.npz`) and a `phi train`
configuration file, and trains the Graph Network-based Simulator of Sanchez-Gonzalez et al. (2020)
with DeepMind's recipe, written independently of phi:

- windows drawn uniformly over every (trajectory, latest input frame) pair of the split;
- random-walk noise on the input positions of the non-kinematic particles (standard deviation
  `noise_std` at the last velocity), and the target shifted by the last position's noise;
- velocities and accelerations normalised by the dataset's statistics, the scales widened by the
  noise (`sqrt(std^2 + noise_std^2)`); distances to the bounds over R, clipped to [-1, 1]; a
  learned embedding of the particle type; edges (p_s - p_r) / R and their norm, every pair within
  R, self-edges included;
- encode, `message_passing_steps` interaction networks with residuals, decode: MLPs of
  `hidden_layers` hidden layers and ReLU, LayerNorm on all but the decoder;
- the squared error of the normalised acceleration, summed over dimensions and averaged over the
  non-kinematic particles; Adam; the learning rate `(initial - final) * 0.1^(step / decay_steps)
  + final`, with the optional linear warm-up and global gradient-norm clipping of phi's
  configuration. A configuration that asks for a `phi train` option this trainer lacks (the
  multi-step loss, another loss, mirroring, pushforward, obstacle weights) is refused, naming
  the key.

Its layout (parameter names and shapes) is phi's, so `--init-from MODEL_DIR` starts from the
weights of a phi model directory (`model.safetensors`), and both trainers can start from the same
point. Every `--screen-every` steps it measures, on the first `--screen-trajectories` validation
trajectories, what `phi train`'s screening measures: MSE-acc 1 (normalised one-step error, windows
every `window_stride` frames, no noise) and the rollout position MSE from frame C. It writes
`OUT/train.csv` with `phi train`'s columns:
`step,loss,learning_rate,steps_per_second,valid_mse_acc1,valid_rollout_mse`.

`--bench-inference N` instead times N one-step predictions (graph included) on the first
validation trajectory and prints steps per second. `--train-loss N` prints the training loss
(no noise) of the `--init-from` model on N training windows drawn from `--train-loss-seed`, the
same windows for every model, beside that of predicting the mean acceleration: with heavy-tailed
targets the logged loss of two runs differs by their batches, this by their models alone.

Virtual environment (from the repository root):

    python3 -m venv VENV
    VENV/bin/pip install -r benches/anchors/gns/requirements.txt
    VENV/bin/python benches/anchors/gns/train_reference.py --data data/flip \\
        --config configs/gns/levers/mse-clip-warmup.toml --steps 1000 --out ref-run
"""

import argparse
import collections
import csv
import json
import math
import pathlib
import sys
import time
import tomllib

import numpy as np
import torch
from torch import nn

KINEMATIC_TYPES = (0,)  # phi's obstacle particles take their positions from the data


# ---------------------------------------------------------------------------------------------
# Data


class Dataset:
    """A phi dataset split, trajectories loaded on demand and kept in a bounded LRU cache."""

    def __init__(self, root, split, cache_bytes=1 << 30):
        self.root = pathlib.Path(root)
        meta_path = self.root / "metadata.json"
        try:
            self.metadata = json.loads(meta_path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            sys.exit(f"error: {meta_path}: {e}")
        self.files = sorted((self.root / split).glob("traj_*.npz"))
        if not self.files:
            sys.exit(f"error: {self.root / split}: no traj_*.npz files")
        self.cache = collections.OrderedDict()
        self.cache_bytes = cache_bytes
        self.cached_bytes = 0

    def __len__(self):
        return len(self.files)

    def load(self, index):
        if index in self.cache:
            self.cache.move_to_end(index)
            return self.cache[index]
        with np.load(self.files[index]) as z:
            item = (np.ascontiguousarray(z["position"], dtype=np.float32), z["particle_type"].astype(np.int64))
        self.cache[index] = item
        self.cached_bytes += item[0].nbytes
        while self.cached_bytes > self.cache_bytes and len(self.cache) > 1:
            _, old = self.cache.popitem(last=False)
            self.cached_bytes -= old[0].nbytes
        return item


# ---------------------------------------------------------------------------------------------
# Model


class MLP(nn.Module):
    """Linear layers named 0, 1, ... with ReLU between them, then an optional LayerNorm `ln`."""

    def __init__(self, inputs, hidden, hidden_layers, outputs, layer_norm):
        super().__init__()
        widths = [inputs] + [hidden] * hidden_layers + [outputs]
        self.count = len(widths) - 1
        for i in range(self.count):
            self.add_module(str(i), nn.Linear(widths[i], widths[i + 1]))
        self.ln = nn.LayerNorm(outputs) if layer_norm else None

    def forward(self, x):
        for i in range(self.count):
            x = getattr(self, str(i))(x)
            if i + 1 < self.count:
                x = torch.relu(x)
        return self.ln(x) if self.ln is not None else x


class Pair(nn.Module):
    """Two MLPs, `node` and `edge` (the encoder, and each interaction network)."""

    def __init__(self, node, edge):
        super().__init__()
        self.node = node
        self.edge = edge


class GNS(nn.Module):
    def __init__(self, model, dim, types, metadata):
        super().__init__()
        latent, hidden, layers = model["latent_size"], model["hidden_size"], model["hidden_layers"]
        self.dim = dim
        self.velocities = model["input_velocities"]
        self.radius = float(metadata["default_connectivity_radius"])
        self.boundary = bool(model.get("boundary_features", True))
        # Where the boundary features saturate, in multiples of the radius (phi's default 1).
        self.boundary_scale = self.radius * float(model.get("boundary_horizon", 1.0))
        self.uses_embedding = types > 1 and model["embedding_size"] > 0
        node_features = self.velocities * dim + (2 * dim if self.boundary else 0)
        if self.uses_embedding:
            self.embedding = nn.Embedding(types, model["embedding_size"])
            node_features += model["embedding_size"]
        self.encoder = Pair(
            MLP(node_features, hidden, layers, latent, True), MLP(dim + 1, hidden, layers, latent, True)
        )
        self.processor = nn.ModuleList(
            Pair(MLP(2 * latent, hidden, layers, latent, True), MLP(3 * latent, hidden, layers, latent, True))
            for _ in range(model["message_passing_steps"])
        )
        self.decoder = MLP(latent, hidden, layers, dim, False)
        noise = float(model.get("noise_std", 0.0))
        stat = lambda key: torch.tensor(metadata[key], dtype=torch.float32)  # noqa: E731
        self.register_buffer("vel_mean", stat("vel_mean"), persistent=False)
        self.register_buffer("vel_scale", torch.sqrt(stat("vel_std") ** 2 + noise**2), persistent=False)
        self.register_buffer("acc_mean", stat("acc_mean"), persistent=False)
        self.register_buffer("acc_scale", torch.sqrt(stat("acc_std") ** 2 + noise**2), persistent=False)
        self.register_buffer("bounds", torch.tensor(metadata["bounds"], dtype=torch.float32), persistent=False)

    def forward(self, positions, types, senders, receivers):
        """Normalised accelerations `[N, dim]` of windows `positions` `[N, C + 1, dim]`."""
        n = positions.shape[0]
        velocities = (positions[:, 1:] - positions[:, :-1] - self.vel_mean) / self.vel_scale
        columns = [velocities.reshape(n, -1)]
        latest = positions[:, -1]
        if self.boundary:
            columns.append(torch.clamp((latest - self.bounds[:, 0]) / self.boundary_scale, -1.0, 1.0))
            columns.append(torch.clamp((self.bounds[:, 1] - latest) / self.boundary_scale, -1.0, 1.0))
        if self.uses_embedding:
            columns.append(self.embedding(types))
        displacement = (latest[senders] - latest[receivers]) / self.radius
        edges = torch.cat([displacement, displacement.norm(dim=1, keepdim=True)], dim=1)
        v = self.encoder.node(torch.cat(columns, dim=1))
        e = self.encoder.edge(edges)
        for step in self.processor:
            messages = step.edge(torch.cat([e, v[senders], v[receivers]], dim=1))
            sums = torch.zeros_like(v).index_add_(0, receivers, messages)
            v = v + step.node(torch.cat([v, sums], dim=1))
            e = e + messages
        return self.decoder(v)


def radius_graph(latest, radius, offset=0):
    """Every (sender, receiver) pair of `latest` `[N, dim]` within `radius`, self-pairs included,
    sorted by receiver."""
    d2 = ((latest[:, None, :] - latest[None, :, :]) ** 2).sum(dim=-1)  # [receiver, sender]
    receivers, senders = torch.nonzero(d2 <= radius * radius, as_tuple=True)
    return senders + offset, receivers + offset


# ---------------------------------------------------------------------------------------------
# Training


def random_walk_noise(n, window, dim, std, movable, generator, device):
    """Position offsets `[n, window, dim]`: a random walk of the velocities, `std` at the last."""
    velocities = window - 1
    step_std = std / math.sqrt(velocities)
    velocity_noise = torch.randn(n, velocities, dim, generator=generator, device=device) * step_std
    position_noise = torch.cumsum(torch.cumsum(velocity_noise, dim=1), dim=1)
    position_noise = torch.cat([torch.zeros(n, 1, dim, device=device), position_noise], dim=1)
    return position_noise * movable[:, None, None]


def learning_rate(rate, step):
    lr = (rate["initial"] - rate["final_rate"]) * 0.1 ** (step / rate["decay_steps"]) + rate["final_rate"]
    warmup = rate.get("warmup_steps", 0.0)
    if warmup > 0:
        lr *= min(1.0, (step + 1) / warmup)
    return lr


class Batcher:
    """Draws one-step training windows uniformly over (trajectory, latest input frame) pairs."""

    def __init__(self, dataset, velocities, seed):
        self.dataset = dataset
        self.velocities = velocities
        self.rng = np.random.default_rng(seed)
        frames = int(dataset.metadata["sequence_length"]) + 1
        self.last = frames - 2  # latest input frame t needs the target t + 1

    def draw(self, batch_size, device):
        windows, types, targets = [], [], []
        for _ in range(batch_size):
            index = int(self.rng.integers(len(self.dataset)))
            positions, particle_type = self.dataset.load(index)
            last = min(self.last, positions.shape[0] - 2)
            t = int(self.rng.integers(self.velocities, last + 1))
            windows.append(torch.from_numpy(positions[t - self.velocities : t + 1].transpose(1, 0, 2).copy()))
            targets.append(torch.from_numpy(positions[t + 1]))
            types.append(torch.from_numpy(particle_type))
        return [(w.to(device), y.to(device), k.to(device)) for w, y, k in zip(windows, targets, types)]


def graph_batch(model, examples):
    """Concatenates examples `(window, ...)` into one graph: windows, senders, receivers."""
    senders, receivers, offset = [], [], 0
    for window, *_ in examples:
        s, r = radius_graph(window[:, -1], model.radius, offset)
        senders.append(s)
        receivers.append(r)
        offset += window.shape[0]
    return torch.cat(senders), torch.cat(receivers)


def movable_mask(types):
    mask = torch.ones_like(types, dtype=torch.float32)
    for k in KINEMATIC_TYPES:
        mask = mask * (types != k).float()
    return mask


# ---------------------------------------------------------------------------------------------
# Screening (what phi train's screening measures)


@torch.no_grad()
def predict_positions(model, window, types):
    senders, receivers = radius_graph(window[:, -1], model.radius)
    acceleration = model(window, types, senders, receivers) * model.acc_scale + model.acc_mean
    latest, previous = window[:, -1], window[:, -2]
    return 2 * latest - previous + acceleration


@torch.no_grad()
def screen(model, dataset, trajectories, stride, rollout_steps, device):
    c = model.velocities
    acc_sum, windows, rollout_sum = 0.0, 0, 0.0
    for index in range(min(trajectories, len(dataset))):
        positions, particle_type = dataset.load(index)
        truth = torch.from_numpy(positions).to(device)
        types = torch.from_numpy(particle_type).to(device)
        movable = movable_mask(types)
        counted = movable.sum() * model.dim
        frames = truth.shape[0]
        for t in range(c, frames - 1, max(stride, 1)):
            window = truth[t - c : t + 1].transpose(0, 1)
            senders, receivers = radius_graph(window[:, -1], model.radius)
            predicted = model(window, types, senders, receivers)
            target = (truth[t + 1] - 2 * truth[t] + truth[t - 1] - model.acc_mean) / model.acc_scale
            error = ((predicted - target) ** 2).sum(dim=1)
            acc_sum += float((error * movable).sum() / counted)
            windows += 1
        steps = min(rollout_steps, frames - 1 - c)
        window = truth[0 : c + 1].transpose(0, 1).clone()
        keep = movable[:, None]
        total = 0.0
        for step in range(1, steps + 1):
            predicted = predict_positions(model, window, types)
            predicted = keep * predicted + (1 - keep) * truth[c + step]
            if not torch.isfinite(predicted).all():
                total = math.inf
                break
            window = torch.cat([window[:, 1:], predicted[:, None]], dim=1)
            error = ((predicted - truth[c + step]) ** 2).sum(dim=1)
            total += float((error * movable).sum() / counted)
        rollout_sum += total / steps
    return acc_sum / windows, rollout_sum / min(trajectories, len(dataset))


# ---------------------------------------------------------------------------------------------


def refuse_unimplemented(config, path):
    """Exits naming the key when the configuration asks for a training option of `phi train` that
    this trainer does not implement (it would otherwise train DeepMind's one-step recipe instead)."""
    training = config.get("training", {})
    unimplemented = [
        ("training.extra_steps", training.get("extra_steps", 0) != 0),
        ("training.loss", training.get("loss", "mse") != "mse"),
        ("training.mirror", bool(training.get("mirror", False))),
        ("training.pushforward", "pushforward" in training),
        ("training.obstacle_weight", training.get("obstacle_weight", 1.0) != 1.0),
        ("training.impact_sampling", "impact_sampling" in training),
    ]
    for key, asked in unimplemented:
        if asked:
            sys.exit(f"error: {path}: {key} is set, and this trainer implements only the one-step "
                     "squared error without mirroring, pushforward or obstacle weights")


def build(args):
    try:
        config = tomllib.loads(pathlib.Path(args.config).read_text())
    except (OSError, tomllib.TOMLDecodeError) as e:
        sys.exit(f"error: {args.config}: {e}")
    device = torch.device(args.device)
    train = Dataset(args.data, config.get("data", {}).get("split", "train"), args.cache_mib << 20)
    metadata = train.metadata
    types = len(metadata.get("particle_types", {"0": 0, "1": 1}))
    torch.manual_seed(config["model"].get("seed", 0))
    model = GNS(config["model"], int(metadata["dim"]), types, metadata).to(device)
    if args.init_from:
        from safetensors.torch import load_file

        path = pathlib.Path(args.init_from) / "model.safetensors"
        model.load_state_dict(load_file(str(path), device=str(device)), strict=True)
    return config, device, train, model


def bench_inference(args):
    _, device, _, model = build(args)
    valid = Dataset(args.data, "valid")
    positions, particle_type = valid.load(0)
    c = model.velocities
    frame = min(args.bench_frame, positions.shape[0] - 1)
    window = torch.from_numpy(positions[frame - c : frame + 1].transpose(1, 0, 2).copy()).to(device)
    types = torch.from_numpy(particle_type).to(device)
    model.eval()
    for _ in range(10):
        predict_positions(model, window, types)
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    sync()
    start = time.perf_counter()
    for _ in range(args.bench_inference):
        out = predict_positions(model, window, types)
    float(out.sum())
    sync()
    rate = args.bench_inference / (time.perf_counter() - start)
    print(f"inference: {rate:.2f} steps/s ({len(particle_type)} particles, frame {frame}, {device})")


def save(model, init_dir, target):
    """A phi model directory: the --init-from model.json and the weights in phi's layout."""
    from safetensors.torch import save_file

    target.mkdir(parents=True, exist_ok=True)
    (target / "model.json").write_text((init_dir / "model.json").read_text())
    weights = {k: v.detach().to("cpu").contiguous() for k, v in model.state_dict().items()}
    save_file(weights, str(target / "model.safetensors"))


def screen_only(args):
    if not args.init_from:
        sys.exit("error: --screen-only needs --init-from MODEL_DIR")
    config, device, _, model = build(args)
    screening = config.get("screening", {})
    split = screening.get("split", "valid")
    began = time.perf_counter()
    model.eval()
    mse_acc1, rollout_mse = screen(
        model,
        Dataset(args.data, split),
        args.screen_only,
        screening.get("window_stride", 20),
        screening.get("rollout_steps", 395),
        device,
    )
    print(
        f"{split}, {args.screen_only} trajectories: MSE-acc1 {mse_acc1:.4f}, rollout MSE {rollout_mse:.4g}"
        f" ({time.perf_counter() - began:.0f} s)"
    )


@torch.no_grad()
def train_loss(args):
    if not args.init_from:
        sys.exit("error: --train-loss needs --init-from MODEL_DIR")
    _, device, train, model = build(args)
    model.eval()
    batcher = Batcher(train, model.velocities, args.train_loss_seed)
    error_sum, zero_sum, counted, began = 0.0, 0.0, 0.0, time.perf_counter()
    for _ in range(args.train_loss):
        ((window, target, types),) = batcher.draw(1, device)
        senders, receivers = radius_graph(window[:, -1], model.radius)
        acceleration = (target - 2 * window[:, -1] + window[:, -2] - model.acc_mean) / model.acc_scale
        predicted = model(window, types, senders, receivers)
        movable = movable_mask(types)
        error_sum += float((((predicted - acceleration) ** 2).sum(dim=1) * movable).sum())
        zero_sum += float(((acceleration**2).sum(dim=1) * movable).sum())
        counted += float(movable.sum())
    print(
        f"{args.init_from}: loss {error_sum / counted:.4f} on {args.train_loss} training windows"
        f" (seed {args.train_loss_seed}; the mean acceleration scores {zero_sum / counted:.4f})"
        f" ({time.perf_counter() - began:.0f} s)"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="a phi dataset directory")
    parser.add_argument("--config", required=True, help="a phi train configuration (TOML)")
    parser.add_argument("--out", help="output folder for train.csv (new or empty)")
    parser.add_argument("--steps", type=int, help="training steps (default: the config's)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    parser.add_argument("--log-every", type=int, default=100)
    parser.add_argument("--screen-every", type=int, default=0)
    parser.add_argument("--screen-trajectories", type=int)
    parser.add_argument("--init-from", help="a phi model directory to start from")
    parser.add_argument("--cache-mib", type=int, default=1024)
    parser.add_argument(
        "--save-every",
        type=int,
        default=0,
        help="write OUT/step-N/ (phi's model.json from --init-from, model.safetensors) every N steps",
    )
    parser.add_argument("--bench-inference", type=int, default=0, help="time N one-step predictions")
    parser.add_argument("--bench-frame", type=int, default=200)
    parser.add_argument(
        "--screen-only",
        type=int,
        default=0,
        metavar="N",
        help="screen the --init-from model on N trajectories of the config's screening split",
    )
    parser.add_argument(
        "--train-loss",
        type=int,
        default=0,
        metavar="N",
        help="the training loss of the --init-from model on N training windows (the same for every model)",
    )
    parser.add_argument("--train-loss-seed", type=int, default=123)
    args = parser.parse_args()
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    if args.bench_inference > 0:
        bench_inference(args)
        return
    if args.screen_only > 0:
        screen_only(args)
        return
    if args.train_loss > 0:
        train_loss(args)
        return
    if not args.out:
        sys.exit("error: --out is required for training")
    if args.save_every > 0 and not args.init_from:
        sys.exit("error: --save-every needs --init-from (its model.json describes the saved weights)")
    out = pathlib.Path(args.out)
    if out.exists() and any(out.iterdir()):
        sys.exit(f"error: {out}: exists and is not empty")
    out.mkdir(parents=True, exist_ok=True)

    config, device, train, model = build(args)
    refuse_unimplemented(config, args.config)
    training, optimizer_config = config["training"], config["optimizer"]
    screening = config.get("screening", {})
    steps = args.steps or training["steps"]
    batch_size = training["batch_size"]
    noise = float(config["model"].get("noise_std", 0.0))
    clip = optimizer_config.get("clip_norm")
    rate = optimizer_config["learning_rate"]
    optimizer = torch.optim.Adam(
        model.parameters(),
        lr=learning_rate(rate, 0),
        betas=(optimizer_config["beta1"], optimizer_config["beta2"]),
        eps=optimizer_config["eps"],
    )
    batcher = Batcher(train, model.velocities, training.get("seed", 0))
    generator = torch.Generator(device=device)
    generator.manual_seed(training.get("seed", 0))
    valid = Dataset(args.data, screening.get("split", "valid")) if args.screen_every > 0 else None
    screen_trajectories = args.screen_trajectories or screening.get("trajectories", 5)

    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    rows, loss_sum, loss_count = [], 0.0, 0
    with open(out / "train.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["step", "loss", "learning_rate", "steps_per_second", "valid_mse_acc1", "valid_rollout_mse"])
        sync()
        interval_start, interval_steps = time.perf_counter(), 0
        for step in range(steps):
            lr = learning_rate(rate, step)
            for group in optimizer.param_groups:
                group["lr"] = lr
            examples = batcher.draw(batch_size, device)
            windows, targets, types = [], [], []
            for window, target, particle_type in examples:
                movable = movable_mask(particle_type)
                if noise > 0:
                    offsets = random_walk_noise(
                        window.shape[0], window.shape[1], window.shape[2], noise, movable, generator, device
                    )
                    window = window + offsets
                    target = target + offsets[:, -1]
                windows.append(window)
                targets.append(target)
                types.append(particle_type)
            senders, receivers = graph_batch(model, [(w,) for w in windows])
            window, target, particle_type = torch.cat(windows), torch.cat(targets), torch.cat(types)
            movable = movable_mask(particle_type)
            latest, previous = window[:, -1], window[:, -2]
            target_acceleration = (target - 2 * latest + previous - model.acc_mean) / model.acc_scale
            predicted = model(window, particle_type, senders, receivers)
            error = ((predicted - target_acceleration) ** 2).sum(dim=1)
            loss = (error * movable).sum() / movable.sum()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if clip:
                nn.utils.clip_grad_norm_(model.parameters(), clip)
            optimizer.step()
            loss_sum += float(loss.detach())
            loss_count += 1
            interval_steps += 1
            done = step + 1
            if done % args.log_every == 0 or done == steps:
                sync()
                elapsed = time.perf_counter() - interval_start
                row = [done, loss_sum / loss_count, lr, interval_steps / elapsed, "", ""]
                if valid is not None and (done % args.screen_every == 0 or done == steps):
                    began = time.perf_counter()
                    model.eval()
                    mse_acc1, rollout_mse = screen(
                        model,
                        valid,
                        screen_trajectories,
                        screening.get("window_stride", 20),
                        screening.get("rollout_steps", 395),
                        device,
                    )
                    model.train()
                    row[4:] = [mse_acc1, rollout_mse]
                    print(f"step {done}: screening MSE-acc1 {mse_acc1:.4f}, rollout MSE {rollout_mse:.4g}"
                          f" ({time.perf_counter() - began:.0f} s)", flush=True)
                writer.writerow(row)
                f.flush()
                print(f"step {done}: loss {row[1]:.4f}, lr {lr:.2e}, {row[3]:.2f} steps/s", flush=True)
                loss_sum, loss_count, interval_steps = 0.0, 0, 0
                interval_start = time.perf_counter()
            if args.save_every > 0 and (done % args.save_every == 0 or done == steps):
                save(model, pathlib.Path(args.init_from), out / f"step-{done:010d}")


if __name__ == "__main__":
    main()
