"""Asset → UsdSkel (.usda text, .usdc crate, .usdz package).

Writers only serialise: everything here is a re-encoding of the Asset. Stage layout:

    /<Asset>                       Xform, kind=component, defaultPrim
        Looks/bark, Looks/leaf     UsdPreviewSurface materials (+ an st primvar reader and a
                                   UsdUVTexture per Material texture: base colour, normal map)
        LODHeuristic               LODDistanceHeuristic (only with >1 LOD, not in a .usdz)
        LODs                       Xform with the variant set "LOD" (only with >1 LOD) and
                                   LODRootAPI (not in a .usdz: AR Quick Look rejects UsdLod)
            LOD0, LOD1, ...        SkelRoot: Skeleton, SkelAnimation(s), meshes
        (LOD0)                     with a single LOD the SkelRoot sits directly under /<Asset>

Textures (texture_files.py): a .usdz packages them (`textures/<name>.png`, after the root
layer); a .usda/.usdc gets flat siblings `<stem>_<ext>_<name>.png` (`a.usdc` → `a_usdc_leaf.png`:
the extension keeps it apart from an `a.usda` or `a.obj` beside it), which staging moves into place
like a .gltf's .bin. Asset paths are "./..." relative to the layer.

Up axis (`usd_stage.Axes`): Z for .usda/.usdc (generator space as it is), Y for a .usdz (AR
Quick Look needs it). Parts: `usd_stage.py` (stages, axes, files), `usd_skel.py` (a LOD's
SkelRoot), `usd_material.py` (UsdPreviewSurface); the validator: validate.validate_usd.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..asset import Asset, Texture, lod_bounds
from ..errors import TreegenError
from .impostor_meta import describe, impostor_lod, write_sidecar
from .texture_files import TextureFiles
from .usd_material import define_material
from .usd_skel import define_skel_root
from .usd_stage import (
    Axes,
    check_suffix,
    gf_vec3f,
    identifier,
    new_stage,
    snap,
    sample_rate,
    up_axis,
    write_stage,
)


def write_usd(asset: Asset, path, textures: TextureFiles | None = None) -> None:
    """Write `asset` to exactly `path` (plus its texture files); the suffix picks text, crate
    or a usdz package. `textures`: names shared with other files written beside (a
    TextureFiles.shared view; default: named after `path`).

    The caller (exchange.export) stages it; a temp name with the right suffix works for all
    three formats.
    """
    path = Path(path)
    suffix = check_suffix(path)  # before the stage is built
    up = up_axis(asset.up_axis, suffix)
    textures = TextureFiles(path) if textures is None else textures
    stage = build_stage(asset, up, textures, lod_schemas=suffix != ".usdz")
    k = impostor_lod(asset)
    meta = None
    if k is not None:  # the atlas beside (or in) the file, described in its axes
        imp = asset.lods[k].impostor
        meta = describe(
            asset,
            k,
            Axes(up).points(np.eye(3)).T,
            {"albedo": textures.name(imp.albedo), "normal_depth": textures.name(imp.normal_depth)},
        )
        layer = stage.GetRootLayer()
        layer.customLayerData = dict(layer.customLayerData) | {
            "treegen_impostor": json.dumps(meta, sort_keys=True)
        }
    write_stage(stage, path, identifier(asset.name) + ".usdc", textures.files)
    if meta is not None:
        write_sidecar(meta | {"file": path.name}, path)


def build_stage(
    asset: Asset,
    up: str = "Z",
    textures: TextureFiles | None = None,
    lod_schemas: bool = True,
    texture_prefix: str = "",
):
    """The whole asset as an in-memory stage (one anonymous layer).

    textures: names the material textures' files (None: the materials are written without
    textures); lod_schemas: author UsdLod's LODRootAPI and heuristic (not in a .usdz);
    texture_prefix: prepended to texture names (forest prototypes)."""
    from pxr import Kind

    if not asset.lods:
        raise TreegenError(f"asset {asset.name!r}: no LODs to write")
    axes = Axes(up)
    stage, root_path = new_stage(
        asset.name, "treegen: skinned Weber-Penn tree (UsdSkel)", Kind.Tokens.component, up
    )
    if asset.extras:
        stage.GetRootLayer().customLayerData = {
            "treegen": {str(k): str(v) for k, v in sorted(asset.extras.items())}
        }

    def texture_path(tex: Texture | None) -> str | None:
        """Layer-relative ("./textures/leaf.png"), never a search path."""
        return None if tex is None or textures is None else "./" + textures.name(tex, texture_prefix)

    materials = {
        m.name: define_material(stage, root_path.AppendChild("Looks"), m, texture_path)
        for m in asset.materials
    }

    tcps = _stage_timing(stage, asset)

    if len(asset.lods) == 1:
        define_skel_root(stage, root_path.AppendChild("LOD0"), asset.lods[0], asset, materials, tcps, axes)
    else:
        _define_lod_root(stage, root_path, asset, materials, tcps, axes, lod_schemas)
    return stage


def _stage_timing(stage, asset: Asset) -> float | None:
    """timeCodesPerSecond = framesPerSecond = the clips' sample rate; start/end cover them."""
    clips = [c for lod in asset.lods for c in lod.clips if len(c.times)]
    if not clips:
        return None
    tcps = sample_rate(clips[0].times)
    end = max(float(c.times[-1]) for c in clips) * tcps
    stage.SetTimeCodesPerSecond(tcps)
    stage.SetFramesPerSecond(tcps)
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(snap(np.array([end]))[0])
    return tcps


def _define_lod_root(
    stage, root_path, asset: Asset, materials, tcps, axes: Axes, lod_schemas: bool = True
) -> None:
    """LODs as children of an LODRootAPI prim, plus a "LOD" variant set on that same prim.
    Without `lod_schemas` (a .usdz) only the variant set: the portable switch.

    Both views share one copy of the data: the LOD items are authored once, locally; each
    variant only toggles `visibility` (LODk: every other item invisible). The default selection
    LOD0 therefore gives legacy renderers exactly what the UsdLod docs recommend (default item
    visible, others invisible), while an LOD-aware renderer still sees every item active under
    the root and picks by the distance heuristic. Importers that read variant sets (Unreal)
    switch LODk to show only that item. `active` is not used for the toggle, because inactive
    items would vanish from the LOD root's children.
    """
    from pxr import UsdGeom, UsdLod, Vt

    lods_path = root_path.AppendChild("LODs")
    heur_path = root_path.AppendChild("LODHeuristic")
    lods_prim = UsdGeom.Xform.Define(stage, lods_path).GetPrim()
    names = [f"LOD{k}" for k in range(len(asset.lods))]
    bounds = []
    for name, lod in zip(names, asset.lods):
        define_skel_root(stage, lods_path.AppendChild(name), lod, asset, materials, tcps, axes)
        bounds.append(lod_bounds(lod))

    if lod_schemas:
        lod_root = UsdLod.RootAPI.Apply(lods_prim)
        lod_root.CreateLodDefaultIndexAttr(0)
        lod_root.CreateLodHeuristicsRel().SetTargets([heur_path])
        heur = UsdLod.DistanceHeuristic.Define(stage, heur_path)
        heur.CreateLodDomainAttr(UsdLod.Tokens.imaging)
        lo, hi = axes.box(*bounds[0])
        heur.CreateCenterAttr(gf_vec3f(0.5 * (lo + hi)))  # LOD root space = tree space
        # thresholds: LOD k (k ≥ 1) is used from Lod.distance on
        heur.CreateThresholdsAttr(Vt.FloatArray([float(lod.distance) for lod in asset.lods[1:]]))

    vset = lods_prim.GetVariantSets().AddVariantSet("LOD")
    for k, name in enumerate(names):
        vset.AddVariant(name)
    for k, name in enumerate(names):
        vset.SetVariantSelection(name)
        with vset.GetVariantEditContext():
            for other in names:
                if other != name:
                    over = stage.OverridePrim(lods_path.AppendChild(other))
                    UsdGeom.Imageable(over).CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    vset.SetVariantSelection(names[0])
    # child order is the LOD index; variant overs would otherwise be composed first
    lods_prim.SetChildrenReorder(names)
