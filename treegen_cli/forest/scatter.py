"""Scattering trees over a rectangle or polygon: uniform, with a minimum spacing (dart throwing
against a k-d tree), seeded."""

from __future__ import annotations

import math

import numpy as np

from ..errors import TreegenError

HEX_PACKING = 2.0 / math.sqrt(3.0)  # most disks of diameter s per s² of area (hexagonal)


def polygon_area(poly: np.ndarray) -> float:
    """Shoelace area (absolute) of a simple polygon (N, 2)."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def crossing_edges(poly: np.ndarray) -> tuple[int, int] | None:
    """The first pair of edges (i, j), edge i from vertex i to i + 1, that cross or touch
    although they are not neighbours; None for a simple polygon. All pairs at once: a
    layout's polygon has tens of vertices, a thousand is a million pairs."""
    a, b = poly, np.roll(poly, -1, axis=0)
    n = len(poly)

    def side(p, q, r):  # sign of the turn p → q → r, (N, N)
        return np.sign(
            (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
            - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])
        )

    A, B = a[:, None, :], b[:, None, :]
    C, D = a[None, :, :], b[None, :, :]
    d1, d2 = side(C, D, A), side(C, D, B)
    d3, d4 = side(A, B, C), side(A, B, D)
    cross = (d1 * d2 <= 0) & (d3 * d4 <= 0)
    i, j = np.triu_indices(n, 2)
    apart = (j - i) % n != n - 1  # the last edge neighbours the first
    hit = cross[i, j] & apart & ~((d1 == 0) & (d2 == 0) & (d3 == 0) & (d4 == 0))[i, j]
    k = np.flatnonzero(hit)
    return (int(i[k[0]]), int(j[k[0]])) if k.size else None


def inside_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule, vectorised over points × edges: bool (P,)."""
    a, b = poly, np.roll(poly, -1, axis=0)
    px, py = points[:, 0:1], points[:, 1:2]
    crosses = (a[None, :, 1] > py) != (b[None, :, 1] > py)
    dy = np.where(b[:, 1] == a[:, 1], 1.0, b[:, 1] - a[:, 1])
    x_at = a[None, :, 0] + (py - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / dy[None, :]
    return (np.count_nonzero(crosses & (px < x_at), axis=1) % 2) == 1


def scatter_points(
    region: np.ndarray,
    is_polygon: bool,
    count: int,
    min_spacing: float,
    rng: np.random.Generator,
    where: str = "scatter",
) -> np.ndarray:
    """`count` points (count, 2) uniformly in the region, pairwise ≥ min_spacing apart.

    Dart throwing in vectorised batches: a candidate survives if it keeps the spacing to every
    accepted point and to every earlier candidate of its batch (a conservative rule that needs
    no sequential pass). Impossible requests (more disks than hexagonal packing holds) fail at
    once; hard ones fail after a bounded number of fruitless batches, naming the count reached.
    """
    lo, hi = region.min(axis=0), region.max(axis=0)
    area = polygon_area(region) if is_polygon else float(np.prod(hi - lo))
    if count == 0:
        return np.zeros((0, 2))
    if area <= 0:
        raise TreegenError(f"{where}: the region has zero area")
    if min_spacing > 0:
        # disks of radius s/2 around each point lie in the region grown by s/2
        per = (
            np.sum(np.linalg.norm(np.roll(region, -1, 0) - region, axis=1))
            if is_polygon
            else 2 * float(np.sum(hi - lo))
        )
        grown = area + per * min_spacing / 2 + math.pi * min_spacing**2 / 4
        most = int(HEX_PACKING * grown / min_spacing**2)
        if count > most:
            raise TreegenError(
                f"{where}: impossible scatter: {count} trees at min_spacing {min_spacing:g} m need "
                f"about {count * min_spacing**2 / HEX_PACKING:.0f} m², the region has {area:.0f} m² "
                f"(at most ~{most} fit); lower count/density or min_spacing"
            )
    from scipy.spatial import cKDTree  # (0.2 s to import: only where used)

    accepted = np.zeros((0, 2))
    stale = 0
    while len(accepted) < count and stale < 60:
        need = count - len(accepted)
        cand = lo + rng.random((max(4 * need, 64), 2)) * (hi - lo)
        if is_polygon:
            cand = cand[inside_polygon(cand, region)]
        if min_spacing > 0 and len(cand):
            if len(accepted):
                d, _ = cKDTree(accepted).query(cand, k=1)
                cand = cand[d >= min_spacing]
            pairs = cKDTree(cand).query_pairs(min_spacing, output_type="ndarray")
            keep = np.ones(len(cand), bool)
            keep[pairs.max(axis=1) if len(pairs) else []] = False
            cand = cand[keep]
        cand = cand[:need]
        stale = stale + 1 if len(cand) == 0 else 0
        accepted = np.concatenate([accepted, cand])
    if len(accepted) < count:
        raise TreegenError(
            f"{where}: could not place {count} trees at min_spacing {min_spacing:g} m "
            f"(placed {len(accepted)}); lower count/density or min_spacing"
        )
    return accepted
