"""Train the neural untangling operator O_theta (paper 3.2, eq. 7) into a checkpoint.

    python -m training.untangler [--checkpoint build/untangler.ckpt] [--steps N]
    python -m export.untangler [--checkpoint build/untangler.ckpt]      # then: ONNX into models/untangler/

About 10 minutes on one thread of the 2-core build machine; an interrupted run resumes from its
checkpoint (delete it to start afresh). An MLP over (f*, h*) for 5 slots (body + 4 garments): garment
k gets f_k = f*_k + a_k u_k(f*, h*), with a_k a gate that is 1 where garment k is active, 0 where it
is inactive and linear over |h*_k| < h_band, so that inactive garments and the body pass unchanged
exactly; u_k is a learned weighted mean over a pool of layers (head "pools", see ``UntanglerNet``).
Its inputs are the 10 pairwise differences f*_i - f*_j (the operator commutes with adding a constant
to every f*) and the clipped h*_k / h_band. Trained with L1 against the exact operator
(``service.pipeline.untangle.untangle``) on fresh samples every step (``training.untangler_data``: the paper's
distribution, samples concentrated near 0, layered outfits whose layers are a few mm apart and
sometimes cross; a share of every batch with unused slots padded as inactive). Batch i is drawn from
``default_rng((seed, i))``, so a run resumed from its checkpoint ends with the same weights as an
uninterrupted one.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from service.pipeline.untangle import GAP_DELTA, untangle
from service.pipeline.untangle_onnx import N_SLOTS, NEAR_SURFACE
from training.untangler_data import SAMPLERS, sample_batch

Activation = Literal["relu", "silu"]
Head = Literal["pools", "residual"]


@dataclass(frozen=True)
class UntanglerConfig:
    hidden: int = 128
    """Width of every hidden layer."""
    depth: int = 3
    """Number of hidden layers."""
    activation: Activation = "relu"
    head: Head = "pools"
    """Output head. "pools": learned pool weights (the exact operator's form); "residual": a learned
    correction. At 4,000 steps "pools" reached 1.3 mm mean error on the paper's distribution and
    0.15 mm on layered outfits, "residual" 4.0 mm and 0.21 mm."""
    steps: int = 24000
    batch: int = 4096
    lr: float = 2e-3
    """Adam learning rate, cosine-decayed to ``lr * lr_final``."""
    lr_final: float = 0.01
    delta: float = GAP_DELTA
    """Gap (m) of the reference operator the network learns."""
    h_band: float = 0.01
    """Half-width of the h* band (m) over which a garment is blended in."""
    f_scale: float = 0.1
    """f* differences are divided by this before the MLP (m)."""
    mixture: tuple[float, float, float] = (0.4, 0.2, 0.4)
    """Shares of paper / near-zero / layered samples in a batch."""
    padded: float = 0.3
    """Share of samples whose outer slots are padded as unused."""
    seed: int = 0
    log_every: int = 500
    checkpoint_every: int = 2000


# ---------------------------------------------------------------- network with explicit Jacobian


def pair_matrix(n: int) -> np.ndarray:
    """Rows e_i - e_j for all i < j: ``(n (n - 1) / 2, n)``."""
    pairs = list(itertools.combinations(range(n), 2))
    d = np.zeros((len(pairs), n))
    for row, (i, j) in enumerate(pairs):
        d[row, i], d[row, j] = 1.0, -1.0
    return d


class UntanglerNet(torch.nn.Module):
    """O_theta: ``forward(f_star, h_star) (B, 5) -> f (B, 5)``; ``with_jacobian`` adds ``(B, 5, 10)``,
    ``with_jacobian_row`` one weighted row of it ``(B, 10)`` (what the fit needs, ~1/3 of the cost).

    Garment k gets f_k = f*_k + a_k u_k with the gate a_k (1 active, 0 inactive, linear in the band).
    Head "residual": u = MLP output. Head "pools": the exact operator's form, a weighted mean over a
    pool plus a multiple of delta, u_k = sum_j alpha_kj (f*_j - f*_k) + delta o_k, with alpha_k a
    softmax over the 5 layers masked by their gates (the body's is 1) and alpha, o from the MLP; its
    errors stay small where corrections are large, because only the pool weights are learned.
    The Jacobian is computed explicitly, reverse mode over the 4 garments (for each layer
    G <- (G * act'(z)) @ W), because autograd does not export to ONNX.
    """

    def __init__(self, config: UntanglerConfig):
        super().__init__()
        self.config = config
        diff = torch.from_numpy(pair_matrix(N_SLOTS) / config.f_scale).float()
        self.register_buffer("diff", diff)  # (10, 5)
        self.register_buffer("eye", torch.eye(N_SLOTS - 1))
        self.register_buffer("garment_rows", torch.eye(N_SLOTS)[1:])  # (4, 5) d f*_k / d f* of garments
        self.register_buffer("body_row", torch.eye(1, 2 * N_SLOTS))  # (1, 10)
        dims = [diff.shape[0] + N_SLOTS - 1] + [config.hidden] * config.depth
        self.hidden = torch.nn.ModuleList(torch.nn.Linear(a, b) for a, b in itertools.pairwise(dims))
        n_out = N_SLOTS - 1 if config.head == "residual" else (N_SLOTS - 1) * (N_SLOTS + 1)
        self.out = torch.nn.Linear(config.hidden, n_out)
        with torch.no_grad():
            self.out.weight.mul_(0.1)
            self.out.bias.zero_()

    def _act(self, z):
        return torch.relu(z) if self.config.activation == "relu" else torch.nn.functional.silu(z)

    def _act_grad(self, z):
        if self.config.activation == "relu":
            return (z > 0).to(z.dtype)
        s = torch.sigmoid(z)
        return s * (1 + z * (1 - s))

    def _forward(self, f_star, h_star):
        """(f (B, 5), dict of intermediates for the Jacobian)."""
        hs = h_star[:, 1:] / self.config.h_band  # (B, 4) garments only: the body's h* is ignored
        x = torch.cat([f_star @ self.diff.T, torch.clamp(hs, -1.0, 1.0)], dim=1)
        zs, xs = [], []
        for layer in self.hidden:
            zs.append(layer(x))
            xs.append(x := self._act(zs[-1]))
        gate = torch.clamp(0.5 - 0.5 * hs, 0.0, 1.0)  # (B, 4)
        parts = {"hs": hs, "zs": zs, "xs": xs, "gate": gate}
        out = self.out(x)
        if self.config.head == "residual":
            u = out * self.config.f_scale  # (B, 4) correction (m) if active
        else:
            n, g = N_SLOTS, N_SLOTS - 1
            logits, offset = out[:, : g * n].reshape(-1, g, n), out[:, g * n :]
            gates = torch.cat([torch.ones_like(gate[:, :1]), gate], dim=1)  # (B, 5)
            masked = logits + torch.log(torch.clamp(gates, min=1e-20)).unsqueeze(1)
            top = masked.max(dim=2, keepdim=True).values.detach()
            total = torch.exp(masked - top).sum(dim=2, keepdim=True)
            alpha = torch.exp(masked - top) / total  # (B, 4, 5) pool weights
            # alpha / gate; clamped so that a gated-out layer's unused logit cannot overflow to inf
            rho = torch.exp(torch.clamp(logits - top, max=60.0)) / total
            spread = f_star.unsqueeze(1) - f_star[:, 1:].unsqueeze(2)  # (B, 4, 5) f*_j - f*_k
            mean = (alpha * spread).sum(dim=2)
            u = mean + self.config.delta * offset
            parts.update(alpha=alpha, rho=rho, spread=spread, mean=mean)
        parts["u"] = u
        return torch.cat([f_star[:, :1], f_star[:, 1:] + gate * u], dim=1), parts

    def forward(self, f_star, h_star):
        return self._forward(f_star, h_star)[0]

    def with_jacobian(self, f_star, h_star):
        f, p = self._forward(f_star, h_star)
        n, g = N_SLOTS, N_SLOTS - 1
        in_band = (torch.abs(p["hs"]) < 1.0).to(f.dtype) / self.config.h_band  # d clamp(h/band) / dh
        dgate = -0.5 * in_band  # (B, 4) d gate / dh, zero outside the band
        w = self.out.weight  # (n_out, H)
        if self.config.head == "residual":
            cot = w.unsqueeze(0) * self.config.f_scale  # (1, 4, H) d u / d last activation
        else:
            # d mean_k = sum_j alpha_kj (spread_kj - mean_k) d logit_kj (softmax), + delta d offset_k
            c = p["alpha"] * (p["spread"] - p["mean"].unsqueeze(2))  # (B, 4, 5)
            w_logits = w[: g * n].reshape(g, n, -1)  # (4, 5, H)
            cot = (c.unsqueeze(2) @ w_logits).squeeze(2) + self.config.delta * w[g * n :].unsqueeze(0)
        for layer, z in zip(reversed(self.hidden), reversed(p["zs"]), strict=True):
            cot = (cot * self._act_grad(z).unsqueeze(1)) @ layer.weight  # (B, 4, fan-in)
        n_diff = self.diff.shape[0]
        du_df = cot[:, :, :n_diff] @ self.diff  # (B, 4, 5) through the network
        du_dh = cot[:, :, n_diff:] * in_band.unsqueeze(1)  # (B, 4, 4)
        if self.config.head == "pools":
            du_df = du_df + p["alpha"] - self.garment_rows  # d spread: sum_j alpha_kj (e_j - e_k)
            # the gates mask the softmax: d alpha_kj / d gate_j = rho_kj (spread_kj - mean_k) (+ renorm.)
            c_gate = p["rho"][:, :, 1:] * (p["spread"][:, :, 1:] - p["mean"].unsqueeze(2))
            du_dh = du_dh + c_gate * dgate.unsqueeze(1)
        gate = p["gate"].unsqueeze(2)
        df_df = self.garment_rows + gate * du_df  # (B, 4, 5)
        df_dh = gate * du_dh + (p["u"] * dgate).unsqueeze(2) * self.eye
        df_dh = torch.cat([torch.zeros_like(df_dh[:, :, :1]), df_dh], dim=2)  # the body's h* column
        rows = torch.cat([df_df, df_dh], dim=2)  # (B, 4, 10)
        body = self.body_row.unsqueeze(0) + 0 * rows[:, :1]  # (B, 1, 10)
        return f, torch.cat([body, rows], dim=1)

    def with_jacobian_row(self, f_star, h_star, row):
        """``(f (B, 5), row @ jacobian (B, 10))`` for weights ``row (1, 5)`` over the outputs: one
        vector-Jacobian product, one reverse pass where ``with_jacobian`` makes 4 (a one-hot ``row``
        gives that row of the Jacobian). The terms are ``with_jacobian``'s contracted with ``row``, laid
        out for onnxruntime: (garment k, layer j) pairs flattened to 20 columns, broadcasts over them
        as products with constant 0/1 matrices, ReLU's derivative read from its output (so that the
        forward's Gemm and ReLU still fuse), the pair differences folded into the first layer."""
        f, p = self._forward(f_star, h_star)
        n, g = N_SLOTS, N_SLOTS - 1
        n_diff = self.diff.shape[0]
        expand = torch.from_numpy(np.repeat(np.eye(g, dtype=np.float32), n, axis=1)).to(f.dtype)  # (4, 20)
        sum_k = torch.from_numpy(np.tile(np.eye(n, dtype=np.float32), (g, 1))).to(f.dtype)  # (20, 5)
        fold = np.zeros((n_diff + g, n + g), dtype=np.float32)  # (14, 9): d input / d (f*, clamped h*_k)
        fold[:n_diff, :n], fold[n_diff:, n:] = self.diff.numpy(), np.eye(g)
        in_band = (torch.abs(p["hs"]) < 1.0).to(f.dtype) / self.config.h_band  # d clamp(h/band) / dh
        dgate = -0.5 * in_band  # (B, 4)
        wg = row[:, 1:] * p["gate"]  # (B, 4) d (row . f) / d u_k = row_k gate_k
        if self.config.head == "residual":
            cot = (wg * self.config.f_scale) @ self.out.weight  # (B, H)
        else:
            alpha, rho, spread = (p[k].flatten(1) for k in ("alpha", "rho", "spread"))  # (B, 20)
            wg_pairs = wg @ expand
            # d mean_k / d logit_kj = alpha_kj (spread_kj - mean_k), weighted by row_k gate_k
            w_dev = wg_pairs * (spread - p["mean"] @ expand)
            cot = torch.cat([w_dev * alpha, self.config.delta * wg], dim=1) @ self.out.weight
        for i in reversed(range(len(self.hidden))):
            weight = (
                self.hidden[i].weight if i else self.hidden[0].weight @ torch.from_numpy(fold).to(f.dtype)
            )
            if self.config.activation == "relu":
                cot = torch.where(p["xs"][i] > 0, cot, 0.0) @ weight
            else:
                cot = (cot * self._act_grad(p["zs"][i])) @ weight
        d_f = row + cot[:, :n]  # (B, 5): f*_k passes through, plus the network
        d_h = cot[:, n:] * in_band  # (B, 4)
        if self.config.head == "pools":
            d_f = d_f + (wg_pairs * alpha) @ sum_k - wg @ self.garment_rows  # d spread
            d_h = d_h + ((w_dev * rho) @ sum_k[:, 1:]) * dgate  # the gates mask the softmax
        d_h = d_h + row[:, 1:] * p["u"] * dgate
        return f, torch.cat([d_f, torch.zeros_like(d_h[:, :1]), d_h], dim=1)  # the body's h* column: 0


# ---------------------------------------------------------------- training and evaluation


def errors_mm(predicted: np.ndarray, f_star: np.ndarray, h_star: np.ndarray, used: np.ndarray, delta: float):
    """(mean error overall, mean error where |f*| < NEAR_SURFACE), mm, over the used garment slots."""
    err = 1e3 * np.abs(predicted - untangle(f_star, h_star, delta=delta))[:, 1:]
    used = used[:, 1:]
    near = used & (np.abs(f_star[:, 1:]) < NEAR_SURFACE)
    return float(err[used].mean()), float(err[near].mean())


def evaluate(net: UntanglerNet, predict=None, n: int = 100_000, seed: int = 1_000_000) -> dict:
    """Errors (mm) per sampler (h* as sampled, no extra samples in the blend band, all 5 slots used)
    on fresh samples from a seed never used for training; ``predict(f, h) -> f`` defaults to the torch
    network in float32."""
    if predict is None:

        def predict(f, h):
            with torch.no_grad():
                return net(torch.from_numpy(f).float(), torch.from_numpy(h).float()).double().numpy()

    report = {}
    for k, sampler in enumerate(SAMPLERS):
        f, h = sampler(np.random.default_rng((seed, k)), n)
        h[:, 0] = -1.0
        mean, near = errors_mm(predict(f, h), f, h, np.ones(f.shape, dtype=bool), net.config.delta)
        report[sampler.__name__.removeprefix("sample_")] = {"mean_mm": mean, "near_surface_mean_mm": near}
    return report


@dataclass
class TrainResult:
    net: UntanglerNet
    seconds: float
    """Wall time of all the steps, summed over the runs a resumed training took."""
    torch_threads: int = 1
    """Threads of the run that finished it (``seconds`` depends on them)."""


def train(
    config: UntanglerConfig, checkpoint: Path | None = None, log=print, stop_at: int | None = None
) -> TrainResult:
    """Train (resuming from ``checkpoint`` when it holds a run of the same config); ``stop_at`` ends
    the run early after that step, as an interruption would (the checkpoint is written then)."""
    torch.manual_seed(config.seed)
    net = UntanglerNet(config)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    start, before = 0, 0.0
    if checkpoint is not None and checkpoint.is_file():
        state = torch.load(checkpoint, weights_only=False)
        if state["config"] == asdict(config):
            net.load_state_dict(state["net"])
            opt.load_state_dict(state["opt"])
            start, before = state["step"], state["seconds"]
            log(f"resumed from {checkpoint} at step {start}")
        else:
            log(f"{checkpoint} holds another config; starting afresh")
    t0 = time.perf_counter()
    running = 0.0
    end = config.steps if stop_at is None else min(stop_at, config.steps)
    saved = before  # the seconds the checkpoint holds
    for step in range(start, end):
        progress = step / max(config.steps - 1, 1)
        lr = config.lr * (config.lr_final + (1 - config.lr_final) * 0.5 * (1 + np.cos(np.pi * progress)))
        for group in opt.param_groups:
            group["lr"] = lr
        rng = np.random.default_rng((config.seed, step))
        f, h, _ = sample_batch(rng, config.batch, config.mixture, config.h_band, config.padded)
        target = torch.from_numpy(untangle(f, h, delta=config.delta)).float()
        pred = net(torch.from_numpy(f).float(), torch.from_numpy(h).float())
        loss = 1e3 * (pred - target)[:, 1:].abs().mean()  # mm
        opt.zero_grad()
        loss.backward()
        opt.step()
        running += loss.item()
        done = step + 1
        if done % config.log_every == 0 or done == config.steps:
            n = done % config.log_every or config.log_every
            log(
                f"step {done}/{config.steps}  L1 {running / n:.4f} mm  lr {lr:.2e}  "
                f"{time.perf_counter() - t0:.0f} s"
            )
            running = 0.0
        if checkpoint is not None and (done % config.checkpoint_every == 0 or done == end):
            checkpoint.parent.mkdir(parents=True, exist_ok=True)
            state = {"config": asdict(config), "net": net.state_dict(), "opt": opt.state_dict()}
            saved = before + time.perf_counter() - t0
            state.update(step=done, seconds=saved)
            state["torch_threads"] = torch.get_num_threads()
            torch.save(state, checkpoint)
    # With a checkpoint, the seconds it holds (the export reads them there), not counting its own
    # save, so the two records of a run agree.
    seconds = saved if checkpoint is not None else before + time.perf_counter() - t0
    return TrainResult(net, seconds, torch.get_num_threads())


def load_trained(checkpoint: Path) -> TrainResult:
    """The finished run in ``checkpoint``; ValueError if it is missing or unfinished (naming the step)."""
    if not Path(checkpoint).is_file():
        raise ValueError(f"{checkpoint}: no training run (python -m training.untangler)")
    state = torch.load(checkpoint, weights_only=False)
    config = UntanglerConfig(**state["config"] | {"mixture": tuple(state["config"]["mixture"])})
    if state["step"] < config.steps:
        raise ValueError(f"{checkpoint} stopped at step {state['step']} of {config.steps}: train it on first")
    net = UntanglerNet(config)
    net.load_state_dict(state["net"])
    return TrainResult(net.float().eval(), state["seconds"], state.get("torch_threads", 1))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--checkpoint", type=Path, default=Path("build/untangler.ckpt"))
    parser.add_argument("--steps", type=int, default=UntanglerConfig.steps)
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--hidden", type=int, default=UntanglerConfig.hidden, help="width of the MLP")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    config = UntanglerConfig(steps=args.steps, hidden=args.hidden)
    result = train(config, args.checkpoint)
    print(json.dumps(evaluate(result.net), indent=2))
    print(f"{args.checkpoint}: {result.seconds / 60:.1f} min of training; next: python -m export.untangler")


if __name__ == "__main__":
    main()
