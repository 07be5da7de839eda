"""Minutiae of two prints paired the way bozorth3 pairs them: by compatible pair tables.

``nbis-py`` gives bozorth3's score but not the minutia pairings behind it, so the paper's "UWA*"
mates (a matcher's pairings) are formed here with bozorth3's own idea:

1. every two minutiae ``(i, j)`` of one print closer than ``max_distance`` make an *intra-print
   pair* with features: their distance ``d`` and each minutia's direction relative to the line
   from ``i`` to ``j`` (``beta_i``, ``beta_j``), all invariant to rotation and translation;
2. a pair of print A and a pair of print B are *compatible* when their distances agree within
   ``distance_tolerance`` (relative) and both betas within ``angle_tolerance``;
3. every compatible pair of pairs implies two minutia correspondences and a turn (the angle
   between the two lines); as bozorth3 clusters by turn, only pairs of pairs within
   ``turn_tolerance`` of the most common turn vote;
4. correspondences are taken greedily by votes, one-to-one, down to ``min_votes``;
5. of those, the ones compatible with at least ``min_votes`` others are kept, and of them the
   largest connected group (bozorth3's largest cluster); fewer than ``min_pairs`` is no pairing.

Coordinates must share a scale (print pixels at ~500 ppi: photo pixels times the print's
``ppi_scale``). Pure numpy.
"""
from __future__ import annotations

import numpy as np

__all__ = ["pair_minutiae"]


def _pair_table(xy: np.ndarray, angles_deg: np.ndarray, max_distance: float):
    i, j = np.triu_indices(len(xy), 1)
    delta = xy[j] - xy[i]
    distance = np.hypot(delta[:, 0], delta[:, 1])
    keep = (distance < max_distance) & (distance > 1e-6)
    i, j, delta, distance = i[keep], j[keep], delta[keep], distance[keep]
    line = np.degrees(np.arctan2(delta[:, 1], delta[:, 0]))
    beta_i = (angles_deg[i] - line) % 360.0
    beta_j = (angles_deg[j] - line) % 360.0
    return i, j, distance, beta_i, beta_j, line


def _line_angles(xy: np.ndarray) -> np.ndarray:
    """``[N, N]`` direction (degrees) of the line from minutia i to minutia j."""
    delta = xy[None, :, :] - xy[:, None, :]
    return np.degrees(np.arctan2(delta[..., 1], delta[..., 0]))


def _angle_close(a: np.ndarray, b: np.ndarray, tolerance: float) -> np.ndarray:
    difference = np.abs(a - b) % 360.0
    return np.minimum(difference, 360.0 - difference) <= tolerance


def pair_minutiae(xy_a: np.ndarray, angles_a: np.ndarray, xy_b: np.ndarray, angles_b: np.ndarray, *,
                  max_distance: float = 150.0, distance_tolerance: float = 0.1, angle_tolerance: float = 15.0,
                  min_votes: int = 3, turn_tolerance: float = 20.0, min_pairs: int = 8,
                  chunk: int = 2048) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(index_a, index_b, votes)`` of the paired minutiae, most votes first."""
    xy_a, xy_b = np.asarray(xy_a, np.float64).reshape(-1, 2), np.asarray(xy_b, np.float64).reshape(-1, 2)
    angles_a, angles_b = np.asarray(angles_a, np.float64).reshape(-1), np.asarray(angles_b, np.float64).reshape(-1)
    empty = (np.zeros(0, np.int64),) * 2 + (np.zeros(0, np.int64),)
    if len(xy_a) < 2 or len(xy_b) < 2:
        return empty
    ia, ja, da, bia, bja, la = _pair_table(xy_a, angles_a, max_distance)
    ib, jb, db, bib, bjb, lb = _pair_table(xy_b, angles_b, max_distance)
    found = []  # (a minutia, b minutia, turn) twice per compatible pair of pairs
    for start in range(0, len(ia), chunk):
        s = slice(start, start + chunk)
        near = np.abs(da[s, None] - db[None, :]) <= distance_tolerance * np.maximum(da[s, None], db[None, :])
        same = near & _angle_close(bia[s, None], bib[None, :], angle_tolerance) & _angle_close(
            bja[s, None], bjb[None, :], angle_tolerance)
        # the same line read the other way round: i <-> j swapped, betas turned by 180 degrees
        swapped = near & _angle_close(bia[s, None], (bjb[None, :] + 180.0) % 360.0, angle_tolerance) & _angle_close(
            bja[s, None], (bib[None, :] + 180.0) % 360.0, angle_tolerance)
        for mask, first_b, second_b, flip in ((same, ib, jb, 0.0), (swapped, jb, ib, 180.0)):
            rows, cols = np.nonzero(mask)
            turn = (lb[cols] + flip - la[s][rows]) % 360.0
            found += [(ia[s][rows], first_b[cols], turn), (ja[s][rows], second_b[cols], turn)]
    if not found:
        return empty
    a_index, b_index, turn = (np.concatenate(v) for v in zip(*found))
    # bozorth3 keeps the pairs that agree on how print B is turned against print A: the mode of
    # the turn (10-degree bins, circular), and votes only from within turn_tolerance of it
    histogram = np.bincount((turn // 10).astype(np.int64) % 36, minlength=36)
    smoothed = histogram + np.roll(histogram, 1) + np.roll(histogram, -1)
    mode = 10.0 * int(np.argmax(smoothed)) + 5.0
    agree = _angle_close(turn, np.full_like(turn, mode), turn_tolerance)
    votes = np.zeros((len(xy_a), len(xy_b)), np.int64)
    np.add.at(votes, (a_index[agree], b_index[agree]), 1)
    order = np.argsort(votes, axis=None)[::-1]
    taken_a, taken_b = np.zeros(len(xy_a), bool), np.zeros(len(xy_b), bool)
    pairs = []
    for flat in order:
        a, b = divmod(int(flat), len(xy_b))
        if votes[a, b] < min_votes:
            break
        if not (taken_a[a] or taken_b[b]):
            taken_a[a] = taken_b[b] = True
            pairs.append((a, b, votes[a, b]))
    if not pairs:
        return empty
    index_a, index_b, count = (np.array(v, np.int64) for v in zip(*pairs))
    keep = _consistent(xy_a[index_a], angles_a[index_a], xy_b[index_b], angles_b[index_b], max_distance,
                       distance_tolerance, angle_tolerance, min_votes)
    if keep.sum() < min_pairs:  # a handful of agreeing pairs happens by chance between any two prints
        return empty
    return index_a[keep], index_b[keep], count[keep]


def _consistent(xy_a, angles_a, xy_b, angles_b, max_distance, distance_tolerance, angle_tolerance,
                min_partners) -> np.ndarray:
    """Correspondences compatible (as pairs of pairs) with at least ``min_partners`` of the others
    kept, removing the least supported one at a time (bozorth3's cluster step, in short)."""
    n = len(xy_a)
    keep = np.ones(n, bool)
    if n < 2:
        return keep
    da = np.linalg.norm(xy_a[:, None] - xy_a[None], axis=-1)
    db = np.linalg.norm(xy_b[:, None] - xy_b[None], axis=-1)
    beta_a = (angles_a[:, None] - _line_angles(xy_a)) % 360.0
    beta_b = (angles_b[:, None] - _line_angles(xy_b)) % 360.0
    compatible = ((da < max_distance) & (np.abs(da - db) <= distance_tolerance * np.maximum(da, db))
                  & _angle_close(beta_a, beta_b, angle_tolerance) & _angle_close(beta_a.T, beta_b.T, angle_tolerance))
    np.fill_diagonal(compatible, False)
    while keep.any():
        support = (compatible & keep[None, :]).sum(1)
        support[~keep] = np.iinfo(np.int64).max
        worst = int(np.argmin(support))
        if support[worst] >= min_partners:
            break
        keep[worst] = False
    if keep.sum() > 1:  # the largest group of mutually supporting correspondences (bozorth3's largest cluster)
        from scipy.sparse.csgraph import connected_components

        kept = np.flatnonzero(keep)
        _, labels = connected_components(compatible[np.ix_(kept, kept)], directed=False)
        keep[:] = False
        keep[kept[labels == np.bincount(labels).argmax()]] = True
    return keep
