"""A small outfit end to end on the committed models: the end-to-end issue's measures, the CLI, GLB."""

from __future__ import annotations

import io
import itertools
import json
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from benchmarks.orders import PENETRATION_LIMIT
from service.cli import main
from service.pipeline.collisions.settings import SETTINGS
from service.pipeline.outfit import OutfitModels, make_outfit
from service.pipeline.strain import RestShape, green_strain_norms
from training.drape.dataset import sample_betas

pytest.importorskip("onnxruntime")


@pytest.fixture(scope="module")
def models():
    return OutfitModels.load()


@pytest.fixture(scope="module")
def held_out_beta():
    return sample_betas(2, 3)[1]  # the outfit benchmark's body seed: used by no training


def _tangle(report: dict, when: str) -> tuple[int, float]:
    """(intersecting triangle pairs over all layer pairs, largest penetrating share of a garment)."""
    return sum(report[f"intersections_{when}"].values()), max(report[f"penetration_{when}"].values())


@pytest.mark.parametrize("untangler", ["reference", "neural"])
def test_tshirt_under_jacket_untangles(models, held_out_beta, untangler):
    r = make_outfit(models, ["tshirt", "jacket"], held_out_beta, untangler=untangler).report
    pairs_before, pen_before = _tangle(r, "before")
    _, pen_fit = _tangle(r, "fit")
    pairs_after, pen_after = _tangle(r, "after")
    # The explicit models alone tangle (crossing triangle pairs, jacket vertices inside the T-shirt)...
    assert pairs_before > 50 and pen_before > 0.001
    # ...the field fit moves most penetrating vertices out (it does not always lower the count of crossing
    # triangle pairs: the learned fields are mm off the meshes, and new small crossings appear where the
    # vertices it moves meet the ones it keeps; docs/collisions.md)...
    assert pen_fit < 0.3 * pen_before, (r["penetration_before"], r["penetration_fit"])
    # ...and the exact repair meets the end-to-end issue's targets: no crossing, <= 0.1 % penetrating.
    assert pairs_after == 0, r["intersections_after"]
    assert pen_after <= 0.001, r["penetration_after"]
    assert all(v["crossing_pairs"] == 0 for v in r["repair"].values())
    assert r["collision_free"] is True and r["crossing_pairs"] == 0
    assert r["fallback"] == []
    # Only the tangled regions move: the mean vertex moves by millimetres.
    assert max(r["mean_displacement_mm"].values()) < 5


def test_tshirt_tucked_into_pants_untangles(models, held_out_beta):
    # Paper Figure 3's tucked order on the short, heavy held-out body: the T-shirt's hem hangs 2-4 cm
    # outside the pants before; the squeeze presses it in under them and the repair leaves no crossing.
    r = make_outfit(models, ["tshirt", "pants"], held_out_beta).report
    pairs_before, _ = _tangle(r, "before")
    pairs_after, pen_after = _tangle(r, "after")
    assert pairs_before > 50
    assert pairs_after == 0, r["intersections_after"]
    assert pen_after <= 0.001, r["penetration_after"]


def test_bad_garments_are_refused(models, held_out_beta):
    for ids, match in ((["tshirt", "tshirt"], "at most once"), (["cape"], "unknown"), ([], "between")):
        with pytest.raises(ValueError, match=match):
            make_outfit(models, ids, held_out_beta)


def test_cli_writes_a_glb_and_prints_the_report(tmp_path, capsys):
    out = tmp_path / "o.glb"
    code = main(["outfit", "--garments", "tank_top,tshirt", "--gender", "1", "--height-cm", "165",
                 "--weight-kg", "60", "-o", str(out)])  # fmt: skip
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["garments"] == ["tank_top", "tshirt"]
    scene = trimesh.load(io.BytesIO(out.read_bytes()), file_type="glb", process=False)
    assert sorted(scene.graph.nodes_geometry) == ["body", "tank_top", "tshirt"]
    assert all(np.isfinite(g.vertices).all() for g in scene.geometry.values())


def test_cli_names_the_bad_field(tmp_path, capsys):
    code = main(["outfit", "--garments", "tshirt", "--height-cm", "400", "-o", str(tmp_path / "x.glb")])
    assert code == 2
    assert "height_cm" in capsys.readouterr().err


def test_serving_path_imports_no_torch():
    import subprocess
    import sys

    modules = (
        "service.server.app, service.cli, service.pipeline.outfit, service.pipeline.fields, "
        "service.pipeline.fit, service.pipeline.gltf"
    )
    code = f"import sys, {modules}; sys.exit('torch' in sys.modules or 'training' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_a_field_answering_nan_gives_the_explicit_mesh_and_a_flag(models, held_out_beta, monkeypatch):
    from service.pipeline.fields import FieldValues

    real = models.fields.__class__.__call__

    def nan_for_jacket(self, field_id, x, beta, gradient=False):
        out = real(self, field_id, x, beta, gradient)
        if field_id != "jacket":
            return out
        return FieldValues(*(None if a is None else np.full_like(a, np.nan) for a in out))

    # A fit never asks its own garment's network (its own layer comes from its mesh): the jacket's
    # NaN reaches the T-shirt's fit only.
    monkeypatch.setattr(models.fields.__class__, "__call__", nan_for_jacket)
    outfit = make_outfit(models, ["tshirt", "jacket"], held_out_beta, measure=False)
    assert outfit.report["fallback"] == ["tshirt"]
    assert all(np.all(np.isfinite(v)) for _, v, _ in outfit.garments)
    json.dumps(outfit.report, allow_nan=False)  # what an HTTP answer needs


def test_side_by_side_fits_equal_one_after_the_other(models, held_out_beta):
    # make_outfit fits the garments on two threads: each fit depends only on its own garment and the
    # fields, so the result must be the sequential fit's, bit for bit.
    from service.pipeline.fields import BODY
    from service.pipeline.fit import fit_garment
    from service.pipeline.outfit import DEFAULT_FIT

    ids = ["pants", "tshirt", "jacket"]
    out = make_outfit(models, ids, held_out_beta, measure=False, repair=False)
    layer_ids = [BODY, *ids]

    def layer_fields(k, x, gradient):
        if k == 0:
            return models.clearance.body_field(x, gradient)
        return models.fields(layer_ids[k], x, held_out_beta, gradient)

    op = models.untangler("neural")
    explicit = [models.explicit[gid].canonical(held_out_beta) for gid in ids]
    bounds = models.pairs.far_bounds(ids, explicit, explicit)
    for i, (gid, world, faces) in enumerate(out.garments):
        fitted = fit_garment(explicit[i], faces, i + 1, len(layer_ids), layer_fields, op, DEFAULT_FIT,
                             bounds[i]).vertices  # fmt: skip
        assert np.array_equal(world, models.space.to_body(fitted, out.body_vertices)), gid


@pytest.mark.parametrize("ids", [["tank_top", "tshirt", "long_sleeve", "jacket"],
                                 ["jacket", "shorts", "long_sleeve"]])  # fmt: skip
def test_asking_ahead_gives_the_meshes_of_asking_when_needed(models, held_out_beta, monkeypatch, ids):
    # The squeeze and the repair ask some closest points ahead on a background thread: the answers
    # are functions of the points alone, so the outfit must be the one of asking each when needed.
    import service.pipeline.collisions.passes as passes

    asked = []
    ahead = passes.ask_ahead
    monkeypatch.setattr(passes, "ask_ahead", lambda *a: asked.append(1) or ahead(*a))
    with_ahead = make_outfit(models, ids, held_out_beta, measure=False)
    assert asked  # two or more layers apart: some were asked ahead
    monkeypatch.setattr(passes, "ASK_AHEAD", False)
    asked.clear()
    when_needed = make_outfit(models, ids, held_out_beta, measure=False)
    assert not asked
    for (gid, v, _), (_, w, _) in zip(with_ahead.garments, when_needed.garments, strict=True):
        assert np.array_equal(v, w), gid
    assert with_ahead.report["repair"] == when_needed.report["repair"]


def test_the_far_bounds_are_below_the_distances_on_every_body(models, held_out_beta):
    """``far_bounds`` skips a layer's field where its surface is provably far: each bound is at most the
    exact canonical distance from the vertex to the other garment's explicit mesh on held-out bodies
    at the corners of the box, and they skip something (pants against a jacket's sleeves)."""
    from benchmarks.imported import corners
    from service.geometry.closest import ClosestPoint
    from service.pipeline.fit import FAR_FIELD

    ids = ["pants", "tshirt", "jacket", "skirt"]
    for beta in [held_out_beta, *corners()]:
        explicit = [models.clearance.clear_of_body(models.explicit[g].canonical(beta)) for g in ids]
        bounds = models.pairs.far_bounds(ids, explicit, explicit)
        for i, x in enumerate(explicit):
            for k, g in enumerate(ids):
                if k == i:
                    assert not bounds[i][:, k + 1].any()
                    continue
                exact = ClosestPoint.build(explicit[k], models.catalog[g].faces).query(x).distance
                assert np.all(bounds[i][:, k + 1] <= exact), (ids[i], g)
        assert (bounds[2][:, 1] >= FAR_FIELD).mean() > 0.3  # the jacket's sleeves and collar, from the pants


# (ids, which of the outfit benchmark's 8 bodies, seed 3): each pair on a body where it crosses without
# the let-down. With the garment models retrained on the population and the box's corners, the shorts
# over the pants crossed without it on bodies 3 and 7 (13 and 22 pairs), no longer on body 1.
@pytest.mark.parametrize(("ids", "body"), [(["long_sleeve", "tank_top"], 1), (["shorts", "pants"], 7)])
def test_an_outer_garment_comes_down_around_a_lower_junction(models, monkeypatch, ids, body):
    # The long sleeve's armhole hangs below the tank top's, the shorts' crotch below the pants': the
    # outer garment is let down there (collisions.junctions) and the pair comes out clean; without
    # that, the same pair on the same body crosses (164 and 40 pairs when this was written) where the
    # repair only pushes (no ``lifts``, which since clear the long sleeve's alone).
    held_out_beta = sample_betas(8, 3)[body]
    assert models.pairs.lowering(*ids) is not None
    r = make_outfit(models, ids, held_out_beta, measure=True).report
    assert r["collision_free"] and _tangle(r, "after") == (0, 0.0)
    monkeypatch.setattr(models.pairs, "lowering", lambda *asked: None)
    pushes_only = replace(SETTINGS, lift=0.0)
    r = make_outfit(models, ids, held_out_beta, measure=False, collisions=pushes_only).report
    assert r["crossing_pairs"] > 0


def test_the_outer_of_two_tops_let_down_around_a_jacket_comes_down_below_the_inner_one(models, monkeypatch):
    # The T-shirt and the tank top both come down around the jacket's low armhole; the tank top, over
    # the T-shirt, takes its own room below the T-shirt's (one EXTRA more), not the same saddle. Each
    # drop is read on the body (the garments' explicit meshes there, junctions.body_run).
    asked = []
    lowering = models.pairs.lowering
    monkeypatch.setattr(models.pairs, "lowering", lambda *a: asked.append(a) or lowering(*a))
    beta = sample_betas(2, 3)[1]
    make_outfit(models, ["jacket", "tshirt", "tank_top"], beta, measure=False, untangle_layers=False)
    down = [(a[:3], lowering(*a)) for a in asked]
    assert [key for key, d in down if d is not None] == [("jacket", "tshirt", 0), ("jacket", "tank_top", 1)]
    (on,) = [a[3] for a in asked if a[:2] == ("jacket", "tank_top")]
    alone, lower = lowering("jacket", "tank_top", 0, on), lowering("jacket", "tank_top", 1, on)
    assert lower[:, 2].min() == pytest.approx(alone[:, 2].min() - SETTINGS.extra)
    asked.clear()
    make_outfit(models, ["jacket", "tshirt"], beta, measure=False, untangle_layers=False)
    assert [a[:3] for a in asked] == [("jacket", "tshirt", 0)]  # a pair: nothing between


def test_a_long_top_tucked_into_pants_is_gathered_above_their_crotch(models, held_out_beta, monkeypatch):
    # The jacket's hem hangs below the pants' crotch: it is gathered up above it
    # (collisions.junctions.raising), the pants keep their crotch, and the pair comes out clean
    # by issue 21's measure (no crossing pair, at most 0.1 % of a garment's vertices inside: 0.00 % when
    # this was written). Without the gathering it was not (15 crossing pairs) until the repair turned
    # over the faces of a fold that face the body (issue 21's seventh round): now it is clean either way
    # on this body, so the test checks that the gathering is what the jacket gets, not that it is needed.
    ids = ["jacket", "pants"]
    assert models.pairs.raising(*ids) is not None and models.pairs.lowering(*ids) is None
    outfit = make_outfit(models, ids, held_out_beta, measure=True)
    pairs, inside = _tangle(outfit.report, "after")
    assert pairs == 0 and inside <= PENETRATION_LIMIT / 100
    monkeypatch.setattr(models.pairs, "raising", lambda inner, outer: None)
    plain = make_outfit(models, ids, held_out_beta, measure=False)
    jacket, jacket_plain = outfit.garments[0][1], plain.garments[0][1]
    assert np.abs(jacket - jacket_plain).max() > 0.01  # the gathering moved the hem by centimetres


def test_garments_worn_the_usual_way_are_not_let_down(models):
    # Every ordered pair of the latency benchmark's outfits (tops by rank, a bottom under them), a top
    # tucked into pants and pants under a skirt: only orders against the grain get a lowering (or, for
    # a top tucked in whose hem hangs below the crotch, a gathering).
    from benchmarks.latency import OUTFITS

    usual = {pair for ids in OUTFITS for pair in itertools.combinations(ids, 2)}
    for inner, outer in sorted(usual | {("tshirt", "pants"), ("pants", "skirt")}):
        assert models.pairs.lowering(inner, outer) is None, (inner, outer)
        assert models.pairs.raising(inner, outer) is None, (inner, outer)


def test_the_report_counts_every_crossing_left(models):
    # The report's crossing pairs are the repair's, which tests only the vertices the fields put near
    # each inner layer. The squeeze walks a loose garment's vertices centimetres towards the body (the
    # jacket under the tank top on the shortest, lightest man): those are tested too, so the report
    # never says fewer than the exact all-pairs count on the returned meshes, and collision-free means
    # none. It said 0 against 25 body/jacket pairs when the repair read the body's distance where
    # the fit had left the walked vertices.
    from benchmarks.imported import corners

    r = make_outfit(models, ["jacket", "tank_top"], corners()[0], measure=True).report
    exact = sum(r["intersections_after"].values())
    assert r["crossing_pairs"] >= exact, r["intersections_after"]
    assert not r["collision_free"] or exact == 0


def test_a_garment_let_down_far_is_cleared_of_the_body_on_the_way(models, held_out_beta):
    # The T-shirt over a long sleeve over the jacket comes down ~26 cm under the arms. Cleared of the
    # body once at the end, its sleeves' undersides had gone through the arm, came out at either side
    # and tore (strain max 5.5 -> 67 on this body when this was written, 31-84 on ten held-out bodies);
    # moved in 1 cm steps, each cleared, the sleeve rests on the arm and keeps the lowering's own strain.
    ids = ["jacket", "long_sleeve", "tshirt"]
    clear = models.clearance.clear_of_body
    jacket, _, tshirt = [clear(models.explicit[g].canonical(held_out_beta)) for g in ids]
    shift = models.pairs.lowering("jacket", "tshirt", 1, (jacket, tshirt))
    assert np.abs(shift).max() > 0.2
    stepped = models.clearance.shifted_clear_of_body(tshirt, shift)
    rest = RestShape.build(tshirt, models.catalog["tshirt"].faces)
    lowered, once, steps = (green_strain_norms(x, rest).max() for x in (
        tshirt + shift, models.clearance.clear_of_body(tshirt + shift), stepped))  # fmt: skip
    assert once > 4 * lowered  # what the steps are for: cleared at once, this body's T-shirt tears
    assert steps <= 1.2 * lowered, (lowered, steps)
    # Out, as test_explicit's.
    assert models.clearance.exact_body_distance(stepped)[0].min() > 0.5 * SETTINGS.clearance
    still = np.all(shift == 0, axis=1)
    np.testing.assert_array_equal(stepped[still], tshirt[still])
    small = np.where(still[:, None], 0.0, np.array([0.0, 0.0, -0.5 * SETTINGS.shift_step]))  # one step
    once = models.clearance.clear_of_body(tshirt + small)
    np.testing.assert_array_equal(models.clearance.shifted_clear_of_body(tshirt, small), once)


@pytest.mark.parametrize("left, chosen", [((5, 3, 4), 1), ((3, 5, 4), 0), ((0, 5, 5), 0), ((5, 4, 0), 2)])
def test_a_let_down_outfit_left_crossing_is_made_again_with_the_next_room(models, monkeypatch, left, chosen):
    # The jacket under the T-shirt is let down; where the repair leaves crossings (stubbed: ``left`` per
    # attempt), the outfit is made again with SETTINGS.rooms' next room, and the attempt with the fewest
    # faults is what comes back, meshes and report; a clean first attempt is the only one.
    from service.pipeline import outfit
    from service.pipeline.collisions.passes import Resolved
    from service.pipeline.collisions.repair import RepairResult

    rooms, calls, limits = [], [], []
    lowering = models.pairs.lowering
    monkeypatch.setattr(models.pairs, "lowering", lambda *a: rooms.append(a[4]) or lowering(*a))

    def resolve(stack, body, explicit, fitted, world, lowered, settings, pass_limit, deadline):
        limits.append(pass_limit)
        n = left[len(calls)]
        calls.append(([x.copy() for x in explicit], world))
        out = [x + len(calls) for x in world]  # tells the attempts apart
        crossing = [0] * (len(out) - 1) + [n]  # all on the outermost garment
        return Resolved(out, [RepairResult(x, np.zeros(len(x), bool), 1, c, 0)
                              for x, c in zip(out, crossing, strict=True)], passes=2)

    monkeypatch.setattr(outfit, "resolve", resolve)
    beta = sample_betas(2, 3)[1]
    ids = ["jacket", "tshirt"]
    r = make_outfit(models, ids, beta, measure=False)
    assert len(SETTINGS.rooms) == len(left)
    attempts = next((k + 1 for k, n in enumerate(left) if n == 0), len(left))  # up to the first clean one
    assert r.report["attempts"] == len(calls) == attempts
    # The attempts share the pass budget: each is offered what the ones before left.
    assert limits == [SETTINGS.pass_budget - 2 * k for k in range(attempts)]
    assert r.report["passes"] == 2 * attempts
    assert sorted(set(rooms)) == sorted(SETTINGS.rooms[:attempts])
    assert r.report["crossing_pairs"] == left[chosen]
    for (_, x, _), fitted in zip(r.garments, calls[chosen][1], strict=True):
        np.testing.assert_array_equal(x, fitted + (chosen + 1))
    if attempts > 1:  # the next room let the T-shirt down further
        assert (calls[0][0][1] - calls[1][0][1])[:, 2].max() > 0.01
    calls.clear()
    # Let down nowhere: made once, crossings or not.
    left = (5, 3, 4)
    assert make_outfit(models, ["tank_top", "tshirt"], beta, measure=False).report["attempts"] == 1
    assert len(calls) == 1


def test_the_pass_budget_bounds_the_passes_of_every_attempt(models):
    """The slowest stack measured (four garments, a 146 cm 42 kg woman) ran 21 passes in 3 attempts;
    with a budget the attempts share it, each runs at least one pass, and the report counts them."""
    from service.pipeline.body import shape_from_measurements

    beta = shape_from_measurements(models.body, 1.0, 146.0, 42.0)
    ids = ["pants", "jacket", "tshirt", "long_sleeve"]
    for budget in (1, 3):
        report = make_outfit(models, ids, beta, measure=False,
                             collisions=replace(SETTINGS, pass_budget=budget)).report  # fmt: skip
        assert report["passes"] <= max(budget, report["attempts"])
        assert report["attempts"] <= budget
        assert report["crossing_pairs"] >= 0


def test_no_pass_starts_after_the_requests_deadline(models, monkeypatch):
    """A request whose clock has run past ``pass_seconds`` (its body's build, say) still gets its first
    squeeze-and-repair pass, and no other: no further pass, no other room. The stub counts them."""
    import time

    from service.pipeline import outfit
    from service.pipeline.collisions import passes

    seen = []
    real = passes.resolve

    def resolve(*args):
        out = real(*args)
        seen.append((args[-1], out.passes))
        return out

    monkeypatch.setattr(outfit, "resolve", resolve)
    ids = ["pants", "jacket", "tshirt", "long_sleeve"]  # against the grain: let down, many passes
    beta = sample_betas(2, 3)[1]
    late = time.perf_counter() - SETTINGS.pass_seconds - 1.0
    r = make_outfit(models, ids, beta, measure=False, started=late)
    assert len(seen) == 1 and seen[0][1] == 1 and r.report["passes"] == 1
    seen.clear()
    r = make_outfit(models, ids, beta, measure=False)  # on time: as many as it needs
    assert seen[0][0] > time.perf_counter() - SETTINGS.pass_seconds
    assert r.report["passes"] == sum(p for _, p in seen) > 1  # the deadline is what stopped it above
