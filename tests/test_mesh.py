"""Bark tubes and leaf cards: counts from formulas, skin bindings, normals, UVs, leaf area."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from synthetic_tree import species_tree, synthetic_tree, trunk_only
from test_rig import compose
from treegen_cli.errors import TreegenError
from treegen_cli.leafshapes import OUTLINES, TRIANGLE_CARD, fill_factor, in_triangle_card, triangle_share
from treegen_cli.mesh import CARD, MeshOptions, bark_offsets, build_mesh, merge_influences
from treegen_cli.rig import RigOptions, build_rig


def mesh(tree, budget=256, **opts):
    rig = build_rig(tree, RigOptions(max_joints=budget))
    prims = {p.name: p for p in build_mesh(tree, rig, MeshOptions(**opts))}
    return rig, prims


def expected_bark_counts(
    tree,
    sides,
    rings_per_segment,
    thin_radius=0.002,
    thin_sides=3,
    point_radius=1e-4,
    point_ratio=0.02,
    extra_trunk_rings=0,
):
    """Per stem: rings = segments·m + 1 (minus the tip ring of a pointed stem), each with
    sides + 1 vertices, plus one apex; triangles = 2·sides per ring gap + a fan of sides."""
    lev = np.minimum(tree.stem_level, len(sides) - 1)
    n_sides = np.where(tree.stem_radius < thin_radius, thin_sides, np.asarray(sides)[lev])
    m = np.asarray(rings_per_segment)[np.minimum(tree.stem_level, len(rings_per_segment) - 1)]
    rings = (tree.stem_node_count - 1) * m + 1
    rings[0] += extra_trunk_rings
    tips = tree.stem_node_start + tree.stem_node_count - 1
    rings -= tree.node_radius[tips] < np.maximum(point_radius, point_ratio * tree.stem_radius)
    verts = rings * (n_sides + 1) + 1
    tris = (rings - 1) * n_sides * 2 + n_sides
    return int(verts.sum()), int(tris.sum())


def skin(prim, skel, world):
    """Linear blend skinning with skinning matrices world_j · inv(bind_j)."""
    M = world @ np.linalg.inv(skel.bind_world)
    P = np.c_[prim.positions.astype(np.float64), np.ones(len(prim.positions))]
    out = np.zeros((len(P), 4))
    for k in range(4):
        out += prim.weights[:, k, None] * np.einsum("vij,vj->vi", M[prim.joints[:, k]], P)
    return out[:, :3]


def descendants(parent, j):
    mask = np.zeros(len(parent), dtype=bool)
    mask[j] = True
    for i in range(j + 1, len(parent)):  # parents come first
        mask[i] = mask[parent[i]]
    return mask


def triangle_normals(prim):
    tri = prim.positions[prim.indices.reshape(-1, 3)].astype(np.float64)
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def check_prim(prim, n_joints):
    V = len(prim.positions)
    assert prim.positions.dtype == np.float32 and prim.normals.dtype == np.float32
    assert prim.uvs.dtype == np.float32 and prim.indices.dtype == np.uint32
    assert prim.joints.dtype == np.uint16 and prim.weights.dtype == np.float32
    assert prim.normals.shape == (V, 3) and prim.uvs.shape == (V, 2)
    assert prim.joints.shape == (V, 4) and prim.weights.shape == (V, 4)
    assert len(prim.indices) % 3 == 0 and prim.indices.max() < V
    assert np.isin(np.arange(V), prim.indices).all()  # no stray vertices
    for a in (prim.positions, prim.normals, prim.uvs, prim.weights):
        assert np.isfinite(a).all()
    np.testing.assert_allclose(np.linalg.norm(prim.normals, axis=1), 1.0, atol=1e-5)
    # Every vertex bound: weights sum to 1, sorted, valid joints, unused slots (0, 0.0).
    w = prim.weights
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-6)
    assert np.all(w >= 0) and np.all(np.diff(w, axis=1) <= 0)
    assert prim.joints.max() < n_joints
    assert np.all(prim.joints[w == 0] == 0)
    # Counter-clockwise fronts: every non-degenerate face agrees with its vertex normals.
    fn = triangle_normals(prim)
    vn = prim.normals[prim.indices.reshape(-1, 3)].sum(axis=1)
    big = np.linalg.norm(fn, axis=1) > 1e-10
    assert np.all(np.einsum("ij,ij->i", fn[big], vn[big]) > 0)


def test_counts_follow_the_formulas():
    tree = synthetic_tree()
    rig, prims = mesh(tree)
    bark = prims["bark"]
    V, T = expected_bark_counts(tree, (16, 8, 6, 4, 3), (2, 1))
    assert (len(bark.positions), len(bark.indices) // 3) == (V, T)
    # Leaves: a 4-vertex, 2-triangle card each by default; the LeafShape outline on request.
    assert len(prims["leaves"].positions) == 4 * tree.n_leaves
    assert len(prims["leaves"].indices) // 3 == 2 * tree.n_leaves
    _, p1 = mesh(tree, leaf_geometry="shape")
    o = OUTLINES[0]
    assert len(p1["leaves"].positions) == tree.n_leaves * len(o.points)
    assert len(p1["leaves"].indices) // 3 == tree.n_leaves * len(o.triangles)
    # Other options: coarser rings, more sides; the 1 mm twig stays, with thin_sides.
    _, p2 = mesh(tree, sides=(7, 5), rings_per_segment=(1, 3), thin_sides=4)
    V, T = expected_bark_counts(tree, (7, 5), (1, 3), thin_sides=4)
    assert (len(p2["bark"].positions), len(p2["bark"].indices) // 3) == (V, T)


def test_lobes_and_flare_add_trunk_detail():
    tree = synthetic_tree(lobes=5, lobe_depth=0.1, flare=0.8)
    _, prims = mesh(tree)
    # Five lobes need 4 samples each: the trunk and its clone get 20 sides; flare adds 4 rings.
    V, T = expected_bark_counts(tree, (20, 8, 6, 4, 3), (2, 1), extra_trunk_rings=4)
    assert (len(prims["bark"].positions), len(prims["bark"].indices) // 3) == (V, T)
    # Flare: the base ring is Flare·0.99 wider than the node radius trend, and it narrows fast.
    trunk = trunk_only(flare=0.8)
    bark = build_mesh(trunk, build_rig(trunk))[0]
    p = bark.positions.astype(np.float64)
    r = np.hypot(p[:, 0], p[:, 1])
    base = r[np.abs(p[:, 2]) < 1e-6].max()
    np.testing.assert_allclose(base, 0.4, rtol=1e-6)  # node radius at the base
    ring1 = r[(p[:, 2] > 0.05) & (p[:, 2] < 0.2)]
    assert ring1.size and np.all(ring1 < 0.4 * 0.99) and np.all(ring1 > 0.0)


@pytest.mark.parametrize("sides", [3, 4, 6])
def test_a_lods_few_sides_are_as_wide_on_average_as_lod0s(sides):
    """match_sides (a LOD's: LOD0's table) widens each ring so the prism is, averaged over the
    directions it is seen from, as wide as LOD0's 16-sided one; without it a square trunk is
    0.90 and a triangle 0.83 as wide, and the trunk visibly thins when a far LOD takes over."""
    trunk = trunk_only()
    rig = build_rig(trunk)

    def mean_width(options):
        p = build_mesh(trunk, rig, options)[0].positions.astype(np.float64)
        ring = p[np.abs(p[:, 2]) < 1e-6][:, :2]  # the base ring
        a = np.linspace(0.0, np.pi, 720, endpoint=False)
        proj = ring @ np.stack([np.cos(a), np.sin(a)])  # (vertices, directions)
        return float(np.mean(proj.max(axis=0) - proj.min(axis=0)))

    lod0 = mean_width(MeshOptions(sides=(16,)))
    widened = mean_width(MeshOptions(sides=(sides,), match_sides=(16,)))
    plain = mean_width(MeshOptions(sides=(sides,)))
    np.testing.assert_allclose(widened, lod0, rtol=2e-3)
    np.testing.assert_allclose(
        plain / lod0, sides * np.sin(np.pi / sides) / (16 * np.sin(np.pi / 16)), rtol=2e-3
    )
    assert plain < 0.97 * lod0
    np.testing.assert_allclose(mean_width(MeshOptions(sides=(16,), match_sides=(16,))), lod0, rtol=1e-9)


@pytest.mark.parametrize("lobes,depth", [(0, 0.0), (5, 0.1), (9, 0.03)])
def test_trunk_normals_point_outward_and_v_runs_up(lobes, depth):
    tree = trunk_only(lobes=lobes, lobe_depth=depth, flare=0.5)
    rig = build_rig(tree)
    bark = build_mesh(tree, rig)[0]
    check_prim(bark, len(rig.joint_node))
    p, n, uv = (a.astype(np.float64) for a in (bark.positions, bark.normals, bark.uvs))
    ring = np.hypot(p[:, 0], p[:, 1]) > 1e-6  # all but the tip apex
    radial = p[ring] * [1, 1, 0]
    assert np.all(np.einsum("ij,ij->i", n[ring], radial) > 0)
    # Lobed radius r·(1 + LobeDepth·sin(Lobes·θ)) around the axis.
    z0 = np.abs(p[:, 2] - 2.0) < 1e-6  # the ring at trunk node 1
    r = np.hypot(p[z0, 0], p[z0, 1]) / 0.3
    off_u, off_v = bark_offsets(tree)[0]
    theta = 2 * np.pi * (uv[z0, 0] - off_u)
    np.testing.assert_allclose(r, 1 + depth * np.sin(lobes * theta), atol=1e-5)
    # u wraps once around (seam column duplicated) from the stem's offset; v grows with height
    # (metres / (2π·base radius)) from its offset, shifted by whole tiles to centre on 0.
    np.testing.assert_allclose([uv[ring, 0].min(), uv[ring, 0].max()], [off_u, off_u + 1], atol=1e-6)
    order = np.argsort(p[:, 2], kind="stable")
    assert np.all(np.diff(uv[order, 1]) >= -1e-6)
    v = p[ring, 2] / (2 * np.pi * 0.4) + off_v
    shift = uv[ring, 1] - v
    np.testing.assert_allclose(shift, np.round(shift[0]), atol=1e-5)


@pytest.mark.parametrize("budget", [1, 2, 5, 9, 256])
def test_every_vertex_bound_and_moving_a_joint_moves_only_its_descendants(budget):
    tree = synthetic_tree()
    rig, prims = mesh(tree, budget=budget)
    skel = rig.skeleton
    J = len(skel.names)
    for prim in prims.values():
        check_prim(prim, J)
        # Rest pose: identity skinning matrices reproduce the positions.
        np.testing.assert_allclose(skin(prim, skel, skel.bind_world), prim.positions, atol=1e-5)
    if J < 2:
        return
    j = J // 2 if J > 2 else 1
    q = skel.rest_rotation.copy()
    q[j] = (Rotation.from_euler("xz", [25, 10], degrees=True) * Rotation.from_quat(q[j])).as_quat()
    t = skel.rest_translation.copy()
    t[j] += [0.05, -0.03, 0.02]
    world = compose(skel, q, t)
    desc = descendants(skel.parent, j)
    for prim in prims.values():
        moved = np.linalg.norm(skin(prim, skel, world) - prim.positions, axis=1) > 1e-5
        touched = (desc[prim.joints] & (prim.weights > 0)).any(axis=1)
        only = (desc[prim.joints] | (prim.weights == 0)).all(axis=1)
        assert not np.any(moved & ~touched)  # nothing outside the subtree moves
        assert np.all(moved[only])  # geometry wholly on the subtree moves


@pytest.mark.parametrize("geometry,P", [("card", 4), ("shape", len(OUTLINES[0].points))])
def test_leaves_take_their_carrier_rigidly(geometry, P):
    tree = synthetic_tree()
    rig, prims = mesh(tree, budget=5, leaf_geometry=geometry)
    leaves = prims["leaves"]
    np.testing.assert_array_equal(leaves.joints[:, 0], np.repeat(rig.leaf_joint, P))
    assert np.all(leaves.weights[:, 0] == 1)
    # Normals are the leaf frames' column 2 (flat card, two-sided material).
    np.testing.assert_allclose(leaves.normals, np.repeat(tree.leaf_frame[:, :, 2], P, axis=0), atol=1e-6)
    # Card UVs span 0..1 and the blade base sits at leaf_pos.
    assert leaves.uvs.min() >= 0 and leaves.uvs.max() <= 1
    o = CARD if geometry == "card" else OUTLINES[0]
    base = o.points[:, 1] == 0  # the base point (outline) or base edge (card)
    np.testing.assert_allclose(
        leaves.positions.reshape(-1, P, 3)[:, base].mean(axis=1), tree.leaf_pos, atol=1e-6
    )


@pytest.mark.parametrize("shape", sorted(OUTLINES))
def test_leaf_shape_area_matches_tree_leaf_area(shape):
    """Outline geometry draws exactly the physical blade area the wind model uses."""
    tree = synthetic_tree(leaf_shape=shape)
    rig, prims = mesh(tree, leaf_geometry="shape")
    leaves = prims["leaves"]
    check_prim(leaves, len(rig.joint_node))
    area = 0.5 * np.linalg.norm(triangle_normals(leaves), axis=1).sum()
    np.testing.assert_allclose(area, tree.leaf_area.sum(), rtol=1e-4)
    assert 0.25 < fill_factor(shape) <= 1.0
    assert leaves.uvs.min() >= 0 and leaves.uvs.max() <= 1


@pytest.mark.parametrize("shape", sorted(OUTLINES))
def test_leaf_cards_are_length_by_width_quads(shape):
    """Cards draw length × width whatever the LeafShape (its outline lives in the texture);
    Tree.leaf_area stays the blade area: card area × fill_factor."""
    tree = synthetic_tree(leaf_shape=shape)
    rig, prims = mesh(tree)
    leaves = prims["leaves"]
    check_prim(leaves, len(rig.joint_node))
    length, width = tree.leaf_size[:, 0], tree.leaf_size[:, 1]
    area = 0.5 * np.linalg.norm(triangle_normals(leaves), axis=1)
    np.testing.assert_allclose(area.reshape(-1, 2).sum(axis=1), length * width, rtol=1e-4)
    np.testing.assert_allclose(area.sum() * fill_factor(shape), tree.leaf_area.sum(), rtol=1e-4)
    # Corners: base at leaf_pos ± width/2 along frame column 0, tip + length along column 1.
    F = tree.leaf_frame
    corners = (
        tree.leaf_pos[:, None, :]
        + (width[:, None] * CARD.points[None, :, 0])[:, :, None] * F[:, None, :, 0]
        + (length[:, None] * CARD.points[None, :, 1])[:, :, None] * F[:, None, :, 1]
    )
    np.testing.assert_allclose(leaves.positions.reshape(-1, 4, 3), corners, atol=1e-5)
    # UVs: the four corners of the 0..1 texture, the same on every card.
    uv = leaves.uvs.reshape(-1, 4, 2)
    assert np.all(uv == uv[:1])
    assert sorted(map(tuple, uv[0].tolist())) == [(0, 0), (0, 1), (1, 0), (1, 1)]


def test_merge_influences_merges_sorts_and_normalises():
    J, W = merge_influences(
        np.array([[3, 5, 3, 0], [2, 2, 2, 2]]), np.array([[0.2, 0.3, 0.5, 0.0], [0.25, 0.25, 0.25, 0.25]])
    )
    np.testing.assert_array_equal(J, [[3, 5, 0, 0], [2, 0, 0, 0]])
    np.testing.assert_allclose(W, [[0.7, 0.3, 0, 0], [1, 0, 0, 0]], atol=1e-7)


def test_bad_options_are_user_errors():
    tree = synthetic_tree()
    rig = build_rig(tree)
    with pytest.raises(TreegenError, match="sides"):
        build_mesh(tree, rig, MeshOptions(sides=(8, 2)))
    with pytest.raises(TreegenError, match="rings"):
        build_mesh(tree, rig, MeshOptions(rings_per_segment=(0,)))
    with pytest.raises(TreegenError, match="LeafShape"):
        build_mesh(synthetic_tree(leaf_shape=42), rig)
    with pytest.raises(TreegenError, match="leaf-geometry"):
        build_mesh(tree, rig, MeshOptions(leaf_geometry="sprite"))


@pytest.mark.parametrize("species", ["quaking_aspen", "black_tupelo"])
def test_species_mesh_is_bound_and_keeps_every_stem(species):
    tree = species_tree(species, seed=2)
    rig, prims = mesh(tree, budget=64)
    for prim in prims.values():
        check_prim(prim, len(rig.joint_node))
    # One apex per stem closes the bark (stems are never dropped), last in the vertex list.
    bark = prims["bark"]
    tips = tree.stem_node_start + tree.stem_node_count - 1
    apex = bark.positions[-tree.n_stems :].astype(np.float64)
    gap = np.linalg.norm(apex - tree.node_pos[tips], axis=1)
    assert np.all(gap <= 0.5 * tree.node_radius[tips] + 1e-5)
    lobed = tree.params.lobes > 0 and tree.params.lobe_depth != 0
    trunk_sides = max(16, 4 * tree.params.lobes) if lobed else 16
    V, T = expected_bark_counts(
        tree, (trunk_sides, 8, 6, 4, 3), (2, 1), extra_trunk_rings=4 if tree.params.flare > 0 else 0
    )
    assert (len(bark.positions), len(bark.indices) // 3) == (V, T)
    area = 0.5 * np.linalg.norm(triangle_normals(prims["leaves"]), axis=1).sum()
    np.testing.assert_allclose(area, np.prod(tree.leaf_size, axis=1).sum(), rtol=1e-3)


# ------------------------------------------------------------------------------ texture UVs


def atlas_cells(variants=4):
    """A real atlas layout (glTF rects, top-left origin), as the materials stage hands it over."""
    from treegen_cli.texture_leaf import leaf_atlas

    rects = leaf_atlas(0, (0.16, 0.30, 0.06), size=128, variants=variants).rects
    return tuple(tuple(float(x) for x in r) for r in rects)


@pytest.mark.parametrize("geometry", ["card", "shape"])
def test_leaf_uvs_fill_their_seeded_atlas_cell(geometry):
    """Every leaf's points land in one cell of the atlas (in the asset's bottom-left UVs), the
    card's corners on the cell's corners; all cells get used, about equally."""
    tree = species_tree("quaking_aspen", seed=1)
    cells = atlas_cells(4)
    _, prims = mesh(tree, budget=32, leaf_geometry=geometry, leaf_cells=cells)
    leaves = prims["leaves"]
    o = CARD if geometry == "card" else OUTLINES[0]
    P = len(o.points)
    uv = leaves.uvs.astype(np.float64).reshape(-1, P, 2)
    r = np.asarray(cells)
    # Bottom-left cell bounds: u0..u1, 1 − v1..1 − v0.
    lo = np.column_stack([r[:, 0], 1 - r[:, 3]])
    hi = np.column_stack([r[:, 2], 1 - r[:, 1]])
    inside = np.all(
        (uv[:, None] >= lo[None, :, None] - 1e-6) & (uv[:, None] <= hi[None, :, None] + 1e-6), axis=(2, 3)
    )  # (L, cells)
    assert np.all(inside.sum(axis=1) == 1)  # one cell per leaf, disjoint
    variant = inside.argmax(axis=1)
    # Card u = x + .5, v = y (base at the cell's bottom edge): affine into the leaf's cell.
    want = lo[variant][:, None] + o.uvs[None] * (hi - lo)[variant][:, None]
    np.testing.assert_allclose(uv, want, atol=1e-6)
    counts = np.bincount(variant, minlength=4)
    assert counts.min() > 0.2 * tree.n_leaves


def test_triangle_cards_draw_the_cards_base_and_tip():
    """A far LOD's triangle cards: per leaf one triangle, the card's two base corners and its
    tip's middle (positions, and UVs at the same points of the leaf's atlas cell), half the
    card's area, facing as the card does."""
    tree = species_tree("quaking_aspen", seed=1)
    cells = atlas_cells(4)
    rig, card = mesh(tree, budget=32, leaf_cells=cells)
    _, tri = mesh(tree, budget=32, leaf_cells=cells, leaf_geometry="triangle")
    card, tri = card["leaves"], tri["leaves"]
    check_prim(tri, len(rig.joint_node))
    L = tree.n_leaves
    assert len(tri.positions) == 3 * L and len(tri.indices) == 3 * L
    quad, three = card.positions.reshape(L, 4, 3), tri.positions.reshape(L, 3, 3)
    np.testing.assert_allclose(three[:, :2], quad[:, :2], atol=1e-6)  # the base corners
    np.testing.assert_allclose(three[:, 2], quad[:, 2:].mean(axis=1), atol=1e-6)  # the tip's middle
    uq, ut = card.uvs.reshape(L, 4, 2), tri.uvs.reshape(L, 3, 2)
    np.testing.assert_allclose(ut[:, :2], uq[:, :2], atol=1e-6)
    np.testing.assert_allclose(ut[:, 2], uq[:, 2:].mean(axis=1), atol=1e-6)
    np.testing.assert_array_equal(tri.joints[::3, 0], rig.leaf_joint)
    area = 0.5 * np.linalg.norm(triangle_normals(tri), axis=1)
    np.testing.assert_allclose(
        area, TRIANGLE_CARD.area * tree.leaf_size[:, 0] * tree.leaf_size[:, 1], rtol=1e-4
    )
    assert np.all(np.einsum("ij,ij->i", triangle_normals(tri), tree.leaf_frame[:, :, 2]) > 0)  # front up


@pytest.mark.parametrize("shape", sorted(OUTLINES))
def test_triangle_share_is_the_blade_inside_the_triangle_card(shape):
    """triangle_share: the blade's area inside TRIANGLE_CARD over its whole area, and the
    cut part's centroid below the blade's; the full card (shape 4) keeps exactly half, its
    cut part's centroid a third of the way up against the card's half."""
    share, dy = triangle_share(shape)
    assert 0.45 < share < 0.9 and dy < 0
    # the same share of the generated atlas's alpha (what a triangle card draws)
    from treegen_cli.texture_leaf import _coverage

    alpha, _inside = _coverage(shape, 200, 200)  # tip at row 0
    x, y = np.meshgrid((np.arange(200) + 0.5) / 200 - 0.5, 1.0 - (np.arange(200) + 0.5) / 200)
    assert alpha[in_triangle_card(x, y)].sum() / alpha.sum() == pytest.approx(share, abs=0.01)
    if shape == 4:
        assert share == pytest.approx(0.5, abs=1e-3) and dy == pytest.approx(1 / 3 - 1 / 2, abs=2e-3)


def test_leaf_variants_are_seeded_by_the_tree():
    from treegen_cli.mesh import leaf_variants

    a, b = species_tree("quaking_aspen", seed=1), species_tree("quaking_aspen", seed=2)
    cells = atlas_cells(4)
    u1 = mesh(a, budget=32, leaf_cells=cells)[1]["leaves"].uvs
    np.testing.assert_array_equal(u1, mesh(a, budget=32, leaf_cells=cells)[1]["leaves"].uvs)
    v1, v2 = leaf_variants(a, 4), leaf_variants(b, 4)
    assert not np.array_equal(v1[:1000], v2[:1000])
    assert np.all(leaf_variants(a, 1) == 0)
    # Neighbouring leaves rarely share a variant more than chance says (not a run of one).
    assert np.mean(v1[1:] == v1[:-1]) < 0.35


def test_single_cell_maps_the_card_to_the_whole_image():
    """A custom leaf texture is one cell: the card's corners are the image's corners."""
    tree = synthetic_tree()
    _, prims = mesh(tree, leaf_cells=((0.0, 0.0, 1.0, 1.0),))
    uv = prims["leaves"].uvs.reshape(-1, 4, 2)
    np.testing.assert_array_equal(uv, np.broadcast_to(CARD.uvs, uv.shape))


def test_bad_leaf_cells_are_refused():
    tree = synthetic_tree()
    with pytest.raises(ValueError, match="leaf_cells"):
        mesh(tree, leaf_cells=())
    with pytest.raises(ValueError, match="leaf_cells"):
        mesh(tree, leaf_cells=((0.0, 0.0, 1.0),))


def bark_layout(tree, bark, sides=(16, 8, 6, 4, 3), m=(2, 1)):
    """Per stem: its vertex ranges in the bark primitive (ring vertices, then one apex per stem
    at the end), from the counting formulas that test_counts_follow_the_formulas checks."""
    lobed = tree.params.lobes > 0 and tree.params.lobe_depth != 0
    sides = (max(sides[0], 4 * tree.params.lobes) if lobed else sides[0],) + tuple(sides[1:])
    lev = np.minimum(tree.stem_level, len(sides) - 1)
    n = np.where(tree.stem_radius < 0.002, 3, np.asarray(sides)[lev])
    mm = np.asarray(m)[np.minimum(tree.stem_level, len(m) - 1)]
    rings = (tree.stem_node_count - 1) * mm + 1
    trunks = np.flatnonzero((tree.stem_level == 0) & ~tree.stem_clone)
    rings[trunks] += 4 if tree.params.flare > 0 else 0
    tips = tree.stem_node_start + tree.stem_node_count - 1
    rings -= tree.node_radius[tips] < np.maximum(1e-4, 0.02 * tree.stem_radius)
    verts = rings * (n + 1)
    assert verts.sum() + tree.n_stems == len(bark.positions)
    return rings, n, np.cumsum(verts) - verts


@pytest.mark.parametrize("species", ["quaking_aspen", "black_tupelo", "ca_black_oak", "palm"])
def test_bark_v_grows_along_every_stem_within_half_float_range(species):
    """v continuous and increasing ring by ring up to the apex (no wraps), u once around from
    the stem's offset, |uv| small enough for half floats (also after glTF's 1 − v), and the
    stems' offsets all different."""
    from treegen_cli.mesh import BARK_MAX_TILES

    tree = species_tree(species, seed=0)
    _, prims = mesh(tree, budget=64, leaves=False)
    bark = prims["bark"]
    uv = bark.uvs.astype(np.float64)
    assert np.abs(uv).max() <= 64 and np.abs(1 - uv[:, 1]).max() <= 64
    assert np.abs(uv[:, 1]).max() <= BARK_MAX_TILES / 2 + 1 and uv[:, 0].min() >= 0
    rings, n, v0 = bark_layout(tree, bark)
    S = tree.n_stems
    # Per ring: the v of its first vertex, the same across the ring; u from off to off + 1.
    ring_stem = np.repeat(np.arange(S), rings)
    k = np.arange(ring_stem.size) - np.repeat(np.cumsum(rings) - rings, rings)
    first = v0[ring_stem] + k * (n[ring_stem] + 1)
    last = first + n[ring_stem]
    v_ring = uv[first, 1]
    np.testing.assert_allclose(uv[last, 1], v_ring, atol=1e-5)
    np.testing.assert_allclose(uv[last, 0] - uv[first, 0], 1.0, atol=1e-5)
    same = ring_stem[1:] == ring_stem[:-1]
    assert np.all(np.diff(v_ring)[same] > 0)
    apex_v = uv[len(uv) - S :, 1]
    ring_top = v_ring[np.cumsum(rings) - 1]
    assert np.all(apex_v >= ring_top - 1e-6)
    # Tiles no taller than the base circumference unless the stem is a long whip.
    tiles = apex_v - v_ring[np.cumsum(rings) - rings]
    span = tree.node_z[tree.stem_node_start + tree.stem_node_count - 1] - tree.node_z[tree.stem_node_start]
    short = span / (2 * np.pi * tree.stem_radius) < BARK_MAX_TILES - 2
    assert np.all(tiles[short] >= span[short] / (2 * np.pi * tree.stem_radius[short]) - 1e-3)
    assert np.all(tiles <= BARK_MAX_TILES + 1e-3)
    # Offsets: per stem, the fractional v at its base and its u at column 0 are the stem's
    # seeded offsets, spread over [0, 1) and different from stem to stem.
    want = bark_offsets(tree)
    dv = np.mod(v_ring[np.cumsum(rings) - rings] - want[:, 1] + 0.5, 1.0) - 0.5
    assert np.abs(dv).max() < 1e-4
    np.testing.assert_allclose(uv[v0, 0], want[:, 0], atol=1e-6)
    assert len(np.unique(want)) == want.size and want.min() >= 0 and want.max() < 1
    assert np.mean(np.abs(np.diff(want[:, 1])) < 0.01) < 0.05


@pytest.mark.parametrize("lobes,depth", [(0, 0.0), (5, 0.1)])
def test_bark_tangents_follow_u_and_their_bitangent_follows_v(lobes, depth):
    """glTF TANGENT for the bark normal map: unit, orthogonal to the normal, along +u; w·(n × t)
    points up the stem, where v grows. Checked against each triangle's own UV gradient."""
    tree = trunk_only(lobes=lobes, lobe_depth=depth, flare=0.5)
    bark = build_mesh(tree, build_rig(tree))[0]
    t = bark.tangents.astype(np.float64)
    n = bark.normals.astype(np.float64)
    assert t.shape == (len(bark.positions), 4) and np.all(np.abs(t[:, 3]) == 1)
    np.testing.assert_allclose(np.linalg.norm(t[:, :3], axis=1), 1.0, atol=1e-5)
    assert np.abs(np.einsum("ij,ij->i", t[:, :3], n)).max() < 1e-5
    # Per triangle: dP/du and dP/dv from positions and UVs.
    tri = bark.indices.reshape(-1, 3)
    P, UV = bark.positions.astype(np.float64)[tri], bark.uvs.astype(np.float64)[tri]
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    d1, d2 = UV[:, 1] - UV[:, 0], UV[:, 2] - UV[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    ok = np.abs(det) > 1e-9  # not the apex fans' slivers
    dPdu = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / det[:, None]
    dPdv = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / det[:, None]
    tv, nv = t[tri[:, 0]], n[tri[:, 0]]
    bv = np.cross(nv, tv[:, :3]) * tv[:, 3:4]
    assert np.all(np.einsum("ij,ij->i", tv[ok, :3], dPdu[ok]) > 0)
    assert np.all(np.einsum("ij,ij->i", bv[ok], dPdv[ok]) > 0)


@pytest.mark.parametrize("species", ["quaking_aspen", "shave_grass"])
def test_thin_branches_are_drawn_as_crossed_ribbons(species):
    """MeshOptions.ribbon_radius (a far LOD's, lod_budget.RIBBON_PX): branches of at most 4
    sides thinner than it at their base leave the bark's tubes for the "twigs" primitive, two
    crossed ribbons, as wide as a square tube through the circle: 4 vertices a ring and 2 at a
    pointed tip, 4 triangles between rings and 2 to the tip, as limits estimates them (the
    budgets count on it). Fronts agree with their normals (check_prim: a renderer lights the
    face it sees by its normal; the other way round, every twig of the desert bush's far LOD
    was drawn unlit). ribbons_as_tubes joins them into square tubes through the same
    vertices: open only round their base (and a blunt tip's) ring, normals outwards."""
    from treegen_cli.limits import bark_triangles, estimate_vertices
    from treegen_cli.mesh import pointed_tips, ribbons_as_tubes
    from treegen_cli.mesh.bark import ring_counts
    from treegen_cli.mesh.options import ribbon_stems

    tree = species_tree(species, seed=2)
    options = MeshOptions(
        sides=(8, 4, 3), ribbon_radius=float(np.median(tree.stem_radius[tree.stem_level > 0]))
    )
    rig = build_rig(tree, RigOptions(max_joints=64))
    prims = {p.name: p for p in build_mesh(tree, rig, options)}
    ribbon = ribbon_stems(tree, options)
    assert 0 < ribbon.sum() < tree.n_stems and not ribbon[tree.stem_level == 0].any()
    twigs, bark = prims["twigs"], prims["bark"]
    for prim in (twigs, bark):
        check_prim(prim, len(rig.joint_node))
    pointed = pointed_tips(tree, options)[ribbon]
    rings = ring_counts(tree, options)[ribbon] - pointed
    assert len(twigs.positions) == int((4 * rings + 2 * pointed).sum())
    assert len(twigs.indices) // 3 == int((4 * (rings - 1) + 2 * pointed).sum())
    drawn_v = sum(len(p.positions) for p in (bark, twigs))
    drawn_t = sum(len(p.indices) // 3 for p in (bark, twigs))
    assert (drawn_v, drawn_t) == (
        estimate_vertices(tree, options)[0],
        int(bark_triangles(tree, options).sum()),
    )
    # each ring's ribbons cross at right angles, each as wide as the square through its circle
    ring = twigs.positions[: 4 * int(rings.sum())].reshape(-1, 4, 3).astype(np.float64)
    x, y = ring[:, 1] - ring[:, 0], ring[:, 3] - ring[:, 2]
    assert np.allclose(np.einsum("ij,ij->i", x, y), 0.0, atol=1e-6)
    assert np.allclose(
        np.linalg.norm(x, axis=1), np.linalg.norm(y, axis=1), rtol=1e-3, atol=1e-5
    )  # (float32)
    tube = ribbons_as_tubes(twigs)
    tri = tube.indices.reshape(-1, 3).astype(np.int64)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    edge, uses = np.unique(edges, axis=0, return_counts=True)
    assert np.all(uses <= 2)
    assert np.all(edge[uses == 1] // 4 == edge[uses == 1][:, :1] // 4)  # open only round a ring
    fn = triangle_normals(tube)
    big = np.linalg.norm(fn, axis=1) > 1e-10
    assert np.all(np.einsum("ij,ij->i", fn[big], tube.normals[tri[big]].sum(axis=1)) > 0)
