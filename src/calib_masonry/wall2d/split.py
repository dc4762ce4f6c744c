"""The splitting method: simplify a closed traced outline to N vertices.

Start from the farthest pair of outline points, then repeatedly add the outline point farthest
from the chord of the arc it lies on (Ramer-Douglas-Peucker run greedily over all arcs at once,
so each added vertex is the one that removes the largest deviation). Vertices always lie on the
outline and keep its order, so the result follows the outline's orientation.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator

import numpy as np
from scipy.spatial import ConvexHull, QhullError

__all__ = ["farthest_pair", "splitting_sequence", "split_outline", "visvalingam"]


def farthest_pair(points: np.ndarray) -> tuple[int, int]:
    """Indices of the two points of ``points`` ``(M, 2)`` farthest apart (exact, via the hull)."""
    idx = np.arange(len(points))
    if len(points) > 8:
        try:
            idx = ConvexHull(points).vertices
        except (QhullError, ValueError):
            pass
    sub = points[idx]
    d2 = ((sub[:, None, :] - sub[None, :, :]) ** 2).sum(-1)
    i, j = np.unravel_index(int(np.argmax(d2)), d2.shape)
    a, b = int(idx[i]), int(idx[j])
    return (a, b) if a < b else (b, a)


def _farthest_on_arc(points: np.ndarray, i: int, j: int) -> tuple[float, int]:
    """Largest distance of the points strictly between ``i`` and ``j`` (cyclic) to chord i-j."""
    m = len(points)
    k = np.arange(i + 1, i + ((j - i) % m)) % m
    if k.size == 0:
        return 0.0, -1
    p, q = points[i], points[j]
    seg = q - p
    length = float(np.hypot(*seg))
    rel = points[k] - p
    if length < 1e-12:
        d = np.hypot(rel[:, 0], rel[:, 1])
    else:
        d = np.abs(rel[:, 0] * seg[1] - rel[:, 1] * seg[0]) / length
    best = int(np.argmax(d))
    return float(d[best]), int(k[best])


def splitting_sequence(points: np.ndarray, max_vertices: int) -> Iterator[np.ndarray]:
    """Yield the sorted vertex indices for 2, 3, ..., ``max_vertices`` vertices in turn."""
    points = np.asarray(points, dtype=np.float64)
    m = len(points)
    a, b = farthest_pair(points)
    chosen = [a, b]
    yield np.array(chosen)
    heap: list[tuple[float, int, int, int]] = []
    for i, j in ((a, b), (b, a)):
        d, k = _farthest_on_arc(points, i, j)
        if k >= 0:
            heapq.heappush(heap, (-d, k, i, j))
    while len(chosen) < min(max_vertices, m) and heap:
        _, k, i, j = heapq.heappop(heap)
        chosen.append(k)
        for s, e in ((i, k), (k, j)):
            d, kk = _farthest_on_arc(points, s, e)
            if kk >= 0:
                heapq.heappush(heap, (-d, kk, s, e))
        yield np.array(sorted(chosen))


def split_outline(points: np.ndarray, n_vertices: int) -> np.ndarray:
    """Sorted indices of ``n_vertices`` outline points chosen by the splitting method."""
    return list(splitting_sequence(points, n_vertices))[-1]


def visvalingam(points: np.ndarray, n_vertices: int) -> np.ndarray:
    """Sorted indices of ``n_vertices`` outline points kept by Visvalingam-Whyatt simplification.

    Repeatedly drops the point whose triangle with its two neighbours has the smallest area (the
    least area lost). Used as a second starting polygon for refinement: it spreads vertices by
    area, where splitting spreads them by distance.
    """
    pts = np.asarray(points, dtype=np.float64)
    m = len(pts)
    if m <= n_vertices:
        return np.arange(m)
    prev = np.roll(np.arange(m), 1)
    nxt = np.roll(np.arange(m), -1)
    alive = np.ones(m, bool)

    def area(i: int) -> float:
        a, b, c = pts[prev[i]], pts[i], pts[nxt[i]]
        return 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    stamp = np.zeros(m, dtype=np.int64)
    heap = [(area(i), i, 0) for i in range(m)]
    heapq.heapify(heap)
    count = m
    while count > n_vertices and heap:
        a, i, st = heapq.heappop(heap)
        if not alive[i] or st != stamp[i]:
            continue
        alive[i] = False
        count -= 1
        p, q = prev[i], nxt[i]
        nxt[p], prev[q] = q, p
        for j in (p, q):
            stamp[j] += 1
            heapq.heappush(heap, (area(j), j, int(stamp[j])))
    return np.flatnonzero(alive)
