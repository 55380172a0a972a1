"""Build the garment catalog around the mean body: ``python -m training.garments``.

Writes ``models/garments/<id>.npz`` and ``catalog.json`` (see ``service.pipeline.catalog``). The body's
signed-distance grid is cached under ``data/cache`` (delete it to rebuild from scratch).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from service.geometry.mesh import boundary_loops, vertex_normals
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.catalog import Garment, save_garment
from service.process.paths import REPO_ROOT, models_dir
from training.garments.appearance import FABRICS, dress, write_catalog
from training.garments.cut import clip_mesh, compact, component_near
from training.garments.sdf import SurfaceDistance, sample_grid
from training.garments.specs import CATALOG, Cut, GarmentSpec, NeckCut, SkirtSpec

VOXEL = 0.006
BAND = 0.08
TARGET_EDGE = 0.012  # m; the body's torso edges are ~2 cm
MIN_CLEARANCE = 0.004  # no garment vertex closer to the mean body than this


def joint_positions(body: BodyModel) -> dict[str, np.ndarray]:
    return {name: body.bone_heads[i] for i, name in enumerate(body.bone_names)}


def polyline_distance(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance ``(N,)`` from points ``(N, 3)`` to a polyline ``(K, 3)`` whose last segment is
    extended 30 cm (hands and feet lie beyond the last joint)."""
    poly = np.concatenate([polyline, polyline[-1:] + 0.3 * _unit(polyline[-1] - polyline[-2])])
    best = np.full(len(points), np.inf)
    for a, b in zip(poly[:-1], poly[1:], strict=True):
        ab = b - a
        t = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points - (a + t[:, None] * ab), axis=1))
    return best


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def cut_values(cut: Cut | NeckCut, side: str, joints: dict, points: np.ndarray) -> np.ndarray:
    """Removal function ``(N,)`` of one cut: > 0 where the surface is removed."""
    if isinstance(cut, NeckCut):
        c = joints[cut.joint] + np.array([0.0, cut.forward, 0.0])
        r = np.hypot((points[:, 0] - c[0]) / cut.radius_x, (points[:, 1] - c[1]) / cut.radius_y)
        # plane through the neck joint, front_drop lower at the front (y = c_y - radius_y)
        slope = (cut.front_drop - cut.back_drop) / (2 * cut.radius_y)
        z_plane = c[2] - 0.5 * (cut.front_drop + cut.back_drop) + slope * (points[:, 1] - c[1])
        neckline = np.minimum((1.0 - r) * cut.radius_x, points[:, 2] - z_plane)
        # and the head, wherever it is: nothing of a top rises this far above the neck joint
        return np.maximum(neckline, points[:, 2] - (joints[cut.joint][2] + 0.05))
    origin = joints[cut.origin.format(s=side)]
    if cut.toward is not None:
        toward = joints[cut.toward.format(s=side)]
        origin = origin + cut.along * (toward - origin)
    mirror = np.array([-1.0, 1.0, 1.0]) if side == "R" else np.ones(3)
    origin = origin + mirror * np.array(cut.offset)
    normal = _unit(mirror * np.array(cut.normal)) if cut.normal is not None else _unit(toward - origin)
    value = (points - origin) @ normal
    if cut.limb:
        limb = np.array([joints[j.format(s=side)] for j in cut.limb])
        value = np.minimum(value, cut.radius - polyline_distance(points, limb))
    return value


def opening_name(cut: Cut | NeckCut, side: str) -> str:
    return cut.opening.format(s=side.lower())


def remesh(vertices: np.ndarray, faces: np.ndarray, target: float, iterations: int = 12):
    """Isotropic remeshing to edge length ``target`` (pymeshlab), boundaries kept in place."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32)))
    ms.meshing_isotropic_explicit_remeshing(
        targetlen=pymeshlab.PureValue(target), iterations=iterations, featuredeg=60.0,
        maxsurfdist=pymeshlab.PureValue(target * 0.1),
    )
    # The remesher keeps the cut's boundary vertices, which can leave a few sub-mm boundary edges
    # (slivers that would stiffen a cloth simulation): merge vertices closer than a third of target.
    ms.meshing_merge_close_vertices(threshold=pymeshlab.PureValue(target / 3))
    ms.meshing_remove_duplicate_faces()
    m = ms.current_mesh()
    return compact(m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64))


def taubin_smooth(vertices: np.ndarray, faces: np.ndarray, iterations: int, fixed: np.ndarray):
    """Taubin (lambda/mu) smoothing that does not shrink; ``fixed`` (V,) bool vertices stay."""
    from scipy.sparse import coo_matrix, diags

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    adj = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(vertices),) * 2).tocsr()
    adj.data[:] = 1.0
    lap = diags(1.0 / np.asarray(adj.sum(axis=1)).ravel()) @ adj
    v = vertices.copy()
    for _ in range(iterations):
        for step in (0.5, -0.53):
            d = lap @ v - v
            d[fixed] = 0.0
            v = v + step * d
    return v


def offset_surface(grid, ease: float, distance: SurfaceDistance):
    """Marching-cubes surface of {signed distance = ease}, normals pointing away from the body.

    Components that are not really at distance ``ease`` (artefacts where the grid's band ends)
    are dropped.
    """
    from skimage.measure import marching_cubes

    from service.geometry.mesh import connected_components

    values, origin, voxel = grid
    v, f, _, _ = marching_cubes(values, level=ease, spacing=(voxel,) * 3)
    v, f = v.astype(np.float64) + origin, f.astype(np.int64)
    labels = connected_components(f, len(v))
    error = np.abs(distance(v, max_distance=1.0) - ease)
    bad = np.bincount(labels, weights=(error > 0.25 * ease).astype(float)) > 0.05 * np.bincount(labels)
    return compact(v, f[~bad[labels[f[:, 0]]]])


def push_out(vertices: np.ndarray, distance: SurfaceDistance, clearance: float) -> np.ndarray:
    """Move vertices closer than ``clearance`` to the body out along the distance gradient."""
    v = vertices.copy()
    for _ in range(5):
        d = distance(v, max_distance=0.1)
        bad = d < clearance
        if not bad.any():
            break
        _, idx = distance.tree.query(v[bad])
        v[bad] += (clearance - d[bad] + 1e-4)[:, None] * distance.normals[idx]
    return v


def finish_surface(vertices, faces, smooth_iterations: int, distance: SurfaceDistance):
    """Remesh, smooth with the openings fixed, and keep clear of the body.

    Returns (vertices, faces, boundary loops)."""
    v, f = remesh(vertices, faces, TARGET_EDGE)
    loops = boundary_loops(f)
    on_boundary = np.zeros(len(v), bool)
    on_boundary[np.concatenate(loops)] = True
    v = taubin_smooth(v, f, smooth_iterations, on_boundary)
    return push_out(v, distance, MIN_CLEARANCE), f, loops


def build_cut_garment(spec: GarmentSpec, grid, joints, distance) -> Garment:
    v, f = offset_surface(grid, spec.ease, distance)
    cuts = [(c, s) for c in spec.cuts for s in c.sides]
    for cut, side in cuts:
        v, f = clip_mesh(v, f, cut_values(cut, side, joints, v))
    v, f = component_near(v, f, joints[spec.keep_near])
    v, f, loops = finish_surface(v, f, spec.smooth_iterations, distance)
    openings = {}
    for loop in loops:
        residual = [np.abs(cut_values(c, s, joints, v[loop])).mean() for c, s in cuts]
        c, s = cuts[int(np.argmin(residual))]
        name = opening_name(c, s)
        if name in openings:  # kept (and reported) so the picture shows what went wrong
            print(f"WARNING {spec.id}: extra boundary loop near opening {name!r} ({len(loop)} vertices)")
            name = f"{name}_extra{len(openings)}"
        openings[name] = loop
    return Garment(spec.id, spec.name, spec.category, spec.layer_rank, v, f, openings)


def build_skirt(spec: SkirtSpec, body_vertices: np.ndarray, keep: np.ndarray, distance) -> Garment:
    """Rings from waist to hem around the body's vertical axis, then remeshed."""
    pts = body_vertices[keep]
    center = np.array([0.0, pts[:, 1].mean()])
    n_theta = 180
    theta = np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)
    zs = np.arange(spec.waist_z, spec.hem_z - 1e-9, -0.008)
    rel = pts[:, :2] - center
    ang = np.mod(np.arctan2(rel[:, 1], rel[:, 0]), 2 * np.pi)
    rad = np.linalg.norm(rel, axis=1)
    bins = np.floor(ang / (2 * np.pi) * n_theta).astype(int) % n_theta
    radii = np.zeros((len(zs), n_theta))
    for i, z in enumerate(zs):
        sel = np.abs(pts[:, 2] - z) < 0.02
        r = np.zeros(n_theta)
        np.maximum.at(r, bins[sel], rad[sel])
        # angular bins with no body point take the largest neighbour; then smooth circularly
        for _ in range(6):
            r = np.maximum(r, 0.98 * np.maximum(np.roll(r, 1), np.roll(r, -1)))
        radii[i] = r + spec.ease
        if i:  # never narrower than the ring above; flare below the hips
            radii[i] = np.maximum(radii[i], radii[i - 1])
            if z < spec.hip_z:
                radii[i] += spec.flare * (zs[i - 1] - z)
    kernel = np.exp(-0.5 * (np.arange(-8, 9) / 3.0) ** 2)
    kernel /= kernel.sum()
    radii = np.stack([np.convolve(np.concatenate([r[-8:], r, r[:8]]), kernel, "valid") for r in radii])
    ring = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    v = np.concatenate([
        np.column_stack([center + radii[i][:, None] * ring, np.full(n_theta, z)]) for i, z in enumerate(zs)
    ])
    f = []
    for i in range(len(zs) - 1):
        a = i * n_theta + np.arange(n_theta)
        b = (i + 1) * n_theta + np.arange(n_theta)
        a1, b1 = np.roll(a, -1), np.roll(b, -1)
        f += [np.stack([a, b, b1], 1), np.stack([a, b1, a1], 1)]
    v, f, loops = finish_surface(v, np.concatenate(f), spec.smooth_iterations, distance)
    heights = [v[loop, 2].mean() for loop in loops]
    openings = {"waist": loops[int(np.argmax(heights))], "hem": loops[int(np.argmin(heights))]}
    return Garment(spec.id, spec.name, spec.category, spec.layer_rank, v, f, openings)


def orient_outward(garment: Garment, distance: SurfaceDistance) -> Garment:
    """Flip the faces if most vertex normals point toward the body."""
    n = vertex_normals(garment.vertices, garment.faces)
    _, idx = distance.tree.query(garment.vertices)
    if np.mean(np.einsum("nd,nd->n", n, distance.normals[idx]) > 0) < 0.5:
        return Garment(**{**garment.__dict__, "faces": garment.faces[:, ::-1].copy(),
                          "openings": {k: loop[::-1].copy() for k, loop in garment.openings.items()}})
    return garment


def body_grid(distance: SurfaceDistance, vertices: np.ndarray, cache: Path):
    if cache.exists():
        with np.load(cache) as d:
            return d["values"], d["origin"], float(d["voxel"])
    grid = sample_grid(distance, vertices.min(0) - BAND, vertices.max(0) + BAND, VOXEL, BAND)
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, values=grid[0], origin=grid[1], voxel=grid[2])
    return grid


def build_catalog(out_dir: Path | None = None, ids: list[str] | None = None) -> list[Garment]:
    out_dir = out_dir or models_dir() / "garments"
    body = BodyModel.load()
    vertices = body.vertices(np.array(DEFAULT_BETA))
    joints = joint_positions(body)
    distance = SurfaceDistance.build(vertices, body.faces)
    t0 = time.time()
    grid = body_grid(distance, vertices, REPO_ROOT / "data" / "cache" / "mean_body_sdf.npz")
    print(f"body distance grid {grid[0].shape} in {time.time() - t0:.1f} s")
    lower_body = np.isin(body.regions, [body.region_names.index(r) for r in body.region_names
                                        if r.startswith(("torso", "upperleg", "lowerleg"))])
    garments = []
    for spec in CATALOG:
        if ids and spec.id not in ids:
            continue
        t0 = time.time()
        if isinstance(spec, SkirtSpec):
            g = build_skirt(spec, vertices, lower_body, distance)
        else:
            g = build_cut_garment(spec, grid, joints, distance)
        g = dress(orient_outward(g, distance), body, FABRICS[g.id])
        save_garment(out_dir, g)
        garments.append(g)
        print(f"{g.id:12s} {len(g.vertices):6d} vertices {len(g.faces):6d} faces "
              f"openings {sorted(g.openings)} ({time.time() - t0:.1f} s)")
    if not ids:
        write_catalog(out_dir, garments)
    return garments
