"""Tree → skeleton whose joints are stem nodes, under a joint budget.  (contract; to implement)"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .asset import Skeleton


@dataclass(frozen=True, eq=False)
class Rig:
    skeleton: Skeleton
    joint_node: np.ndarray     # int32 (J,): the tree node each joint sits on
    joint_stem: np.ndarray     # int32 (J,): the stem that node belongs to
    node_joints: np.ndarray    # uint16 (N, 2): skin binding of a point at each node: the jointed
    node_weights: np.ndarray   # float32 (N, 2)  nodes enclosing it on its chain, weights sum 1
                               # (rigidly carried nodes: (carrier, 0) with weights (1, 0))
    leaf_joint: np.ndarray     # uint16 (L,): joint carrying each leaf rigidly
    stem_joint: np.ndarray     # int32 (S,): joint carrying the stem's base (its attach joint)
