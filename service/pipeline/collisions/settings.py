"""Every tuned number of collision handling, in one place: ``CollisionSettings``.

Each field says its unit, what it trades and how it was chosen: the benchmark (``benchmarks.orders``,
``benchmarks.outfits``, ``benchmarks.latency``) and the effect measured when it was set. The history
of the choices is in ``docs/decisions/``; the stages that read them are in ``docs/collisions.md``.
Numbers that are not decisions (the quality measures' band, ``quality.PENETRATION_BAND``; rounding
slacks of floating point) stay where they are defined.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from service.pipeline.quality import PENETRATION_BAND


@dataclass(frozen=True)
class Way:
    """How the passes after the first repeat the squeeze and the repair where faults are left
    (``collisions.passes``)."""

    from_repaired: bool
    """The next squeeze starts from this pass's repaired meshes (else from the fitted ones again, with
    only the deepened margins carried over)."""
    past_rim: bool
    """A vertex whose closest point on the outer layer is on its rim is past its opening, not under it
    (the repair's rule), unless the segment test finds it under: the fields, read where the fit left the
    vertex, can still call it covered (a jacket's cloth 5 cm past a T-shirt's armhole was pulled 10 cm
    by the first way's passes, and made things worse pass after pass: 58 -> 655 -> 2,437 crossing
    pairs; this way made jacket < shorts < long sleeve and long sleeve < jacket < T-shirt clean)."""


@dataclass(frozen=True)
class CollisionSettings:
    """The tuned numbers of ``service.pipeline.collisions``, one field each (lengths in metres)."""

    # --- shared by every stage -----------------------------------------------------------------------
    margin: float = 0.002
    """m: the clearance every garment keeps from the layers inside it. The repair pushes a vertex to it,
    the squeeze pulls a vertex this far inside the outer layer, each squeezed garment keeps one margin
    per garment under it above the body, and the layering rule counts it per layer in a girth. Larger
    margins show as a visible gap between tight layers; 2 mm is under the untangling gap (4 mm)."""
    reach_pad: float = 0.01
    """m added to the measure's band (``PENETRATION_BAND``) within which the fields' distance makes a
    vertex a candidate for an inner layer's exact tests (``reach``): the fields are ~1-2 mm off near
    their surface and up to ~1 cm a few centimetres away (pants 3.5 cm inside a T-shirt read 4.5 cm)."""
    short_of_margin: float = 0.9
    """The fraction of its target distance at which a pushed or pulled vertex counts as there: one moved
    exactly to the margin lands a rounding error short of it, and without this slack the loops push it
    again and again by nothing."""

    # --- canonical space: the explicit meshes before the fit (``collisions.clearance``) --------------
    clearance: float = 5e-4
    """m: explicit vertices closer to the mean body than this move out to it: the drape dataset's own
    rule (``training.drape.dataset.CLEARANCE``, which the service cannot import; a test holds them
    equal)."""
    clearance_candidates: float = 0.003
    """m over ``clearance`` within which the body's distance grid (up to ~1.6 mm off at the face and the
    feet) sends a vertex to the exact distance query."""
    clearance_steps: int = 3
    """Exact moves out along the distance gradient; one lands within the surface's curvature error."""
    shift_step: float = 0.01
    """m: the longest move of a let-down or gathered garment's vertex between two clearings of the body:
    well under an arm's or a wrist's radius (2.5 cm and more). Moved in one step a sleeve's underside
    went through the arm and tore into spikes (strain max 5.5 -> 67 on the test's body, 31-84 on ten
    held-out bodies; stepped 5.4-7.2)."""
    gap_step: float = 0.004
    """m: the kept distance between two garments' drapes (``PairCaches.gap``) is rounded down to this,
    a byte a vertex up to 1.02 m: a lower bound stays one, 4 mm looser at most against the fit's 8 cm
    far-field distance."""

    # --- layering rule (``collisions.layering``) -----------------------------------------------------
    slice_step: float = 0.01
    """m between the horizontal slices the layering rule and the junctions read."""
    join_tolerance: dict[str, float] = field(
        default_factory=lambda: {"leg": 0.05, "arm": 0.10, "torso": 0.10}
    )
    """m of height over which the parts an inner loop joins may be held apart by the outer garment, by
    the lowest-ranked part involved. Bottoms hang from a belted waistband, so an outer crotch cannot
    ride up over a skirt's cloth between the legs; a fitted top's armpit lifts a looser top's lower
    armhole (a jacket's sits 6-8 cm below a T-shirt's), as a sweater's lifts a shirt's."""
    stretch_limit: float = 0.10
    """Strain a garment's girth can take when it holds the layers under it (woven cotton; knits take
    more): garments draped on the body always pass, compression wear over another garment does not."""
    min_part: float = 0.03
    """m: body loops shorter than this (finger tips) are no part of anything a garment wraps."""
    chest: float = 2 / 3
    """How far from the crotch to the armpits (0 to 1) a garment's torso loops must reach to cover the
    chest. On the mean body that is 40 cm above the crotch's level: the bundled bottoms' waistbands are at
    27 cm, the tops' highest torso loops at 56-71 cm (the tank top's armholes lowest), a dress cut from
    just under the arms at ~50 cm; a high-waisted skirt to 35 cm still counts as worn from the waist."""

    # --- let-down and gathering at junctions (``collisions.junctions``) ------------------------------
    rooms: tuple[float, ...] = (0.04, 0.06, 0.10)
    """m below the inner garment's junction to which the outer one's comes down, tried in turn while the
    one before left the outfit crossing (``collisions.attempts``); the first is also the gathering's room
    above a crotch. 2 cm left the jacket under the T-shirt crossing on one of ``benchmarks.orders
    --pairs``' three bodies. Which room leaves a stack clean is a matter of millimetres upstream
    (``--stacks 100`` seed 7 left 7 stacks crossing with 4 cm, 3 with 6 cm, 2 in both; of the three left
    after both, 10 cm made two clean, 8 cm one). More room is a lower armhole, so it is tried last."""
    bump_radius: float = 1.5
    """The let-down bump's radius per metre of drop: the cloth around the saddle comes down with it, so
    the drop spreads over the sleeve and the side instead of pulling one vertex."""
    min_bump_radius: float = 0.06
    """m: the smallest radius of the let-down bump."""
    gate: float = 0.10
    """m above the saddle over which the drop fades to nothing: the top of the sleeve and the shoulder
    seam stay on the body. 5 cm left the jacket under the tank top at 24-133 crossing pairs, 10 cm at
    0-36 (before the repair's lifts)."""
    gather_pad: float = 0.02
    """m beyond a tucked top's loop around both legs to which it is gathered up in full, and then over
    which the gathering fades: the loop's cloth moves up as one, its sleeves stay."""
    crotch_vertices: int = 8
    """Vertices of the outer garment nearest its crotch's saddle; the highest of them is the crotch."""
    run_band: float = 0.10
    """m above and below the drapes' junction run within which a body's own run is looked for: on the
    catalog's bodies it is within 5 cm of the mean body's (jacket under tank top: 16-21 cm against 18)."""

    # --- squeeze (``collisions.squeeze``) ------------------------------------------------------------
    squeeze_ring: int = 3
    """Rings of neighbours a pull spreads over, so that the garment folds in along the outer layer's
    edge instead of tearing there."""
    squeeze_smoothing: int = 12
    """Jacobi iterations of the diffusion of the pulls per round."""
    squeeze_relax: int = 4
    """Jacobi iterations over the whole moved patch after the diffusion: neighbours pulled towards
    different sides of an armpit (torso and arm) otherwise part ways and crumple the cloth."""
    squeeze_rounds: int = 8
    """Rounds when a layer asks the segment test (a garment worn against the usual order)."""
    squeeze_usual_rounds: int = 3
    """Rounds when no layer asks the segment test: every garment worn the usual way is done within them
    (``benchmarks.outfits`` all clean), and more rounds took 1-8 % of a request (``benchmarks.latency
    --compare``, body + 1..4)."""
    squeeze_stall_after: int = 2
    """Rounds after which a round that pulls no fewer vertices than the one before is the last but one."""
    squeeze_steps: int = 4
    """Steps of a vertex's walk towards the body in a round; one still outside waits for the next."""
    squeeze_backoffs: int = 3
    """Times a walk to an anchor that would end under the floor backs off halfway before it waits."""

    # --- repair (``collisions.repair``) --------------------------------------------------------------
    repair_ring: int = 2
    """Rings of neighbours a push spreads over: a push lifts a patch instead of a spike."""
    repair_smoothing: int = 8
    """Jacobi iterations of the displacement diffusion per round."""
    repair_rounds: int = 24
    """Rounds of pushes and exact crossing tests per layer and pass at most."""
    repair_patience: int = 6
    """Rounds without a new fewest count of faults before the loop stops and returns the round with the
    fewest (tight stacks of four tops oscillate)."""
    growth: float = 1.5
    """Factor on the margin of the vertices of triangles still crossing after a round."""
    max_margin: float = 0.008
    """m: the margin never grows beyond this (larger pushes around fingers made new crossings)."""
    lift: float = 0.012
    """m: the largest move of a corner of a crossing triangle lifted clear of the inner triangles it
    crosses in a round; 0: none, the corners are only kicked along the layer's normal. A tank top's 4 cm
    triangles over a jacket's armpit kept 13 pairs after 15 rounds of kicks, 0 lifted; seed 10's
    T-shirt < jacket < pants < long sleeve went 9 -> 0 pairs."""

    # --- passes (``collisions.passes``) --------------------------------------------------------------
    ways: tuple[Way, ...] = (Way(from_repaired=True, past_rim=False), Way(from_repaired=False, past_rim=True))
    """Ways of repeating the squeeze and the repair, a pass of each in turn, until one comes out clean.
    The first squeezes the last pass's repaired meshes (four tops on a heavy body: 123 crossing pairs in
    the armpits after the first pass, 0 after the second); the second starts from the fitted meshes each
    time, pressed deeper where its own pass left faults, and does not pull cloth past a rim."""
    passes: int = 6
    """Passes of each way at most. Six, not three: a tank top under a jacket tucked into pants kept 13
    pants vertices inside the jacket after three (0.17 %), 0.04 % after six; ``benchmarks.orders
    --pairs`` 114 -> 117 of 120 clean, ``--stacks 100`` 64 -> 65 of 85."""
    pass_patience: int = 2
    """Passes of a way without fewer faults than its best before it stops."""
    pass_budget: int = 12
    """Passes a request may run in all, over its rooms and ways: the bound on its worst case. Before it,
    the slowest stack measured (pants < jacket < tshirt < long_sleeve on a 146 cm, 42 kg woman) ran 21
    passes in 3 rooms, 23-31 s on 2 cores, past the service's 30 s deadline; a pass of four garments
    costs ~0.5-0.7 s on 2 quiet cores, so 12 keep those outfits under 10 s (``python -m
    benchmarks.worst_case``, docs/collisions.md)."""
    pass_seconds: float = 8.0
    """s after a request began (its body's build included) past which no squeeze-and-repair pass starts:
    with ``pass_budget``, the bound on its time. The passes cost twice as much on the heaviest bodies:
    with the pass budget alone, 4-garment stacks worn against the grain on a BMI 60 woman took 19-25 s
    on 2 quiet cores (her body's first build ~5 s), a BMI 59 man's 11-15 s; a last pass there takes up
    to ~2 s, so passes stop starting at 8 s for 10 s (``python -m benchmarks.worst_case``)."""
    deepen: float = 0.002
    """m: how much deeper, each pass, the squeeze presses an inner garment under an outer one where the
    repair left them crossing; lifting the outer one is all the repair can do, and over the gathered
    cloth of a jacket tucked into shorts it traded 9 vertices inside for ~200 crossing pairs and back."""
    deepest: float = 0.008
    """m: the deepest margin ``deepen`` reaches."""
    deepen_ring: int = 2
    """Rings around a fault's vertices that are pressed deeper with them."""
    body_query_pad: float = 0.01
    """m over the largest margin within which the body's canonical distance sends a garment vertex to
    the exact body query. World and canonical distances to the body differ by < 6 mm at 99 % of
    garment vertices within 6 cm of 6 held-out bodies (one jacket vertex of 60,000: 38 mm, in an
    armpit); a vertex missed that way is still asked once a triangle of it is found crossing."""
    body_map_stretch: float = 1.2
    """Factor on a move in canonical space that bounds the same move on the body (the body map's
    largest stretch), when an outer layer widens where it looks for an inner one that moved."""

    @property
    def reach(self) -> float:
        """m: vertices whose field distance to an inner layer is below this are checked against its mesh:
        a vertex counts as inside an inner garment down to ``PENETRATION_BAND``, plus ``reach_pad``."""
        return PENETRATION_BAND + self.reach_pad

    @property
    def extra(self) -> float:
        """m: the first room below a junction (``rooms[0]``), the one every pair is made with first."""
        return self.rooms[0]


SETTINGS = CollisionSettings()
"""The settings the service runs with."""
