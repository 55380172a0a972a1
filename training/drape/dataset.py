"""The drape dataset: every catalog garment draped on sampled body shapes (paper Figure 2, top).

Layout under ``data/drapes/`` (resumable: finished bodies are skipped, files appear atomically):

    shapes.json            the sampled betas per split, the seeds and the drape settings
    train/000.npz ...      one file per body: for each garment its world and canonical vertices
    test/000.npz ...       held-out shapes, never seen by training
    build.json             measured build time

Bodies (``DatasetConfig.source``): ``population`` (the default, issue 55) draws real adults of
NHANES, tails included (``training.drape.population``); each file then holds the served body
(``body``) beside its garment code (``beta``). ``box``, the dataset before it: a scrambled Sobol
sequence over the documented adult range of Anny's (gender, height, weight) parameters; the test
split uses another seed, so no test shape is a training shape. A Sobol sample of a few dozen points
leaves the corners of the box thin (the tallest and heaviest, the shortest and lightest), where the
explicit models then extrapolate and sink into the body, so the training split also holds the box's
8 corners drawn ``corner_inset`` of each range inwards, and the test split the 4 extreme corners
themselves (``box_corners``): the corners a benchmark measures are never training shapes.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from service.geometry.closest import ClosestPoint
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.catalog import Garment, load_catalog
from training.drape import energy
from training.drape.solve import DrapeProblem, DrapeSettings, body_planes, drape, stick_to_skin

HEIGHT_PARAM_RANGE = (0.12, 0.72)  # Anny height params of the supported range (~1.35 to ~2.15 m)
WEIGHT_PARAM_RANGE = (0.0, 1.0)
PINNED_OPENINGS = ("waist", "top")
"""Openings held where the rest mesh puts them on each body: a bottom hangs from its waistband, as if
belted; a strapless dress from its top edge (an import names it ``top``), as a boned bodice holds it.
Unpinned, the dress of ``tests/garment_files.py`` slid 44 cm down to the hips in the drape."""
DEFAULT_DIR = Path("data/drapes")


@dataclass(frozen=True)
class DatasetConfig:
    n_train: int = 28
    """Training bodies (population: two per sex and BMI band; box: Sobol shapes before the corners)."""
    n_test: int = 8
    """Held-out bodies."""
    train_seed: int = 1
    test_seed: int = 2
    garments: tuple[str, ...] = ()
    """Garment ids; empty means the whole catalog."""
    corners: bool = True
    """Add the inset box corners to the training split and the extreme ones to the test split."""
    corner_inset: float = 0.1
    """Share of the height and weight ranges by which the training corners sit inside the box."""
    source: str = "population"
    """``population``: real adults (``training.drape.population``); ``box``: Sobol shapes and corners."""

    def __post_init__(self):
        if self.source not in ("population", "box"):
            raise ValueError(f"source must be 'population' or 'box', got {self.source!r}")


def sample_betas(n: int, seed: int) -> np.ndarray:
    """``(n, 3)`` betas (gender, height, weight) spread over the supported range."""
    # Draw a power of two (Sobol's balanced size) and keep the first n: the same points as random(n).
    u = qmc.Sobol(d=3, scramble=True, seed=seed).random_base2(int(np.ceil(np.log2(max(n, 1)))))[:n]
    lo = np.array([0.0, HEIGHT_PARAM_RANGE[0], WEIGHT_PARAM_RANGE[0]])
    hi = np.array([1.0, HEIGHT_PARAM_RANGE[1], WEIGHT_PARAM_RANGE[1]])
    return lo + u * (hi - lo)


def box_corners(inset: float = 0.0, extremes_only: bool = False) -> np.ndarray:
    """``(8, 3)`` betas at the corners of the supported box (gender 0 and 1, each height and weight
    bound moved ``inset`` of its range inwards), or with ``extremes_only`` ``(4, 3)``: each gender at
    the shortest-lightest and the tallest-heaviest corner."""
    (h0, h1), (w0, w1) = HEIGHT_PARAM_RANGE, WEIGHT_PARAM_RANGE
    hs = (h0 + inset * (h1 - h0), h1 - inset * (h1 - h0))
    ws = (w0 + inset * (w1 - w0), w1 - inset * (w1 - w0))
    pairs = [(hs[0], ws[0]), (hs[1], ws[1])] if extremes_only else [(h, w) for h in hs for w in ws]
    return np.array([[g, h, w] for g in (0.0, 1.0) for h, w in pairs])


def split_bodies(config: DatasetConfig) -> dict[str, tuple[np.ndarray, np.ndarray | None, list]]:
    """Per split (betas ``(B, 3)``, served bodies ``(B, V, 3)`` or None where a beta's box body is
    the body, the people as ``[sex, row]`` or empty)."""
    if config.source == "box":
        return {k: (b, None, []) for k, b in split_betas(config).items()}
    from training.drape.population import people

    out = {}
    for split, n in (("train", config.n_train), ("test", config.n_test)):
        picked = people(n, split)
        out[split] = (
            np.array([c for _, c, _ in picked]).reshape(-1, 3),
            np.array([v for _, _, v in picked]) if picked else None,
            [[p.sex, p.row] for p, _, _ in picked],
        )
    return out


def split_betas(config: DatasetConfig) -> dict[str, np.ndarray]:
    """The box betas of each split: Sobol points first, then the corners (so growing ``n_train`` or
    ``n_test`` is a rebuild, and the corners never shift the Sobol prefix)."""
    train = sample_betas(config.n_train, config.train_seed)
    test = sample_betas(config.n_test, config.test_seed)
    if config.corners:
        train = np.concatenate([train, box_corners(config.corner_inset)])
        test = np.concatenate([test, box_corners(extremes_only=True)])
    return {"train": train, "test": test}


@dataclass
class GarmentDrape:
    world: np.ndarray  # (V, 3) equilibrium on the body
    canonical: np.ndarray  # (V, 3) the same with the diffused body displacement removed
    iterations: int
    converged: bool
    residual: float
    min_distance: float  # m, signed distance of the deepest vertex to the body surface
    seconds: float
    last_move: float  # m, largest vertex motion over the solver's last window of iterations


def drape_garment(
    garment: Garment,
    body: np.ndarray,
    faces: np.ndarray,
    space: CanonicalSpace,
    settings: DrapeSettings,
    planes=None,
    rest_body: np.ndarray | None = None,
) -> GarmentDrape:
    """Drape one garment (template on the mean body) on a body ``(V, 3)`` and canonicalise it.

    ``rest_body (V, 3)``: the body of a size's chart row (issue 56, ``training.garments.grading``);
    the rest shape is then the template carried onto it, cloth of that size, whatever body wears it.
    None: the one-size garment, graded ``settings.grading`` of the way to the wearer."""
    t0 = time.perf_counter()
    planes = planes or body_planes(body, faces)
    carried = space.to_body(garment.vertices, body)
    loops = [
        np.asarray(garment.openings[k], dtype=np.int64) for k in PINNED_OPENINGS if k in garment.openings
    ]
    pinned = np.concatenate(loops) if loops else np.zeros(0, dtype=np.int64)
    # Shops sell sizes: the rest shape is graded part of the way to the body (settings.grading),
    # the rest of the body's change shows as a taut garment on a big body and a loose one on a
    # small body.
    if rest_body is None:
        graded = garment.vertices + settings.grading * (carried - garment.vertices)
    else:
        graded = space.to_body(garment.vertices, rest_body)
    problem = DrapeProblem(
        energy.rest_shape(graded, garment.faces),
        energy.bending_matrix(graded, garment.faces),
        planes, pinned, carried[pinned], settings,
    )  # fmt: skip
    result = drape(stick_to_skin(problem, carried), carried)
    result.vertices = clear_of_body(result.vertices, ClosestPoint.build(body, faces))
    # Start the inversion from the template shifted by the drape: exact where nothing moved.
    canonical, _ = space.to_canonical(
        result.vertices, body, start=garment.vertices + (result.vertices - carried)
    )
    depth = float(planes.signed_distance(result.vertices)[0].min())
    return GarmentDrape(
        result.vertices, canonical, result.iterations, result.converged, result.residual, depth,
        time.perf_counter() - t0, result.last_move,
    )  # fmt: skip


CLEARANCE = 5e-4  # m


def clear_of_body(world: np.ndarray, body: ClosestPoint, clearance: float = CLEARANCE) -> np.ndarray:
    """``world (V, 3)`` with every vertex inside the exact body mesh moved out along the normal of its
    closest body point to ``clearance``. The simulator sees the body through a smoothed distance
    (``BodyPlanes``), which is up to ~3 mm off in the armpits and crotch, where a few vertices then
    rest inside the true surface; this moves those (~0.001 % of the vertices) and nothing else."""
    q = body.query(world)
    inside = q.signed < 0
    out = world.copy()
    out[inside] = q.point[inside] + clearance * q.normal[inside]
    return out


def clear_dataset(out: Path = DEFAULT_DIR) -> int:
    """Apply ``clear_of_body`` to every drape already on disk (canonical recomputed where it moved);
    returns the number of vertices moved."""
    model, catalog = BodyModel.load(), load_catalog()
    space = CanonicalSpace.build(model.vertices(np.asarray(DEFAULT_BETA)), model.faces)
    moved = 0
    for path in sorted(Path(out).glob("*/[0-9][0-9][0-9].npz")):
        with np.load(path) as z:
            arrays = dict(z)
        body = drape_body(model, arrays)
        closest = ClosestPoint.build(body, model.faces)
        changed = False
        for gid in catalog:
            if f"{gid}/world" not in arrays:
                continue
            world = arrays[f"{gid}/world"].astype(np.float64)
            fixed = clear_of_body(world, closest)
            idx = np.flatnonzero(np.any(fixed != world, axis=1))
            if len(idx):
                start = arrays[f"{gid}/canonical"][idx].astype(np.float64)
                canonical, _ = space.to_canonical(fixed[idx], body, start=start)
                arrays[f"{gid}/world"] = fixed.astype(np.float32)
                arrays[f"{gid}/canonical"][idx] = canonical.astype(np.float32)
                moved += len(idx)
                changed = True
        if changed:
            _save_atomic(path, arrays)
    return moved


def _save_atomic(path: Path, arrays: dict) -> None:
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


_WORKER: dict = {}


def _init_worker(garment_ids: tuple[str, ...]) -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    model = BodyModel.load()
    catalog = load_catalog()
    mean = model.vertices(np.asarray(DEFAULT_BETA))
    _WORKER.update(
        model=model,
        garments=[catalog[g] for g in garment_ids],
        space=CanonicalSpace.build(mean, model.faces),
    )


def drape_body(model: BodyModel, arrays) -> np.ndarray:
    """The body ``(V, 3)`` of one drape file's arrays: the stored served body, else the box body of
    its beta."""
    return arrays["body"].astype(np.float64) if "body" in arrays else model.vertices(arrays["beta"])


def _drape_body(job: tuple[Path, np.ndarray, np.ndarray | None, DrapeSettings]) -> tuple[Path, float]:
    path, beta, served, settings = job
    t0 = time.perf_counter()
    model, space = _WORKER["model"], _WORKER["space"]
    body = model.vertices(beta) if served is None else served
    planes = body_planes(body, model.faces)
    arrays = {"beta": beta} | ({} if served is None else {"body": served.astype(np.float32)})
    for g in _WORKER["garments"]:
        d = drape_garment(g, body, model.faces, space, settings, planes)
        arrays[f"{g.id}/world"] = d.world.astype(np.float32)
        arrays[f"{g.id}/canonical"] = d.canonical.astype(np.float32)
        stats = [d.iterations, float(d.converged), d.residual, d.min_distance, d.seconds, d.last_move]
        arrays[f"{g.id}/stats"] = np.array(stats)
    _save_atomic(path, arrays)
    return path, time.perf_counter() - t0


STATS = ("iterations", "converged", "residual", "min_distance", "seconds", "last_move")


def _extends(old: dict, new: dict) -> bool:
    """True when ``new`` only adds shapes to ``old`` (Sobol prefixes): finished bodies stay valid."""
    same = (
        all(old[k] == new[k] for k in ("settings",))
        and old["config"]["garments"] == new["config"]["garments"]
    )
    seeds = all(old["config"].get(k) == new["config"].get(k) for k in ("train_seed", "test_seed", "source"))
    prefix = all(new["betas"][s][: len(old["betas"][s])] == old["betas"][s] for s in ("train", "test"))
    return same and seeds and prefix


def build_dataset(out: Path = DEFAULT_DIR, config: DatasetConfig = DatasetConfig(), workers: int = 2) -> dict:
    """Drape every garment on every shape not yet on disk; returns the build record."""
    from multiprocessing import get_context

    from tqdm import tqdm

    out = Path(out)
    garment_ids = config.garments or tuple(load_catalog())
    settings = DrapeSettings()
    splits = split_bodies(config)
    manifest = {
        "config": asdict(config) | {"garments": list(garment_ids)},
        "settings": asdict(settings),
        "betas": {k: v[0].tolist() for k, v in splits.items()},
        "people": {k: v[2] for k, v in splits.items()},
    }
    out.mkdir(parents=True, exist_ok=True)
    shapes_path = out / "shapes.json"
    if shapes_path.exists() and not _extends(json.loads(shapes_path.read_text()), manifest):
        raise RuntimeError(f"{shapes_path} was built with another configuration; remove {out} to rebuild")
    shapes_path.write_text(json.dumps(manifest, indent=1))
    jobs = []
    # The held-out split first: an interrupted build can already be measured.
    for split, (betas, bodies, _) in sorted(splits.items(), key=lambda kv: kv[0] != "test"):
        (out / split).mkdir(exist_ok=True)
        jobs += [(out / split / f"{i:03d}.npz", b, None if bodies is None else bodies[i], settings)
                 for i, b in enumerate(betas)]  # fmt: skip
    todo = [j for j in jobs if not j[0].exists()]
    record_path = out / "build.json"
    record = json.loads(record_path.read_text()) if record_path.exists() else {"seconds": 0.0, "bodies": 0}
    # Wall time accumulates over interrupted and resumed runs, written after every body.
    t0, base = time.perf_counter(), record["seconds"]
    record["workers"] = workers
    if todo:
        with get_context("spawn").Pool(workers, _init_worker, (garment_ids,)) as pool:
            for _, seconds in tqdm(
                pool.imap_unordered(_drape_body, todo), total=len(todo), desc="drapes", unit="body"
            ):
                record["bodies"] += 1
                record["cpu_seconds"] = record.get("cpu_seconds", 0.0) + seconds
                record["seconds"] = base + time.perf_counter() - t0
                record_path.write_text(json.dumps(record, indent=1))
    return record


def split_body_vertices(model: BodyModel, split: dict) -> list[np.ndarray]:
    """The body ``(V, 3)`` float64 of each drape of a ``load_split`` split: its stored served body,
    else the box body of its beta."""
    if "body" in split:
        return [b.astype(np.float64) for b in split["body"]]
    return [model.vertices(b) for b in split["beta"]]


def load_split(out: Path, split: str, garment_id: str) -> dict[str, np.ndarray]:
    """Stacked arrays of one garment over a split: beta (B, 3), world/canonical (B, V, 3), stats, and
    body (B, V_body, 3) where every file holds its served body."""
    files = sorted((Path(out) / split).glob("[0-9][0-9][0-9].npz"))
    if not files:
        raise FileNotFoundError(f"no drapes in {Path(out) / split}; run python -m training.drape")
    rows = [np.load(f) for f in files]
    return {
        "beta": np.stack([r["beta"] for r in rows]),
        "world": np.stack([r[f"{garment_id}/world"] for r in rows]),
        "canonical": np.stack([r[f"{garment_id}/canonical"] for r in rows]),
        "stats": np.stack([r[f"{garment_id}/stats"] for r in rows]),
    } | ({"body": np.stack([r["body"] for r in rows])} if all("body" in r for r in rows) else {})
