"""GLB size per encoding (``service.pipeline.gltf.Compression``), and what a client decodes from it.

    python -m benchmarks.glb_sizes [--garments pants,tshirt,jacket] [--repeats 5] [--threads 2]
                                   [--all-outfits] [--gzip]

One untangled outfit on the committed models (default: body + pants + tshirt + jacket, gender 0,
180 cm, 80 kg: issue 22's), written in each encoding: bytes, bytes after gzip (level 6, what HTTP
compression sends), the median encode time, and the decoded outfit (``service.pipeline.gltf_read``,
meshopt views by the official decoder) measured as docs/design.md section 7 defines it: intersecting
triangle pairs between layers (exact tests) and the penetration (largest share of any garment's
vertices on the wrong side of an inner layer), on the meshes the GLB holds (display meshes, with
their seam vertices). The covariant field h that penetration needs at a vertex is the one at the
canonical point of the uncompressed vertex (``CanonicalSpace.to_canonical``), so every encoding is
measured with the same h; a vertex of another encoding takes its nearest uncompressed vertex's.
``--all-outfits`` adds those two measures for every outfit of ``benchmarks.outfits`` on its 3 held-out
bodies (about two minutes).
"""

from __future__ import annotations

import argparse
import gzip
import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from service.pipeline.gltf import Compression, outfit_glb
from service.pipeline.gltf_read import MeshoptDecode, read_glb
from service.pipeline.quality import Layer, intersections, penetration

VARIANTS: tuple[Compression, ...] = ("none", "quantized", "meshopt")
DEFAULT_OUTFIT = ("pants", "tshirt", "jacket")


def outfit_layers(models, garments: tuple[str, ...], gender=0.0, height_cm=180.0, weight_kg=80.0):
    """(``GltfLayer``s of the untangled outfit with the body, as ``ModelEngine.make`` writes them, beta)."""
    from service.pipeline.body import shape_from_measurements

    beta = shape_from_measurements(models.body, gender, height_cm, weight_kg)
    return _layers(models, garments, beta), beta


def _layers(models, garments, beta):
    from service.pipeline.outfit import make_outfit
    from service.pipeline.tryon import glb_layers

    outfit = make_outfit(models, list(garments), beta, measure=False)
    return glb_layers(outfit.garments, models.catalog, (outfit.body_vertices, outfit.body_faces))


@dataclass
class DecodedMeasures:
    """The quality measures of decoded outfits [(name, vertices (V, 3), faces (F, 3))], body first,
    with every garment's h taken at the canonical points of the ``reference`` outfit's vertices."""

    models: object
    beta: np.ndarray
    reference: list[tuple[str, np.ndarray, np.ndarray]]

    def __post_init__(self):
        body = self.models.body.vertices(self.beta)
        self._canonical = [self.models.space.to_canonical(v, body)[0] for _, v, _ in self.reference[1:]]
        self._trees = [cKDTree(v) for _, v, _ in self.reference[1:]]
        self._h: dict[tuple[int, int], np.ndarray] = {}

    def h_reference(self, inner: int, outer: int) -> np.ndarray:
        """h of layer ``inner`` at the reference vertices of layer ``outer`` (V_outer,)."""
        if (inner, outer) not in self._h:
            name = self.reference[inner][0]
            self._h[inner, outer] = self.models.fields(name, self._canonical[outer - 1], self.beta).h
        return self._h[inner, outer]

    def __call__(self, decoded: list[tuple[str, np.ndarray, np.ndarray]]) -> tuple[int, dict[str, float]]:
        """(intersecting triangle pairs between layers, in total; penetration per garment)."""
        if [n for n, _, _ in decoded] != [n for n, _, _ in self.reference]:
            raise ValueError("decoded layers must be the reference's, in its order")
        layers = [Layer(n, v, f) for n, v, f in decoded]
        nearest = [self._trees[j - 1].query(layers[j].vertices)[1] for j in range(1, len(layers))]

        def h_at(inner, outer):
            return self.h_reference(inner, outer)[nearest[outer - 1]]

        return sum(intersections(layers).values()), penetration(layers, h_at)


def rows(models, garments=DEFAULT_OUTFIT, repeats: int = 5, meshopt_decode: MeshoptDecode | None = None,
         beta: np.ndarray | None = None):  # fmt: skip
    """One dict per encoding: variant, bytes, gzip_bytes, encode_ms, crossing_pairs, penetration (max)
    of the outfit on the body of issue 22 (or of shape ``beta (3,)``)."""
    if beta is None:
        layers, beta = outfit_layers(models, garments)
    else:
        layers = _layers(models, garments, beta)
    out, measure = [], None
    for variant in VARIANTS:
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            data = outfit_glb(layers, variant)
            times.append(time.perf_counter() - t0)
        decoded = read_glb(data, meshopt_decode)
        measure = measure or DecodedMeasures(models, beta, decoded)
        pairs, pen = measure(decoded)
        out.append({
            "variant": variant, "bytes": len(data), "gzip_bytes": len(gzip.compress(data, 6)),
            "encode_ms": 1e3 * float(np.median(times)), "crossing_pairs": pairs,
            "penetration": max(pen.values()),
        })  # fmt: skip
    return out


def gzip_table(layers, repeats: int) -> None:
    """What gzip (HTTP compression, one core) costs and saves on each encoding, levels 1 and 6: why
    the service sends GLBs as they are and leaves compression to a proxy (docs/operations.md, "Outfit ids,
    GLB URLs and HTTP caching")."""
    print("\n## gzip of each encoding (median ms of one core)")
    print("| variant | bytes | level 1 bytes | level 1 ms | level 6 bytes | level 6 ms |")
    print("|---|---:|---:|---:|---:|---:|")
    for variant in VARIANTS:
        data, cells = outfit_glb(layers, variant), []
        for level in (1, 6):
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                size = len(gzip.compress(data, level))
                times.append(time.perf_counter() - t0)
            cells.append(f"{size:,} | {1e3 * float(np.median(times)):.0f}")
        print(f"| {variant} | {len(data):,} | {' | '.join(cells)} |")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--garments", default=",".join(DEFAULT_OUTFIT))
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--all-outfits", action="store_true")
    parser.add_argument("--gzip", action="store_true", help="also time gzip of each encoding")
    args = parser.parse_args(argv)
    from service.pipeline.outfit import OutfitModels

    models = OutfitModels.load(threads=args.threads)
    garments = tuple(args.garments.split(","))
    print(f"## GLB of body + {' + '.join(garments)} (gender 0, 180 cm, 80 kg), untangled")
    print("| variant | bytes | gzip bytes | encode ms | crossing pairs after decoding | penetration % |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows(models, garments, args.repeats):
        print(f"| {r['variant']} | {r['bytes']:,} | {r['gzip_bytes']:,} | {r['encode_ms']:.1f} "
              f"| {r['crossing_pairs']} | {100 * r['penetration']:.3f} |")  # fmt: skip
    if args.gzip:
        gzip_table(outfit_layers(models, garments)[0], args.repeats)
    if args.all_outfits:
        all_outfits(models)


def all_outfits(models) -> None:
    from benchmarks.outfits import BODY_SEED, OUTFITS
    from training.drape.dataset import sample_betas

    print("\n## Decoded outfits of benchmarks.outfits, untangled: crossing pairs / penetration %")
    print("| outfit | body | " + " | ".join(VARIANTS) + " |")
    print("|---|---|" + "---:|" * len(VARIANTS))
    for ids in OUTFITS:
        for b, beta in enumerate(sample_betas(3, BODY_SEED)):
            cells = [f"{r['crossing_pairs']} / {100 * r['penetration']:.3f}"
                     for r in rows(models, ids, repeats=1, beta=beta)]  # fmt: skip
            print(f"| {', '.join(ids)} | {b} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
