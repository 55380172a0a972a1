"""Collision handling: from the explicit garment meshes of a request to world meshes that cross nothing.

Contract (``docs/collisions.md`` has it with pictures):

- **In**: the garments inner to outer (catalog ``Garment``s, an order ``layering`` accepts), their
  explicit canonical meshes on the request's body, the body's world mesh, and the models' fields.
- **Out**: per garment a world mesh ``(V_i, 3)`` with the garment's own faces, and its
  ``repair.RepairResult``: the crossing triangle pairs and the vertices inside an inner layer it left.
- **Guarantee**: none beyond "the fewest faults found". Each garment's repair keeps its round with the
  fewest faults (crossing pairs plus vertices inside); the passes and the let-down attempts keep the
  outfit with the fewest crossing pairs, then vertices inside, and return it; the report's
  ``collision_free`` is true only when that outfit has none. What is tried, at most (the retry budget, in
  ``settings.CollisionSettings``): ``rooms`` (3) let-down rooms x ``ways`` (2) x ``passes`` (6) passes
  x ``repair_rounds`` (24) rounds per garment, at most ``pass_budget`` (12) passes over all the
  attempts of a request, and none but the first starting ``pass_seconds`` (8 s) after the request began
  (the bound on its time: within 10 s on 2 cores, ``benchmarks.worst_case``); an outfit that comes out
  clean stops at once, and the usual orders (nothing let down) are made with one room and one pass.
- **Refused before any of it**: orders cloth cannot take (``layering.LayeringRule.refusals``: a skirt
  over pants' legs, a garment too tight for what is under it), answered 422 by the service.

The stages, in order, each for a failure the one before leaves:

1. ``service.pipeline.fit`` (paper 4.2): each garment fitted to its untangled field; the learned fields
   are ~1-2 mm off the meshes, so the fitted meshes still cross by that much.
2. ``junctions`` (let-down and gathering, before the fit): an inner garment's armhole or crotch that
   hangs below the outer one's leaves cloth between two body parts that no push can take in; the outer
   garment comes down around it, or a top tucked into a bottom is gathered up above its crotch.
   ``attempts`` in ``service.pipeline.outfit`` retries with more room below the junction.
3. ``squeeze``: the repair only moves layers outwards; an inner garment hanging loose beyond a tight
   outer one is pressed under it instead, as cloth is.
4. ``repair``: exact crossing tests, pushes along the inner layer's normal, lifts of crossing corners;
   ``passes`` repeats squeeze and repair where faults are left.

Supporting modules: ``settings`` (every tuned number), ``stack`` (what the stages know of an outfit),
``traits`` (garment behaviour read off its geometry), ``caches`` (per garment and per pair, made once),
``clearance`` (canonical vertices kept out of the mean body).
"""
