"""The body map's weights per point, compiled (numba): ``CanonicalSpace._transfer_rows`` in one loop.

``transfer_weights_reference`` (``service.pipeline.canonical``) defines the weights with numpy arrays
of every (point, candidate triangle) slot; here each point works through its own slots in registers:
Ericson's test (``service.geometry.closest_kernel.closest_on``, the reference's arithmetic) once per
distinct triangle of the rings of its ``near_vertices`` nearest vertices, the least distance d0, the
``near_triangles`` least slots (a triangle in several rings keeps a slot per ring, as in the
reference), their soft-min and the Gaussian far term. The same weights to rounding (the reference
sorts the slots; the soft-min's sum does not depend on their order but its rounding does).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from service.geometry.closest_kernel import closest_on


@njit(cache=True, nogil=True)
def transfer_rows(points, vertices, faces, spheres, ring, vdist, far_index, near_vertices, near_triangles,
                  blend, sigma_min, softness, far_weight, near_index, near_weight, has_near):  # fmt: skip
    """For ``points (N, 3)`` with their nearest body vertices ``far_index (N, K)`` at ``vdist (N, K)``
    (ascending): the far term's weights into ``far_weight (N, K)``; for the points nearer than
    ``blend`` (``has_near``), the corners ``near_index (N, 3 T)`` and weights ``near_weight (N, 3 T)``
    of the near term's T = ``near_triangles`` slots (rows of the others are left as they are).
    ``spheres (F, 4)`` bound each triangle (``closest_kernel.bounding_spheres``): one whose sphere is
    farther than the T-th least slot so far cannot enter the T least, nor be the least, and is not
    tested (the same result as testing it)."""
    n, k = far_index.shape
    r = ring.shape[1]
    slot_face = np.empty(near_vertices * r, dtype=np.int64)
    tested_at = np.full(len(faces), -1, dtype=np.int64)  # the point a triangle was last tested for
    tested_d = np.empty(len(faces))  # its distance and barycentric coordinates for that point
    tested_w = np.empty((len(faces), 3))
    w = np.empty(3)
    chosen = np.empty(near_triangles, dtype=np.int64)
    chosen_d = np.empty(near_triangles)
    for i in range(n):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        m = 0
        count = 0  # slots kept among the near_triangles least so far, ascending in chosen_d
        d0 = np.inf
        for j in range(min(near_vertices, k)):
            v = far_index[i, j]
            for s in range(r):
                f = ring[v, s]
                if f < 0:
                    break
                if tested_at[f] != i:
                    tested_at[f] = i
                    tested_d[f] = np.inf  # pruned, unless tested below
                    sx, sy, sz = px - spheres[f, 0], py - spheres[f, 1], pz - spheres[f, 2]
                    gap = np.sqrt(sx * sx + sy * sy + sz * sz) - spheres[f, 3]
                    if not (count == near_triangles and gap > chosen_d[count - 1]):
                        tested_d[f] = closest_on(px, py, pz, vertices, faces, f, w)[0]
                        tested_w[f, 0], tested_w[f, 1], tested_w[f, 2] = w[0], w[1], w[2]
                        d0 = min(d0, tested_d[f])
                slot_face[m] = f
                d = tested_d[f]
                # The near_triangles least slots, in slot order (an equal one later stays out).
                if not (count == near_triangles and d >= chosen_d[count - 1]):
                    pos = count if count < near_triangles else near_triangles - 1
                    while pos > 0 and chosen_d[pos - 1] > d:
                        if pos < near_triangles:
                            chosen[pos], chosen_d[pos] = chosen[pos - 1], chosen_d[pos - 1]
                        pos -= 1
                    chosen[pos], chosen_d[pos] = m, d
                    if count < near_triangles:
                        count += 1
                m += 1
        t = min(max(d0 / blend, 0.0), 1.0)
        s_blend = t * t * (3 - 2 * t)  # smoothstep
        # Far term: Gaussian over the nearest vertices, wider further out, times s.
        sigma = sigma_min + 0.5 * d0
        total = 0.0
        for j in range(k):
            g = np.exp((vdist[i, j] ** 2 - vdist[i, 0] ** 2) * (-0.5 / sigma**2))
            far_weight[i, j] = g
            total += g
        for j in range(k):
            far_weight[i, j] *= s_blend / total
        has_near[i] = s_blend < 1
        if not has_near[i]:
            continue
        tau = max(softness * d0, 1e-9)
        total = 0.0
        for c in range(count):
            total += np.exp(-0.5 * (chosen_d[c] ** 2 - d0**2) / tau**2)
        for c in range(near_triangles):
            f, soft = slot_face[0], 0.0
            if c < count:
                f = slot_face[chosen[c]]
                soft = np.exp(-0.5 * (chosen_d[c] ** 2 - d0**2) / tau**2) * (1 - s_blend) / total
            for corner in range(3):
                near_index[i, 3 * c + corner] = faces[f, corner]
                near_weight[i, 3 * c + corner] = soft * tested_w[f, corner]
