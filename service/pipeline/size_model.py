"""A garment worn in one of its sizes (issue 56): the explicit model's drape moved by the size's cut.

The explicit model (``service.pipeline.explicit``) predicts, for a body code beta, the drape of the
one-size garment whose rest shape is graded ``ONE_SIZE_GRADING`` (70 %) of the way from the mean body
to the wearer: its cut grows with the shopper. A size is a fixed cut, the style's pattern on the size's
chart body (``training.garments.grading``). Each is described by two measurements of the body it is cut
for: its primary girth (chest for a top, hip for a bottom: how wide) and its height (how long):

    one-size cut  m_f = m_mean + grading (m_wearer - m_mean)      (per measurement)
    size cut      m_s = the size's chart body's
    delta         = log(m_s / m_f)    (2,): 0 where the size is cut as the one-size garment is

and the size model adds to the explicit model's body-offset coordinates q (``ExplicitModel.encode``)

    q_s(beta, delta) = q_f(beta) + sum_k c_k basis_k
    c = delta_girth A(beta, delta) + delta_height B(beta, delta)

so that delta = 0 is the explicit model exactly, a bigger cut hangs further off the body and a smaller
one lies closer (heights are log-encoded below 5 mm, so never inside). ``basis`` is the uncentred PCA
of the drapes' differences q_s - q_f over the size drapes (``training.drape.sizes``); A and B are one
network's two halves, trained on them (``training.explicit_sizes``). Files:
``models/explicit/<id>.size.npz``, which also hold the sizes' chart measurements
(``models/garments/size_charts.json``); the coordinates q are those of the explicit model beside it
(``<id>.npz``: its anchors and frames).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from service.process.paths import models_dir

SUFFIX = ".size.npz"
ONE_SIZE_GRADING = 0.7
"""The one-size garment's grading: its rest shape follows this share of the wearer's change from the mean
body (the drapes' ``training.drape.solve.DrapeSettings.grading``): a shop's size run, which the drapes
before sizes stood for (docs/training.md)."""


def follow_cut(wearer: np.ndarray, mean: np.ndarray, grading: float) -> np.ndarray:
    """The measurements ``(2,)`` (primary girth, height; cm) the one-size garment is cut for on a wearer
    of ``wearer (2,)``: ``grading`` of the way from the mean body's ``mean (2,)``."""
    return np.asarray(mean, dtype=np.float64) + grading * (np.asarray(wearer, dtype=np.float64) - mean)


def size_delta(size: np.ndarray, wearer: np.ndarray, mean: np.ndarray, grading: float) -> np.ndarray:
    """delta ``(2,)`` (module docstring) of a size cut for ``size (2,)`` on a wearer of ``wearer (2,)``."""
    return np.log(np.asarray(size, dtype=np.float64) / follow_cut(wearer, mean, grading))


@dataclass
class SizeModel:
    garment_id: str
    letters: tuple[str, ...]  # the style's sizes, smallest first
    run: str  # the size chart's run (``service.pipeline.sizes.RUNS``)
    size_cm: np.ndarray  # (S, 2) each size's chart body's primary girth and height
    primary: str  # "chest" or "hip": the girth delta compares
    mean_cm: np.ndarray  # (2,) the mean body's primary girth and height
    grading: float  # the one-size garment's grading (``ONE_SIZE_GRADING`` when trained)
    basis: np.ndarray  # (K, V, 3) float16 orthonormal directions of q_s - q_f
    input_shift: np.ndarray  # (5,): (beta, delta) normalisation, (x - shift) / scale
    input_scale: np.ndarray  # (5,)
    weights: list[np.ndarray]  # per layer (out, in) float32; the last has 2K outputs
    biases: list[np.ndarray]
    coder: object = None  # the ExplicitModel (anchors and frames only suffice) whose q this moves

    def delta(self, size: str, wearer: np.ndarray) -> np.ndarray:
        """delta ``(2,)`` of ``size`` (one of ``letters``) on a wearer measuring ``wearer (2,)`` (primary
        girth, height; cm)."""
        return size_delta(self.size_cm[self.letters.index(size)], wearer, self.mean_cm, self.grading)

    def coefficients(self, beta: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """``(K,)`` coefficients for one beta ``(3,)`` and delta ``(2,)``: delta_girth times the network's
        first K outputs plus delta_height times its last K."""
        delta = np.asarray(delta, dtype=np.float64)
        x = np.concatenate([np.asarray(beta, dtype=np.float64), delta])
        h = (x - self.input_shift) / self.input_scale
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = h @ w.T.astype(np.float64) + b
            if i < len(self.weights) - 1:
                h = np.tanh(h)
        k = len(h) // 2
        return delta[0] * h[:k] + delta[1] * h[k:]

    def offset(self, beta: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """q_s - q_f ``(V, 3)`` float64."""
        return np.tensordot(self.coefficients(beta, delta), self.basis.astype(np.float64), axes=1)

    def canonical(self, follow: np.ndarray, beta: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """Canonical vertices ``(V, 3)`` of the size: ``follow (V, 3)`` is the explicit model's drape for
        ``beta (3,)``."""
        follow = np.asarray(follow, dtype=np.float64)
        if not np.any(delta):
            return follow
        return self.coder.decode(self.coder.encode(follow) + self.offset(beta, delta))

    def lift(self, follow: np.ndarray, sized: np.ndarray) -> float:
        """How far (m) ``sized (V, 3)`` lies further from the body than ``follow (V, 3)``, on average over
        the vertices, along the normals of the anchors (negative: closer)."""
        normals = self.coder.frame.astype(np.float64)[:, 2]
        return float(np.mean(np.einsum("vx,vx->v", normals, np.asarray(sized) - np.asarray(follow))))

    def save(self, path: Path) -> Path:
        arrays = {"basis": self.basis, "input_shift": self.input_shift, "input_scale": self.input_scale,
                  "letters": np.array(self.letters), "run": self.run,
                  "size_cm": np.asarray(self.size_cm, dtype=np.float64)}  # fmt: skip
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            arrays[f"w{i}"], arrays[f"b{i}"] = w, b
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, garment_id=self.garment_id, primary=self.primary, mean_cm=self.mean_cm,
                            grading=self.grading, **arrays)  # fmt: skip
        return path

    @classmethod
    def load(cls, garment_id: str, directory: Path | None = None) -> SizeModel | None:
        """The garment's size model, or None where it has none (imported garments come in one size)."""
        from service.pipeline.explicit import ExplicitModel

        directory = Path(directory or models_dir() / "explicit")
        path = directory / f"{garment_id}{SUFFIX}"
        if not path.exists():
            return None
        with np.load(path) as z:
            n = sum(1 for k in z.files if k.startswith("w"))
            model = cls(
                str(z["garment_id"]), tuple(str(x) for x in z["letters"]), str(z["run"]), z["size_cm"],
                str(z["primary"]),
                z["mean_cm"], float(z["grading"]), z["basis"], z["input_shift"], z["input_scale"],
                [z[f"w{i}"] for i in range(n)], [z[f"b{i}"] for i in range(n)],
            )  # fmt: skip
        with np.load(directory / f"{garment_id}.npz") as z:
            model.coder = ExplicitModel(garment_id, None, None, None, None, [], [], z["anchor"], z["frame"],
                                        float(z["soft"]))  # fmt: skip
        return model
