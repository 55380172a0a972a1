"""``girth.tape_girths`` at many heights in one compiled pass (numba): the same sections, loops, choice
of loop and hull as the numpy path, one height after another without leaving compiled code.

Per height: the faces a plane can cross are a run of the faces sorted by their lowest corner; each
crossed face gives the section a segment from its down edge to its up edge; the edges are numbered in
order of their key ``min * V + max`` (an argsort, as ``np.unique``) and must each be met twice (else
the section is open); the segments then form loops (``girth._order_cycles``). The loop kept is the
one of largest area among those that wind around the height's point (even-odd rule, as
``girth.encloses``), and the tape is its convex hull (``girth._monotone_chain`` on the points sorted by
x, then y). Every number is computed by the numpy path's formula, so the hulls are its hulls; only the
lengths sum in another order (within ~1e-15 relative; tested against ``tape_girths_reference``).

Why: ``measurements.measure`` reads ~110 heights of a body, and the numpy path spends ~0.2 ms a height
in per-call overhead (22 ms a body): a table body of a gender in between is measured on a thread beside
its outfit, and those milliseconds came off the outfit's cores (``benchmarks.latency``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from service.geometry.girth import _monotone_chain, _order_cycles

OPEN = 1
"""Error code of a height: a crossed edge met once (the mesh has a boundary there)."""
NOT_LOOPS = 2
"""Error code of a height: a segment without a successor (the faces' orientations disagree)."""


@njit(cache=True, nogil=True)
def _encloses(points, order, s, e, x, y):
    """Whether the loop ``points[order[s:e]]`` winds around (x, y) (``girth.encloses``)."""
    xmin, xmax, ymin, ymax = np.inf, -np.inf, np.inf, -np.inf
    for k in range(s, e):
        px, py = points[order[k], 0], points[order[k], 1]
        xmin, xmax, ymin, ymax = min(xmin, px), max(xmax, px), min(ymin, py), max(ymax, py)
    if e == s or not (xmin <= x <= xmax and ymin <= y <= ymax):
        return False
    count = 0
    for k in range(s, e):
        p = order[k]
        q = order[k + 1] if k + 1 < e else order[s]
        py, qy = points[p, 1], points[q, 1]
        if (py > y) != (qy > y):
            x_cross = points[p, 0] + (y - py) * (points[q, 0] - points[p, 0]) / (qy - py)
            if x < x_cross:
                count += 1
    return count % 2 == 1


@njit(cache=True, nogil=True)
def _area(points, order, s, e):
    """|signed area| of the loop ``points[order[s:e]]`` (``girth.signed_area``)."""
    total = 0.0
    for k in range(s, e):
        p = order[k]
        q = order[k + 1] if k + 1 < e else order[s]
        total += points[p, 0] * points[q, 1] - points[q, 0] * points[p, 1]
    return abs(0.5 * total)


@njit(cache=True, nogil=True)
def _sorted_xy(loop):
    """``loop (K, 2)`` sorted by x, then y (``np.lexsort((y, x))``: stable, so equal points keep order)."""
    order = np.argsort(loop[:, 0], kind="mergesort")
    out = loop[order]
    i = 0
    while i < len(out):  # runs of equal x, by y (insertion sort: stable, and the runs are short)
        j = i + 1
        while j < len(out) and out[j, 0] == out[i, 0]:
            j += 1
        for a in range(i + 1, j):
            ya, row = out[a, 1], out[a].copy()
            b = a - 1
            while b >= i and out[b, 1] > ya:
                out[b + 1] = out[b]
                b -= 1
            out[b + 1] = row
        i = j
    return out


@njit(cache=True, nogil=True)
def _level(vertices, faces, fz, lowest, highest, span, z):
    """The crossing points ``(N, 2)`` and successors ``(N,)`` of the plane z (``_Slicer.crossing_edges``),
    and an error code (0, ``OPEN``, ``NOT_LOOPS``)."""
    first = np.searchsorted(lowest, z - span, side="right")
    last = np.searchsorted(lowest, z, side="right")
    tri = np.empty(max(last - first, 0), dtype=np.int64)
    n_tri = 0
    for f in range(first, last):
        if highest[f] > z:
            tri[n_tri] = f
            n_tri += 1
    keys = np.empty(2 * n_tri, dtype=np.int64)
    n_v = len(vertices)
    for r in range(n_tri):
        f = tri[r]
        down, up = 0, 0
        for k in range(2, -1, -1):  # np.argmax: the first edge that goes down (up)
            here, there = fz[f, k] > z, fz[f, (k + 1) % 3] > z
            if here and not there:
                down = k
            if not here and there:
                up = k
        a, b = faces[f, down], faces[f, (down + 1) % 3]
        keys[2 * r] = min(a, b) * n_v + max(a, b)
        a, b = faces[f, up], faces[f, (up + 1) % 3]
        keys[2 * r + 1] = min(a, b) * n_v + max(a, b)
    order = np.argsort(keys, kind="mergesort")
    node = np.empty(2 * n_tri, dtype=np.int64)
    unique = np.empty(2 * n_tri, dtype=np.int64)
    n = -1
    for i in range(2 * n_tri):
        if i == 0 or keys[order[i]] != keys[order[i - 1]]:
            n += 1
            unique[n] = keys[order[i]]
        node[order[i]] = n
    n += 1
    count = np.zeros(n, dtype=np.int64)
    for i in range(2 * n_tri):
        count[node[i]] += 1
    points = np.empty((n, 2))
    succ = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        if count[i] != 2:
            return points, succ, OPEN
        ia, ib = unique[i] // n_v, unique[i] % n_v
        t = (z - vertices[ia, 2]) / (vertices[ib, 2] - vertices[ia, 2])
        for d in range(2):
            points[i, d] = vertices[ia, d] + t * (vertices[ib, d] - vertices[ia, d])
    for r in range(n_tri):
        succ[node[2 * r]] = node[2 * r + 1]
    for i in range(n):
        if succ[i] < 0:
            return points, succ, NOT_LOOPS
    return points, succ, 0


@njit(cache=True, nogil=True)
def tape_hulls(vertices, faces, fz, lowest, highest, span, zs, select):
    """At each height ``zs[l]``: the convex hull of the largest section loop around ``select[l] (2,)``.

    ``faces (F, 3)`` sorted by their lowest corner, ``fz (F, 3)`` their corners' z, ``lowest``,
    ``highest (F,)`` and ``span`` as ``girth._Slicer`` keeps them. Returns (hull corners ``(H, 2)`` of
    all heights one after another, ``starts (L + 1,)``: height l's are ``starts[l]:starts[l + 1]``,
    empty where no loop goes around its point; ``error (L,)``: 0, ``OPEN`` or ``NOT_LOOPS``)."""
    n_levels = len(zs)
    starts = np.zeros(n_levels + 1, dtype=np.int64)
    error = np.zeros(n_levels, dtype=np.int64)
    out = np.empty((0, 2))
    for lev in range(n_levels):
        starts[lev + 1] = starts[lev]
        points, succ, err = _level(vertices, faces, fz, lowest, highest, span, zs[lev])
        error[lev] = err
        if err or not len(succ):
            continue
        order, loop_starts = _order_cycles(succ)
        best, best_area = -1, -1.0
        for c in range(len(loop_starts) - 1):
            s, e = loop_starts[c], loop_starts[c + 1]
            if _encloses(points, order, s, e, select[lev, 0], select[lev, 1]):
                area = _area(points, order, s, e)
                if area > best_area:  # max() keeps the first of equal areas
                    best, best_area = c, area
        if best < 0:
            continue
        s, e = loop_starts[best], loop_starts[best + 1]
        hull = _monotone_chain(_sorted_xy(points[order[s:e]]))
        if starts[lev] + len(hull) > len(out):
            grown = np.empty((2 * (starts[lev] + len(hull)), 2))
            grown[: starts[lev]] = out[: starts[lev]]
            out = grown
        out[starts[lev] : starts[lev] + len(hull)] = hull
        starts[lev + 1] = starts[lev] + len(hull)
    return out[: starts[-1]], starts, error
