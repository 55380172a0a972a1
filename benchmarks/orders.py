"""Garment orders: which stacks the service untangles, and what the report says of the rest.

Run (a minute or two each)::

    python -m benchmarks.orders [--outfits 24] [--seed 7]      # random stacks of 1-4, one per body
    python -m benchmarks.orders --pairs [--bodies 1]           # every ordered pair, held-out + corners
    python -m benchmarks.orders --stacks 100 [--seed 7]        # random stacks of 3-4, held-out + corners
    python -m benchmarks.orders --junctions                    # armholes and crotches, template vs drape
    python -m benchmarks.orders --let-down [--bodies 1]        # pairs let down at a junction, 4 corners
    python -m benchmarks.orders --refusals                     # share of all 3-4 stacks refused (~1.5 min)

The default: ``--outfits`` outfits of 1-4 catalog garments in random order (many of them orders cloth
cannot take: shorts over a skirt, a T-shirt over a jacket) on held-out body shapes (a Sobol seed no
training used), one request at a time as the service runs them (no quality measures). Per outfit: the
report's ``collision_free`` and ``crossing_pairs`` after the repair, and the time.

``--pairs`` (issue 21): every ordered pair of distinct catalog garments (inner first) on ``--bodies``
held-out bodies plus two corners of the supported box (the shortest and lightest man, the tallest
and heaviest woman: gender 0 is male). ``--stacks N``: N random stacks of 3-4 distinct garments in
random order, the first four on the box's extreme corners, the rest on held-out shapes. Both with the
quality measures. Per outfit:
- the crossing pairs, exactly, over every pair of layers of the returned meshes (and the report's
  ``crossing_pairs`` beside it where that differs: the report counts what the repair tested);
- the largest share of a garment's vertices inside an inner layer after the repair;
- the largest Green strain of any garment against its explicit mesh on the same body, i.e. what the
  layering stretched or pressed (p99 over its triangles, and the maximum);
- the time.
Then a summary: outfits, clean ones (0 crossing pairs and at most ``PENETRATION_LIMIT`` % penetrating),
the worst of each measure and the p50 time.

``--junctions`` (seconds, no outfits): for every ordered pair, how far the inner garment's junction (an
armhole, a crotch) hangs below the outer one's (``service.pipeline.collisions.layering.junction_run``), on the
catalog's rest meshes (what the layering rule reads) and on the garments' drapes on the mean body (the
explicit models at the default shape, in canonical space): a drape's armhole can hang lower than its
template's.
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from benchmarks.imported import corners
from service.pipeline.collisions.settings import SETTINGS
from service.pipeline.outfit import OutfitModels, make_outfit
from service.pipeline.strain import RestShape, green_strain_norms
from training.drape.dataset import sample_betas

BODY_SEED = 99
PENETRATION_LIMIT = 0.1  # %: issue 21's bound for a clean outfit


def random_orders(models: OutfitModels, args) -> None:
    rng = np.random.default_rng(args.seed)
    catalog = sorted(models.catalog)
    betas = sample_betas(args.outfits, BODY_SEED)
    print(f"## {args.outfits} random outfits (inner to outer) on held-out bodies")
    print("| outfit | body | collision free | crossing pairs | ms |")
    print("|---|---|---|---:|---:|")
    clean = 0
    for beta in betas:
        ids = [str(g) for g in rng.choice(catalog, size=rng.integers(1, 5), replace=False)]
        r = make_outfit(models, ids, beta, measure=False).report
        clean += r["collision_free"]
        body = ", ".join(f"{v:.2f}" for v in beta)
        print(f"| {' < '.join(ids)} | {body} | {'yes' if r['collision_free'] else 'no'} "
              f"| {r['crossing_pairs']} | {1e3 * r['seconds']['total']:.0f} |")  # fmt: skip
    print(f"\ncollision free: {clean} of {args.outfits}")


def measured(models: OutfitModels, ids: list[str], beta: np.ndarray) -> dict:
    """One outfit with the quality measures: crossing pairs, worst penetration (%), worst strain
    (p99 and max over the garments' triangles, against their explicit meshes on the same body), ms;
    or ``{"refused": reason}`` for an order the layering rule refuses."""
    refusals = models.refusals(ids)
    if refusals:
        return {"refused": "; ".join(r.reason for r in refusals)}
    outfit = make_outfit(models, ids, beta, measure=True)
    r = outfit.report
    # Against each garment's explicit mesh carried onto the same body: the stretch the layering added
    # (the body's own shape stretches every garment by the body map, layered or not).
    explicit = [models.explicit[g].canonical(np.asarray(beta, dtype=np.float64)) for g in ids]
    alone = models.space.to_bodies(explicit, outfit.body_vertices)
    strain_p99, strain_max = 0.0, 0.0
    for (_, vertices, faces), rest in zip(outfit.garments, alone, strict=True):
        norms = green_strain_norms(vertices, RestShape.build(rest, faces))
        strain_p99 = max(strain_p99, float(np.percentile(norms, 99)))
        strain_max = max(strain_max, float(norms.max()))
    penetration = 100 * max(r["penetration_after"].values(), default=0.0)
    # The exact all-pairs count on the returned meshes (every layer against every other), not the
    # report's, which counts what the repair tested (never fewer since the repair looks for what the
    # squeeze moved; printed beside it where they differ).
    exact = int(sum(r["intersections_after"].values()))
    return {
        "pairs": exact,
        "reported": int(r["crossing_pairs"]),
        "penetration": penetration,
        "strain_p99": strain_p99,
        "strain_max": strain_max,
        "ms": 1e3 * r["seconds"]["total"],
        "clean": exact == 0 and penetration <= PENETRATION_LIMIT,
    }


def _table(title: str, runs: list[tuple[list[str], np.ndarray, dict]]) -> None:
    print(f"## {title}")
    print("| outfit (inner < outer) | body (gender, height, weight) | clean | crossing pairs "
          "| penetration % | strain p99 | strain max | ms |")  # fmt: skip
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for ids, beta, m in runs:
        body = ", ".join(f"{v:.2f}" for v in beta)
        if "refused" in m:
            print(f"| {' < '.join(ids)} | {body} | refused: {m['refused']} | | | | | |")
            continue
        pairs = m["pairs"] if m["reported"] == m["pairs"] else f"{m['pairs']} (report: {m['reported']})"
        cells = [" < ".join(ids), body, "yes" if m["clean"] else "no", pairs, f"{m['penetration']:.3f}",
                 f"{m['strain_p99']:.3f}", f"{m['strain_max']:.3f}", f"{m['ms']:.0f}"]  # fmt: skip
        print("| " + " | ".join(map(str, cells)) + " |")
    results = [m for _, _, m in runs if "refused" not in m]
    refused = len(runs) - len(results)
    print()
    print("| outfits | accepted | refused | clean | worst crossing pairs | worst penetration % "
          "| worst strain p99 | p50 ms |")  # fmt: skip
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    worst = {key: max((m[key] for m in results), default=0) for key in ("pairs", "penetration", "strain_p99")}
    cells = [len(runs), len(results), refused, sum(m["clean"] for m in results), worst["pairs"],
             f"{worst['penetration']:.3f}", f"{worst['strain_p99']:.3f}",
             f"{np.median([m['ms'] for m in results]) if results else 0:.0f}"]  # fmt: skip
    print("| " + " | ".join(map(str, cells)) + " |")
    print()


def pairs(models: OutfitModels, args) -> None:
    betas = np.concatenate([sample_betas(args.bodies, BODY_SEED), corners()[[0, 3]]])
    runs = [
        (list(ids), beta, measured(models, list(ids), beta))
        for ids in itertools.permutations(sorted(models.catalog), 2)
        for beta in betas
    ]
    _table(f"Every ordered pair of catalog garments on {args.bodies} held-out bodies + 2 corners", runs)


def let_down(models: OutfitModels, args) -> None:
    """The ordered pairs whose outer garment is let down around the inner one's junction
    (``PairCaches.lowering``), on ``--bodies`` held-out bodies and all four corners: the pairs whose
    outcome depends most on the body."""
    betas = np.concatenate([sample_betas(args.bodies, BODY_SEED), corners()])
    chosen = [
        list(ids)
        for ids in itertools.permutations(sorted(models.catalog), 2)
        if not models.refusals(list(ids)) and models.pairs.lowering(*ids) is not None
    ]
    runs = [(ids, beta, measured(models, ids, beta)) for ids in chosen for beta in betas]
    _table(f"Pairs let down at a junction on {args.bodies} held-out bodies + 4 corners", runs)


def stacks(models: OutfitModels, args) -> None:
    rng = np.random.default_rng(args.seed)
    catalog = sorted(models.catalog)
    held_out, extremes = sample_betas(args.stacks, BODY_SEED), corners()
    runs = []
    for n in range(args.stacks):
        ids = [str(g) for g in rng.choice(catalog, size=rng.integers(3, 5), replace=False)]
        beta = extremes[n] if n < len(extremes) else held_out[n]  # the four corners first
        runs.append((ids, beta, measured(models, ids, beta)))
    _table(f"{args.stacks} random stacks of 3-4 garments (the first 4 on the box's corners)", runs)


def refusal_rates(models: OutfitModels) -> None:
    """The share of every ordered stack of 3 and of 4 distinct catalog garments that the layering rule
    refuses: what ``--stacks`` (sizes 3 and 4 equally likely, any order) refuses on average."""
    print("## Stacks the layering rule refuses, over every ordered stack of the catalog")
    print("| garments | stacks | refused | share % |")
    print("|---:|---:|---:|---:|")
    shares = []
    for size in (3, 4):
        stacks = list(itertools.permutations(sorted(models.catalog), size))
        refused = sum(bool(models.refusals(list(ids))) for ids in stacks)
        shares.append(refused / len(stacks))
        print(f"| {size} | {len(stacks)} | {refused} | {100 * shares[-1]:.1f} |")
    print(f"\nexpected share of --stacks refused: {100 * np.mean(shares):.1f} %")


def junctions(models: OutfitModels) -> None:
    from service.pipeline.body import DEFAULT_BETA
    from service.pipeline.collisions.layering import GarmentProfile, junction_run

    rule = models.pairs.layering_rule()
    beta = np.asarray(DEFAULT_BETA, dtype=np.float64)
    drape = {
        g: GarmentProfile.build(g, models.clearance.clear_of_body(models.explicit[g].canonical(beta)),
                                garment.faces, rule.body)
        for g, garment in models.catalog.items()
    }  # fmt: skip
    print("## Junctions: how far the inner garment's armhole or crotch hangs below the outer one's (cm)")
    print("| inner < outer | parts | on the rest meshes | on the mean body's drapes | refused |")
    print("|---|---|---:|---:|---|")
    for a, b in itertools.permutations(sorted(models.catalog), 2):
        rest = junction_run(rule.profile(models.catalog[a]), rule.profile(models.catalog[b]), rule.body)
        draped = junction_run(drape[a], drape[b], rule.body)
        if rest is None and draped is None:
            continue
        k, parts = (rest or draped)[1:]
        kinds = " + ".join(sorted({rule.body.names[k][i] for i in parts}))
        cm = [f"{100 * r[0] * SETTINGS.slice_step:.0f}" if r else "0" for r in (rest, draped)]
        refused = "yes" if models.refusals([a, b]) else "no"
        print(f"| {a} < {b} | {kinds} | {cm[0]} | {cm[1]} | {refused} |")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--outfits", type=int, default=24)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--pairs", action="store_true", help="every ordered pair (issue 21)")
    parser.add_argument("--bodies", type=int, default=1, help="held-out bodies for --pairs (plus 2 corners)")
    parser.add_argument("--stacks", type=int, default=0, help="random stacks of 3-4 garments (issue 21)")
    parser.add_argument("--junctions", action="store_true", help="armhole and crotch depths, no outfits")
    parser.add_argument("--let-down", action="store_true", help="pairs let down at a junction, 4 corners")
    parser.add_argument("--refusals", action="store_true", help="share of all 3-4 stacks refused, no outfits")
    args = parser.parse_args(argv)
    models = OutfitModels.load()
    if args.junctions:
        junctions(models)
    if args.pairs:
        pairs(models, args)
    if args.let_down:
        let_down(models, args)
    if args.stacks:
        stacks(models, args)
    if args.refusals:
        refusal_rates(models)
    if not (args.pairs or args.stacks or args.junctions or args.let_down or args.refusals):
        random_orders(models, args)


if __name__ == "__main__":
    main()
