"""The Anny body model (torch), restricted to the adult shapes this service dresses.

beta is the service's body-shape code: ``(gender, height, weight)`` in Anny's phenotype
units, each in [0, 1]. Every other phenotype is held fixed (see ``FIXED_PHENOTYPES``) so that
the shape space stays small enough to simulate garments over it densely.
Frame: Anny's rest pose (A-pose), metres, Z up, body facing -Y.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

TOPOLOGY = "anny-noeyes-notongue"
BETA_LABELS = ("gender", "height", "weight")
# age 2/3 is Anny's "young adult" anchor; the others sit at their neutral value.
FIXED_PHENOTYPES = {"age": 2.0 / 3.0, "muscle": 0.25, "proportions": 0.5}
# MakeHuman's girth targets that shape a body beyond its phenotypes (issue 55, decision 0020): each is one
# signed local change, its "-incr" target for positive values and its "-decr" target for negative ones.
LOCAL_CHANGES = {
    "waist": "measure-waist-circ-incr",
    "hips": "measure-hips-circ-incr",
    "bust": "measure-bust-circ-incr",
    "thigh": "measure-thigh-circ-incr",
    "upperarm": "measure-upperarm-circ-incr",
    "belly": "stomach-pregnant-incr",
}
DEFAULT_CACHE_DIR = Path(os.environ.get("ULNEF_CACHE_DIR", Path.home() / ".cache" / "ulnef")) / "anny"


@lru_cache(maxsize=1)
def load_anny():
    """Build (first call ~60 s, ~800 MB cache) or load the watertight Anny model."""
    os.environ.setdefault("ANNY_CACHE_DIR", str(DEFAULT_CACHE_DIR))
    import anny  # local: importing anny initialises warp, which is slow and noisy

    model = anny.Anny(topology=TOPOLOGY)
    model.requires_grad_(False)
    return model


@lru_cache(maxsize=1)
def load_anny_extended():
    """Anny with extrapolated phenotypes and the ``LOCAL_CHANGES`` (the shapes of real adults)."""
    os.environ.setdefault("ANNY_CACHE_DIR", str(DEFAULT_CACHE_DIR))
    import anny

    model = anny.Anny(
        topology=TOPOLOGY, extrapolate_phenotypes=True, local_changes=list(LOCAL_CHANGES.values())
    )
    model.requires_grad_(False)
    return model


def anny_rest_extended(betas: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Rest vertices ``(B, V, 3)`` float64 of the extended Anny for betas ``(B, 3)`` (any real values:
    the phenotypes are extrapolated) and local changes ``(B, L)`` in ``LOCAL_CHANGES`` order."""
    import torch

    model = load_anny_extended()
    betas, local = np.atleast_2d(betas), np.atleast_2d(local)
    kw = phenotype_kwargs(betas)
    order = [list(model.local_change_labels).index(label) for label in LOCAL_CHANGES.values()]
    changes = torch.zeros((len(betas), len(order)), dtype=model.dtype)
    changes[:, order] = torch.as_tensor(local, dtype=model.dtype)
    out = model(phenotype_kwargs=kw, local_changes_kwargs=changes)
    return out["rest_vertices"].detach().double().numpy()


def phenotype_kwargs(betas: np.ndarray) -> dict:
    """Anny phenotype keyword arguments for betas ``(B, 3) float`` (gender, height, weight)."""
    import torch

    betas = np.asarray(betas, dtype=np.float64)
    if betas.ndim != 2 or betas.shape[1] != len(BETA_LABELS):
        raise ValueError(f"betas must be (B, {len(BETA_LABELS)}), got {betas.shape}")
    model = load_anny()
    kw = {k: torch.as_tensor(betas[:, i], dtype=model.dtype) for i, k in enumerate(BETA_LABELS)}
    for k, v in FIXED_PHENOTYPES.items():
        kw[k] = torch.full((len(betas),), v, dtype=model.dtype)
    return kw


@dataclass(frozen=True)
class AnnyRest:
    """Rest-pose output of Anny for a batch of shapes.

    vertices: (B, V, 3) float64, metres.
    bone_heads: (B, J, 3) float64, joint positions in the same frame (order of ``bone_labels``).
    """

    vertices: np.ndarray
    bone_heads: np.ndarray


def anny_rest(betas: np.ndarray) -> AnnyRest:
    """Rest-pose (A-pose) vertices and bones for betas ``(B, 3)``, straight from Anny."""
    model = load_anny()
    out = model(phenotype_kwargs=phenotype_kwargs(betas))
    return AnnyRest(
        vertices=out["rest_vertices"].detach().double().numpy(),
        bone_heads=out["rest_bone_heads"].detach().double().numpy(),
    )


def anny_faces() -> np.ndarray:
    """Triangles ``(F, 3) int64`` of the watertight topology, outward oriented."""
    return load_anny().faces.detach().numpy().astype(np.int64)


def bone_labels() -> list[str]:
    return list(load_anny().bone_labels)


def dominant_bone(min_weight: float = 0.0) -> np.ndarray:
    """Index ``(V,) int64`` of the bone with the strongest skinning weight at each vertex."""
    model = load_anny()
    w = model.vertex_bone_weights.detach().numpy()
    idx = model.vertex_bone_indices.detach().numpy()
    return idx[np.arange(len(idx)), np.argmax(w, axis=1)].astype(np.int64)
