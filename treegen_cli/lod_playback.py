"""Playback check: a decimated clip as an engine plays it (kept keys slerped or held, composed
through the hierarchy), compared with the dense clip on each joint's probe corners. Kept up to
date as the decimation adds keys, re-posing only what changed, since it runs every round."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .asset import Skeleton
from .clip import play_at, play_keys
from .lod_probes import Probes
from .skeleton import depth_levels, pose_world, trs


def corner_errors(world: np.ndarray, dense_world: np.ndarray, hom: np.ndarray) -> np.ndarray:
    """Largest squared distance (K, n) between a joint's 8 box corners posed by joint world
    matrices `world` and by the dense clip's `dense_world` (both (K, n, 4, 4)); hom (n, 4, 8)
    homogeneous corners in the joints' bind frames: one 3×4 @ 4×8 product per joint and frame."""
    diff = np.matmul((world - dense_world)[..., :3, :], hom)
    return np.einsum("kjac,kjac->kjc", diff, diff).max(axis=2)


def ancestors(parent: np.ndarray) -> np.ndarray:
    """(J, D) table: column 0 the joint itself, then its parent, grandparent, … (the root
    repeats once reached); D = depth of the deepest joint + 1."""
    chain = [np.arange(parent.shape[0])]
    while True:
        up = parent[chain[-1]]
        nxt = np.where(up >= 0, up, chain[-1])
        if np.array_equal(nxt, chain[-1]):
            return np.stack(chain, axis=1)
        chain.append(nxt)


@dataclass(frozen=True, eq=False)
class PlaybackModel:
    """What the playback check needs of one LOD: skeleton tables, the probes' corners as
    homogeneous bind-frame points hom (J, 4, 8), ancestors (J, D) and lever[j, a], the
    farthest corner of joint j from the pivot of its a-th ancestor (rest pose)."""

    skeleton: Skeleton
    parent: np.ndarray
    levels: list
    hom: np.ndarray
    anc: np.ndarray
    lever: np.ndarray

    @classmethod
    def of(cls, skeleton: Skeleton, pr: Probes) -> "PlaybackModel":
        J = len(skeleton.names)
        parent = np.asarray(skeleton.parent, dtype=np.int64)
        hom = np.concatenate([pr.local.reshape(J, 8, 3).transpose(0, 2, 1), np.ones((J, 1, 8))], axis=1)
        anc = ancestors(parent)
        pivot = np.asarray(skeleton.bind_world)[:, :3, 3]
        corners = pr.rest.reshape(J, 8, 3)
        lever = np.sqrt(((corners[:, None] - pivot[anc][:, :, None]) ** 2).sum(-1)).max(axis=2)
        return cls(skeleton, parent, depth_levels(parent), hom, anc, lever)


class Playback:
    """The decimated clip as an engine plays it, kept up to date as keys are added: local
    rotations, composed world matrices and the corner errors (squared, (K, J)). Adding keys to
    some joints re-plays those joints and re-poses only them and their descendants."""

    def __init__(
        self,
        m: PlaybackModel,
        rot: np.ndarray,
        kept: np.ndarray,
        interpolation: str,
        dense_world: np.ndarray,
        work: int = 0,
        half: Playback | None = None,
    ):
        """`half`: this clip's every other frame (rows 0, 2, …, K − 1 of an odd K) already
        played with the same keys there: its poses are taken, not recomputed (a key at 2i
        between keys at 2p and 2n slerps by (i − p) / (n − p), to the bit)."""
        self.m, self.rot, self.kept, self.interp, self.dense_world = m, rot, kept, interpolation, dense_world
        if half is None:
            self.rec = play_keys(rot, kept, interpolation)
            self.world = pose_world(m.skeleton, self.rec)
            self.err2 = corner_errors(self.world, dense_world, m.hom)
        else:  # the even frames' rotations too: the odd ones alone are slerped
            self.rec = np.empty_like(rot)
            self.rec[::2] = half.rec
            self.rec[1::2] = play_keys(rot, kept, interpolation, rows=slice(1, None, 2))
            self.world = np.empty_like(dense_world)
            self.err2 = np.empty(rot.shape[:2])
            self.world[::2], self.err2[::2] = half.world, half.err2
            self.world[1::2] = pose_world(m.skeleton, self.rec[1::2])
            self.err2[1::2] = corner_errors(self.world[1::2], dense_world[1::2], m.hom)
        self.work = work + (self.err2.size if half is None else self.err2[1::2].size)  # checked here

    def update(self, nk: np.ndarray, nj: np.ndarray, prev: np.ndarray, nxt: np.ndarray) -> None:
        """New kept keys at frames nk of joints nj (already set in `kept`), each between kept
        keys prev and nxt: their playback changes only inside (prev, nxt), and so do the poses
        of their descendants there. Re-play those joints, re-pose and re-check only those
        (frame, joint) pairs — work proportional to what changed, not to the clip."""
        m = self.m
        K, J = self.err2.shape
        changed = np.unique(nj)
        span = np.zeros((K + 1, J), dtype=np.int32)
        np.add.at(span, (prev + 1, nj), 1)
        np.add.at(span, (nxt, nj), -1)
        mask = np.cumsum(span[:K], axis=0) > 0  # (K, J) pairs to redo
        kk, col = np.nonzero(mask[:, changed])  # their own playback: only inside (prev, nxt)
        self.rec[kk, changed[col]] = play_at(
            self.rot[:, changed], self.kept[:, changed], kk, col, self.interp
        )
        for level in m.levels[1:]:  # children follow parents
            mask[:, level] |= mask[:, m.parent[level]]
        kk, jj = np.nonzero(mask)  # every pair's local matrix in one call, composed by level
        local = trs(np.asarray(m.skeleton.rest_translation)[jj], self.rec[kk, jj])
        slot = np.empty((K, J), dtype=np.int64)
        slot[kk, jj] = np.arange(kk.size)
        for level in m.levels:
            lk, col = np.nonzero(mask[:, level])
            if not lk.size:
                continue
            j = level[col]
            here = local[slot[lk, j]]
            p = m.parent[j]
            root = p < 0
            self.world[lk[root], j[root]] = here[root]
            self.world[lk[~root], j[~root]] = self.world[lk[~root], p[~root]] @ here[~root]
        diff = np.matmul((self.world[kk, jj] - self.dense_world[kk, jj])[:, :3, :], m.hom[jj])
        self.err2[kk, jj] = np.einsum("nac,nac->nc", diff, diff).max(axis=1)
        self.work += len(kk)
