"""Compiled bounding-volume hierarchy over a mesh's triangles (numba): exact closest points.

``ClosestPoint.query`` used to test the triangles around a point's 4 nearest vertices (a KD-tree query
and a ring of candidates: ~2.8 us a point, exact only where the closest triangle touches one of those
vertices). A hierarchy of axis-aligned boxes answers the closest triangle of all of them, and sooner:
the boxes nearer than the best distance so far are opened, nearest first, and only their leaves'
triangles are tested.

The layout is flat: node ``n`` has a box ``lo[n], hi[n] (3,)``; an inner node's children are ``left[n]``
and ``left[n] + 1``; a leaf (``left[n] < 0``) holds the triangles ``order[start[n]:start[n] + count[n]]``.
Nodes are numbered parents before children, so ``boxes`` walks them backwards. The tree (``build``)
depends on the faces alone; the boxes (``corners``, ``boxes``: ~0.1 ms for 10,000 triangles, against
~7 ms for the tree, built once per faces array) are made for each mesh of those faces.

The triangle test is ``closest_kernel.closest_on_corners`` (Ericson's, as ``closest_on_triangles``), and ties
go to the lowest face index, as ``np.argmin`` over all faces (``closest.closest_point_reference``): the
answer is the reference's bit for bit. The boxes are grown by a relative 1e-9 (as the triangles'
bounding spheres of ``closest_kernel``) so that rounding never closes a box holding the closest
triangle, and a box as far as the best distance is still opened (a tie in it may win by index).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from service.geometry.closest_kernel import closest_on_corners

LEAF = 4
"""Triangles per leaf: 2, 4 and 8 answered the jacket's closest points in the same time within 10 %."""
STACK = 128
"""Entries of the build's and the search's stacks: each holds at most one more than the tree is deep, and
below ``SAH_DEPTH`` every split is a median's, ~log2(F / LEAF) more levels (14 for 60,000 triangles)."""
SAH_DEPTH = 48
BINS = 16
"""Bins per axis of ``_sah_split``'s boundaries."""


@njit(cache=True, nogil=True)
def _partition(keys, order, s, e, m):
    """Reorder ``order[s:e]`` so that ``keys[order[m]]`` is in its sorted place, none before it larger
    and none after it smaller (quickselect, middle pivot)."""
    lo, hi = s, e - 1
    while lo < hi:
        pivot = keys[order[(lo + hi) // 2]]
        i, j = lo, hi
        while i <= j:
            while keys[order[i]] < pivot:
                i += 1
            while keys[order[j]] > pivot:
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                i += 1
                j -= 1
        if m <= j:
            hi = j
        elif m >= i:
            lo = i
        else:
            return


@njit(cache=True, nogil=True)
def build(vertices, faces, leaf):
    """The hierarchy of ``faces (F, 3)`` over ``vertices (V, 3)``: (left (N,), start (N,), count (N,),
    order (F,)), down to ``leaf`` triangles. Each inner node is split where the surface area heuristic
    is lowest (``_sah_split``), below ``SAH_DEPTH`` at the median of its triangles' centroids along the
    longest side of their bounds (``_partition``), which bounds the depth. It holds for any vertex
    positions (``boxes``): only how fast ``closest`` answers depends on the ones it was built on."""
    nf = len(faces)
    centroid, tlo, thi = np.empty((nf, 3)), np.empty((nf, 3)), np.empty((nf, 3))
    for f in range(nf):
        for d in range(3):
            a, b, c = vertices[faces[f, 0], d], vertices[faces[f, 1], d], vertices[faces[f, 2], d]
            centroid[f, d] = (a + b + c) / 3.0
            tlo[f, d], thi[f, d] = min(a, min(b, c)), max(a, max(b, c))
    order = np.arange(nf)
    cap = 2 * nf + 1  # every leaf holds a triangle at least: at most 2 F - 1 nodes
    left = np.full(cap, -1, dtype=np.int64)
    start, count = np.zeros(cap, dtype=np.int64), np.zeros(cap, dtype=np.int64)
    keys = np.empty(nf)
    scratch = np.empty(nf, dtype=np.int64)
    todo = np.empty((STACK, 4), dtype=np.int64)  # (node, first, end, depth)
    todo[0, 0], todo[0, 1], todo[0, 2], todo[0, 3] = 0, 0, nf, 0
    top, nodes = 1, 1
    while top:
        top -= 1
        n, s, e, depth = todo[top, 0], todo[top, 1], todo[top, 2], todo[top, 3]
        start[n], count[n] = s, e - s
        if e - s <= leaf:
            continue
        cmin, cmax = np.full(3, np.inf), np.full(3, -np.inf)
        for t in range(s, e):
            for d in range(3):
                c = centroid[order[t], d]
                cmin[d] = min(cmin[d], c)
                cmax[d] = max(cmax[d], c)
        m = -1
        if depth < SAH_DEPTH:
            m = _sah_split(centroid, tlo, thi, order, s, e, cmin, cmax, scratch)
        if m < 0:
            axis = 0
            for d in range(1, 3):
                if cmax[d] - cmin[d] > cmax[axis] - cmin[axis]:
                    axis = d
            for t in range(s, e):
                keys[order[t]] = centroid[order[t], axis]
            m = (s + e) // 2
            _partition(keys, order, s, e, m)
        left[n] = nodes
        todo[top, 0], todo[top, 1], todo[top, 2], todo[top, 3] = nodes, s, m, depth + 1
        todo[top + 1, 0], todo[top + 1, 1], todo[top + 1, 2], todo[top + 1, 3] = nodes + 1, m, e, depth + 1
        top += 2
        nodes += 2
    return left[:nodes].copy(), start[:nodes].copy(), count[:nodes].copy(), order


@njit(cache=True, nogil=True, inline="always")
def _bin(c, lo, extent):
    return min(BINS - 1, int((c - lo) / extent * BINS))


@njit(cache=True, nogil=True)
def _sah_split(centroid, tlo, thi, order, s, e, cmin, cmax, scratch):
    """Split ``order[s:e]`` in place where the surface area heuristic is lowest: of ``BINS`` equal bins
    of the centroids along each axis, the boundary minimising (half-area x triangles) summed over both
    sides' boxes. Returns the first index of the second side, or -1 when no boundary leaves both sides
    non-empty (the caller splits at the median)."""
    best_cost, best_axis, best_bin = np.inf, -1, -1
    count = np.empty(BINS, dtype=np.int64)
    lo, hi = np.empty((BINS, 3)), np.empty((BINS, 3))
    area_below, count_below = np.empty(BINS), np.empty(BINS, dtype=np.int64)
    box_lo, box_hi = np.empty(3), np.empty(3)
    for axis in range(3):
        extent = cmax[axis] - cmin[axis]
        if not extent > 0:
            continue
        count[:] = 0
        lo[:], hi[:] = np.inf, -np.inf
        for t in range(s, e):
            f = order[t]
            b = _bin(centroid[f, axis], cmin[axis], extent)
            count[b] += 1
            for d in range(3):
                lo[b, d], hi[b, d] = min(lo[b, d], tlo[f, d]), max(hi[b, d], thi[f, d])
        box_lo[:], box_hi[:] = np.inf, -np.inf
        below = 0
        for b in range(BINS):  # bins 0..b on the first side
            below += count[b]
            for d in range(3):
                box_lo[d], box_hi[d] = min(box_lo[d], lo[b, d]), max(box_hi[d], hi[b, d])
            area_below[b], count_below[b] = _half_area(box_lo, box_hi) if below else 0.0, below
        box_lo[:], box_hi[:] = np.inf, -np.inf
        above = 0
        for b in range(BINS - 1, 0, -1):  # bins b.. on the second side
            above += count[b]
            for d in range(3):
                box_lo[d], box_hi[d] = min(box_lo[d], lo[b, d]), max(box_hi[d], hi[b, d])
            if count_below[b - 1] == 0 or above == 0:
                continue
            cost = area_below[b - 1] * count_below[b - 1] + _half_area(box_lo, box_hi) * above
            if cost < best_cost:
                best_cost, best_axis, best_bin = cost, axis, b
    if best_axis < 0:
        return -1
    extent = cmax[best_axis] - cmin[best_axis]
    k, m = 0, s
    for side in range(2):  # stable: the first side's triangles, then the second's, each in order
        for t in range(s, e):
            f = order[t]
            if (_bin(centroid[f, best_axis], cmin[best_axis], extent) >= best_bin) == (side == 1):
                scratch[k] = f
                k += 1
        if side == 0:
            m = s + k
    order[s:e] = scratch[: e - s]
    return m


@njit(cache=True, nogil=True, inline="always")
def _half_area(lo, hi):
    dx, dy, dz = max(hi[0] - lo[0], 0.0), max(hi[1] - lo[1], 0.0), max(hi[2] - lo[2], 0.0)
    return dx * dy + dy * dz + dz * dx


@njit(cache=True, nogil=True)
def _refit_inner(lo, hi, left):
    for n in range(len(left) - 1, -1, -1):
        c = left[n]
        if c < 0:
            continue
        for d in range(3):
            lo[n, d] = min(lo[c, d], lo[c + 1, d])
            hi[n, d] = max(hi[c, d], hi[c + 1, d])


@njit(cache=True, nogil=True)
def boxes(tri, left, start, count):
    """(lo (N, 3), hi (N, 3)): the nodes' boxes around their triangles' corners ``tri (F, 3, 3)`` in
    leaf order (``corners``), grown by a relative 1e-9."""
    lo, hi = np.empty((len(left), 3)), np.empty((len(left), 3))
    for n in range(len(left)):
        if left[n] >= 0:
            continue
        s, e = start[n], start[n] + count[n]
        for d in range(3):
            a, b = np.inf, -np.inf
            for t in range(s, e):
                a = min(a, min(tri[t, 0, d], min(tri[t, 1, d], tri[t, 2, d])))
                b = max(b, max(tri[t, 0, d], max(tri[t, 1, d], tri[t, 2, d])))
            pad = 1e-9 * max(abs(a), abs(b)) + 1e-12
            lo[n, d], hi[n, d] = a - pad, b + pad
    _refit_inner(lo, hi, left)
    return lo, hi


@njit(cache=True, nogil=True)
def triangle_boxes(tri):
    """(lo (F, 3), hi (F, 3)): each triangle's own box around its corners ``tri (F, 3, 3)`` (leaf order),
    grown by a relative 1e-9 as the nodes' boxes. ``closest`` tests a leaf's triangle only where its box
    is within the best distance so far: the box costs a few comparisons, Ericson's test several times
    that, and a leaf's box near a point often holds triangles far from it (the T-shirt's and the
    jacket's queries of an outfit of four tops: 27 % less time, the same answers)."""
    lo, hi = np.empty((len(tri), 3)), np.empty((len(tri), 3))
    for t in range(len(tri)):
        for d in range(3):
            a = min(tri[t, 0, d], min(tri[t, 1, d], tri[t, 2, d]))
            b = max(tri[t, 0, d], max(tri[t, 1, d], tri[t, 2, d]))
            pad = 1e-9 * max(abs(a), abs(b)) + 1e-12
            lo[t, d], hi[t, d] = a - pad, b + pad
    return lo, hi


@njit(cache=True, nogil=True)
def corners(vertices, faces, order):
    """``(F, 3, 3)``: the corners of the triangles in leaf order, read one after the other by ``closest``."""
    out = np.empty((len(order), 3, 3))
    for t in range(len(order)):
        for c in range(3):
            for d in range(3):
                out[t, c, d] = vertices[faces[order[t], c], d]
    return out


@njit(cache=True, nogil=True, inline="always")
def _box_distance(px, py, pz, lo, hi, n):
    dx = max(lo[n, 0] - px, 0.0, px - hi[n, 0])
    dy = max(lo[n, 1] - py, 0.0, py - hi[n, 1])
    dz = max(lo[n, 2] - pz, 0.0, pz - hi[n, 2])
    return dx * dx + dy * dy + dz * dz  # squared


@njit(cache=True, nogil=True)
def closest(points, tri, tlo, thi, lo, hi, left, start, count, order, face_out, bary_out, point_out):
    """For each of ``points (N, 3)``: the closest point on any triangle into ``face_out (N,)`` (-1 for
    a point no test could place, e.g. NaN), ``bary_out (N, 3)`` and ``point_out (N, 3)``. ``tri``:
    ``corners``; ``tlo, thi``: ``triangle_boxes``; ``lo, hi``: ``boxes``."""
    w = np.empty(3)
    stack = np.empty(STACK, dtype=np.int64)
    gap = np.empty(STACK)  # squared distance of each stacked node's box, computed when it was pushed
    for i in range(len(points)):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        best_face = -1
        stack[0], gap[0] = 0, 0.0
        top = 1
        while top:
            top -= 1
            n = stack[top]
            if gap[top] > best * best:
                continue
            c = left[n]
            if c >= 0:
                # The nearer child is opened first: it most likely holds the closest triangle, and the
                # farther one is then often skipped.
                da = _box_distance(px, py, pz, lo, hi, c)
                db = _box_distance(px, py, pz, lo, hi, c + 1)
                near, far, d_near, d_far = (c, c + 1, da, db) if da <= db else (c + 1, c, db, da)
                if d_far <= best * best:
                    stack[top], gap[top] = far, d_far
                    top += 1
                if d_near <= best * best:
                    stack[top], gap[top] = near, d_near
                    top += 1
                continue
            for t in range(start[n], start[n] + count[n]):
                if _box_distance(px, py, pz, tlo, thi, t) > best * best:
                    continue  # as far as its box is, farther than the best (equal: a tie may win)
                f = order[t]
                d, qx, qy, qz = closest_on_corners(px, py, pz, tri[t, 0], tri[t, 1], tri[t, 2], w)
                if d < best or (d == best and f < best_face):
                    best, best_face = d, f
                    bary_out[i, 0], bary_out[i, 1], bary_out[i, 2] = w[0], w[1], w[2]
                    point_out[i, 0], point_out[i, 1], point_out[i, 2] = qx, qy, qz
        face_out[i] = best_face
