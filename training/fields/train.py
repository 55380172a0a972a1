"""Train the neural field of one garment (or the body) with L1 losses on values and gradients (eq. 1-5).

Training shapes: the garment codes of ``config.n_betas`` real adults (``population.codes``: the
drape dataset's cells, tails included, a quarter of them with a gender in between); held-out shapes
are codes of adults of the held-out set. Ground truth per shape (``training.fields.samples``) is
cached under ``data/fields/``; the network is checkpointed under ``build/fields/`` every
``CHECKPOINT_EVERY`` steps and a run with the same config resumes from it (batch i is drawn from
``default_rng((seed, i))``, so a resumed run ends with the weights an uninterrupted one would).
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.catalog import load_catalog
from service.pipeline.explicit import ExplicitModel
from service.process.manifest import file_sha256
from service.process.paths import models_dir
from training.drape import population
from training.fields.net import FieldConfig, FieldNet
from training.fields.samples import (
    GROUND_TRUTH_VERSION,
    PAD,
    FieldSamples,
    garment_samples,
    near_surface_samples,
)

BODY = "body"
TRAIN_SEED, TEST_SEED = 11, 12
N_TEST_BETAS = 16
BETA_SOURCE = "pop"  # in the ground truth's cache name: the population's codes, not the box's
DATA_DIR = Path("data/fields")
CHECKPOINT_DIR = Path("build/fields")
CHECKPOINT_EVERY = 500


@dataclass
class Surface:
    """A field's surface in canonical space for one shape: vertices (V, 3), faces (F, 3), loops or None."""

    vertices: np.ndarray
    faces: np.ndarray
    loops: dict[str, np.ndarray] | None


class Surfaces:
    """Canonical surfaces of a garment (its explicit model) or of the body (the mean body) per beta."""

    def __init__(self, field_id: str, explicit_dir: Path | None = None):
        self.field_id = field_id
        body = BodyModel.load()
        self.body_vertices = body.vertices(np.asarray(DEFAULT_BETA))
        self.body_faces = body.faces
        if field_id == BODY:
            self.template = Surface(self.body_vertices, self.body_faces, None)
            self.model = None
            self.source = ""  # the mean body never changes
        else:
            g = load_catalog()[field_id]
            self.template = Surface(g.vertices, g.faces, g.openings)
            self.model = ExplicitModel.load(field_id, explicit_dir)
            # Ground truth and checkpoints belong to one explicit model: a retrained one starts afresh.
            path = Path(explicit_dir or models_dir() / "explicit") / f"{field_id}.npz"
            self.source = file_sha256(path)[:12]

    def __call__(self, beta: np.ndarray) -> Surface:
        if self.model is None:
            return self.template
        return Surface(self.model.canonical(beta), self.template.faces, self.template.loops)

    def box(self) -> tuple[np.ndarray, float]:
        """(centre (3,), half extent) of the template's bounding box padded by PAD: x normalisation."""
        lo, hi = self.template.vertices.min(0) - PAD, self.template.vertices.max(0) + PAD
        return (lo + hi) / 2, float((hi - lo).max() / 2)


def stack(samples: list[FieldSamples]) -> dict[str, np.ndarray]:
    return {k: np.concatenate([getattr(s, k) for s in samples]) for k in ("x", "f", "grad_f", "h", "grad_h")}


def training_data(surfaces: Surfaces, config: FieldConfig, log=print) -> dict[str, np.ndarray]:
    """Cached ground truth over the training shapes: x, f, grad_f, h, grad_h (P, ...) float32, beta (P, 3)."""
    size = f"{config.n_betas}x{config.points_per_beta}"
    name = f"{surfaces.field_id}_{size}_s{config.seed}_v{GROUND_TRUTH_VERSION}"
    name += f"_{surfaces.source}" if surfaces.source else ""
    name += f"_{BETA_SOURCE}"
    path = DATA_DIR / f"{name}.npz"
    if path.exists():
        with np.load(path) as z:
            return dict(z)
    t0 = time.perf_counter()
    betas = population.codes(config.n_betas, "train", TRAIN_SEED)
    parts, beta_rows = [], []
    for i, beta in enumerate(betas):
        s = surfaces(beta)
        rng = np.random.default_rng((config.seed, i))
        parts.append(
            garment_samples(
                s.vertices, s.faces, s.loops, surfaces.body_vertices, surfaces.body_faces,
                config.points_per_beta, rng,
            )
        )  # fmt: skip
        beta_rows.append(np.repeat(beta[None], config.points_per_beta, axis=0))
    data = {k: v.astype(np.float32) for k, v in stack(parts).items()}
    data["beta"] = np.concatenate(beta_rows).astype(np.float32)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **data)
    os.replace(tmp, path)
    log(f"{surfaces.field_id}: ground truth for {config.n_betas} shapes in {time.perf_counter() - t0:.0f} s")
    return data


def _loss(net: FieldNet, batch: dict[str, torch.Tensor], grad_weight: float) -> torch.Tensor:
    """eq. 1 in metres. Batches mix shapes: a (P, 3) beta broadcasts row by row like a (1, 3) one."""
    if grad_weight > 0:
        f, h, gf, gh = net.with_gradient(batch["x"], batch["beta"])
        grad = (gf - batch["grad_f"]).abs().sum(1).mean() + (gh - batch["grad_h"]).abs().sum(1).mean()
    else:
        f, h = net(batch["x"], batch["beta"])
        grad = torch.zeros(())
    return (f - batch["f"]).abs().mean() + (h - batch["h"]).abs().mean() + grad_weight * grad


@dataclass
class TrainResult:
    net: FieldNet
    seconds: float
    """Training wall time, summed over resumed runs (ground truth excluded)."""


def train_field(
    surfaces: Surfaces, config: FieldConfig, name: str | None = None, log=print, stop_at: int | None = None
) -> TrainResult:
    """Train (or resume) the field of ``surfaces``; checkpoint ``build/fields/<name>.pt``."""
    from tqdm import tqdm

    name = name or surfaces.field_id
    data = training_data(surfaces, config, log)
    tensors = {k: torch.from_numpy(v) for k, v in data.items()}
    torch.manual_seed(config.seed)
    centre, extent = surfaces.box()
    net = FieldNet(config, centre, extent)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    checkpoint = CHECKPOINT_DIR / f"{name}.pt"
    start, before = 0, 0.0
    if checkpoint.is_file():
        state = torch.load(checkpoint, weights_only=False)
        if state["config"] == asdict(config) and state.get("source", "") == surfaces.source:
            net.load_state_dict(state["net"])
            opt.load_state_dict(state["opt"])
            start, before = state["step"], state["seconds"]
        else:
            log(f"{checkpoint} holds another config or explicit model; starting afresh")
    n_points = len(data["x"])
    end = config.steps if stop_at is None else min(stop_at, config.steps)
    t0 = time.perf_counter()
    saved = before  # the seconds the checkpoint holds
    bar = tqdm(
        range(start, end), desc=name, unit="step", initial=start, total=config.steps, leave=False,
        mininterval=10,
    )  # fmt: skip
    for step in bar:
        lr = config.lr * (0.01 + 0.99 * 0.5 * (1 + np.cos(np.pi * step / max(config.steps - 1, 1))))
        for group in opt.param_groups:
            group["lr"] = lr
        idx = torch.from_numpy(np.random.default_rng((config.seed, step)).integers(0, n_points, config.batch))
        loss = _loss(net, {k: v[idx] for k, v in tensors.items()}, config.grad_weight)
        opt.zero_grad()
        loss.backward()
        opt.step()
        done = step + 1
        if done % 50 == 0:
            bar.set_postfix(loss=f"{loss.item() * 1e3:.3f}")
        if done % CHECKPOINT_EVERY == 0 or done == end:
            checkpoint.parent.mkdir(parents=True, exist_ok=True)
            state = {"config": asdict(config), "net": net.state_dict(), "opt": opt.state_dict()}
            state["source"] = surfaces.source
            saved = before + time.perf_counter() - t0
            state.update(step=done, seconds=saved)
            torch.save(state, checkpoint)
    bar.close()
    # The seconds the last checkpoint holds (the export reads them there), not counting its own save:
    # 0.55 against 0.50 s made a tiny run's two records round apart.
    return TrainResult(net, saved)


def load_trained(surfaces: Surfaces, name: str) -> FieldNet | None:
    """The finished network of checkpoint ``name``, or None if it is missing or unfinished."""
    run = finished_run(surfaces, name)
    return None if run is None else run.net


def finished_run(surfaces: Surfaces, name: str) -> TrainResult | None:
    """The finished run (network, training seconds) of checkpoint ``name``, or None."""
    path = CHECKPOINT_DIR / f"{name}.pt"
    if not path.is_file():
        return None
    state = torch.load(path, weights_only=False)
    config = FieldConfig(**state["config"])
    if state["step"] < config.steps:
        return None
    net = FieldNet(config, *surfaces.box())
    net.load_state_dict(state["net"])
    return TrainResult(net, state["seconds"])


def held_out(
    surfaces: Surfaces, n_per_beta: int = 2048, seed: int = 5
) -> list[tuple[np.ndarray, FieldSamples]]:
    """Per held-out shape (never trained on): (beta (3,), samples within 1 cm of its surface)."""
    out = []
    for i, beta in enumerate(population.codes(N_TEST_BETAS, "test", TEST_SEED)):
        s = surfaces(beta)
        rng = np.random.default_rng((seed, i))
        out.append((beta, near_surface_samples(s.vertices, s.faces, s.loops, n_per_beta, rng)))
    return out


def field_errors(predict, tests: list[tuple[np.ndarray, FieldSamples]]) -> dict[str, float]:
    """Mean |f - f_GT| and |h - h_GT| in mm, and mean gradient errors; ``predict(x, beta) -> (f, h)``."""
    ef, eh = [], []
    for beta, s in tests:
        f, h = predict(s.x.astype(np.float32), beta.astype(np.float32)[None])
        ef.append(np.abs(f - s.f))
        eh.append(np.abs(h - s.h))
    return {"f_mm": float(np.concatenate(ef).mean() * 1e3), "h_mm": float(np.concatenate(eh).mean() * 1e3)}


def torch_predict(net: FieldNet):
    def predict(x, beta):
        with torch.no_grad():
            f, h = net(torch.from_numpy(x), torch.from_numpy(beta))
        return f.double().numpy(), h.double().numpy()

    return predict
