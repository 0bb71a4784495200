"""Forest → one USD stage: each prototype written once, trees as instanceable references.

    /<Forest>                 Xform, kind=assembly, defaultPrim
        Prototypes            class prim (abstract: never drawn itself)
            <species>_s<seed>[_lod<k>]   the tree as exchange.usd writes it (Looks, SkelRoot(s))
        Trees                 Xform, kind=group
            tree0000          Xform: translate, rotateZ, scale; instanceable; an internal
                              reference to its prototype with a layer offset (its phase)

Phase variety at no data cost: each prototype's clip is written over two periods (one extra
copy per prototype, not per tree) and tree i references it with layer offset −o_i (o_i its
time offset in whole frames), so over the stage's one-period range it plays [o_i, o_i + T],
which loops seamlessly because the clip is periodic. Whole-frame offsets keep the number of
distinct instancing prototypes bounded (≤ frames per loop per prototype).

With `all_lods` (the default) a prototype keeps all its LODs (LODRootAPI + exchange.usd's "LOD"
variant set, lifted to the prototype's root so each tree has the set itself: LOD0 by default,
any tree switchable, still instanced); otherwise one prototype prim per (prototype, LOD) used.

Textures and axes as exchange.usd: a .usdz packages the textures and is Y up (instances then
translate by the converted position and turn about +Y), a .usda/.usdc keeps Z up with the
textures beside it; texture names carry their prototype's name (`<stem>_<ext>_<prototype>_leaf.png`,
`grove.usdc` → `grove_usdc_palm_s2_leaf.png`; texture_files.py).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import TreegenError
from ..asset import Forest
from ..axes import to_y_up
from .texture_files import TextureFiles
from .usd import build_stage
from .usd_stage import check_suffix, identifier, new_stage, sample_rate, snap, up_axis, write_stage


def _prototype_asset(forest: Forest, p: int, lods: list[int], loop: bool):
    """Prototype p with only `lods`; its clips over two periods (Forest.looped) when looping."""
    asset = forest.looped[p] if loop else forest.prototypes[p]
    return replace(asset, lods=[asset.lods[k] for k in lods])


def _lift_lod_variants(layer, proto, n: int) -> None:
    """Give the prototype's root prim the "LOD" variant set, so every tree that references it
    has one of its own: variant LODk selects LODk of the inner LODs prim (exchange.usd's set,
    whose own default selection is dropped so the outer one decides). LOD0 is the default; an
    engine or a user picks per tree (`tree0042{LOD=LOD2}`), which stays instanceable (the
    selection is part of the instance's key)."""
    from pxr import Sdf

    spec = layer.GetPrimAtPath(proto)
    inner = layer.GetPrimAtPath(proto.AppendChild("LODs"))
    if inner is None or "LOD" not in inner.variantSelections:
        raise TreegenError(f"prototype {proto.name}: has no LOD variant set to lift")
    del inner.variantSelections["LOD"]
    vset = Sdf.VariantSetSpec(spec, "LOD")
    for k in range(n):
        over = Sdf.PrimSpec(Sdf.VariantSpec(vset, f"LOD{k}").primSpec, "LODs", Sdf.SpecifierOver)
        over.variantSelections["LOD"] = f"LOD{k}"
    spec.variantSetNameList.Prepend("LOD")
    spec.variantSelections["LOD"] = "LOD0"


def build_forest_stage(
    scene: Forest, up: str = "Z", textures: TextureFiles | None = None, lod_schemas: bool = True
):
    """The whole forest as an in-memory stage (one layer); `up`, `textures` and `lod_schemas`
    as exchange.usd.build_stage."""
    from pxr import Gf, Kind, Sdf, Usd, UsdGeom

    stage, root_path = new_stage(
        scene.name,
        "treegen: forest of instanced, skinned Weber-Penn trees (UsdSkel)",
        Kind.Tokens.assembly,
        up,
    )
    layer = stage.GetRootLayer()
    protos_path = root_path.AppendChild("Prototypes")
    stage.CreateClassPrim(protos_path)

    tcps = None
    clips = [c for a in scene.prototypes for lod in a.lods for c in lod.clips if len(c.times) > 1]
    if clips and scene.loop > 0:
        tcps = sample_rate(clips[0].times)
        stage.SetTimeCodesPerSecond(tcps)
        stage.SetFramesPerSecond(tcps)
        stage.SetStartTimeCode(0.0)
        stage.SetEndTimeCode(float(snap(np.array([scene.loop * tcps]))[0]))

    # one prototype prim per (prototype, LOD) used, or per prototype with all LODs
    wanted: dict[tuple[int, int], None] = {}
    for inst in scene.instances:
        wanted[(inst.prototype, -1 if scene.all_lods else inst.lod)] = None
    proto_paths: dict[tuple[int, int], Sdf.Path] = {}
    used: set[str] = set()
    for p, k in sorted(wanted):  # per prototype: a few
        asset = scene.prototypes[p]
        lods = list(range(len(asset.lods))) if k < 0 else [k]
        proto = identifier(scene.prototype_name(p))
        sub = build_stage(
            _prototype_asset(scene, p, lods, tcps is not None),
            up,
            textures,
            lod_schemas,
            texture_prefix=proto + "_",
        )
        src = sub.GetDefaultPrim().GetPath()
        name = identifier(proto + ("" if k < 0 else f"_lod{k}"))
        while name in used:
            name += "_"
        used.add(name)
        dst = protos_path.AppendChild(name)
        if not Sdf.CopySpec(sub.GetRootLayer(), src, layer, dst):
            raise TreegenError(f"prototype {name}: could not copy into the forest layer")
        if k < 0 and len(lods) > 1:
            _lift_lod_variants(layer, dst, len(lods))
        proto_paths[(p, k)] = dst

    trees_path = root_path.AppendChild("Trees")
    trees = UsdGeom.Xform.Define(stage, trees_path).GetPrim()
    Usd.ModelAPI(trees).SetKind(Kind.Tokens.group)
    width = len(str(max(len(scene.instances) - 1, 0)))
    frames = (scene.loop * tcps) if tcps else 0.0
    with Sdf.ChangeBlock():
        for i, inst in enumerate(scene.instances):  # per tree: a handful of specs
            path = trees_path.AppendChild(f"tree{i:0{width}d}")
            spec = Sdf.CreatePrimInLayer(layer, path)
            spec.specifier = Sdf.SpecifierDef
            spec.typeName = "Xform"
            spec.instanceable = True
            offset = float(np.round(inst.time_offset * tcps)) % frames if tcps else 0.0
            ref = Sdf.Reference(
                "",
                proto_paths[(inst.prototype, -1 if scene.all_lods else inst.lod)],
                Sdf.LayerOffset(-offset, 1.0),
            )
            spec.referenceList.Prepend(ref)
            ops = []
            position = to_y_up(np.asarray(inst.position, np.float64)) if up == "Y" else inst.position
            for op_name, type_name, value in (
                ("xformOp:translate", Sdf.ValueTypeNames.Double3, Gf.Vec3d(*(float(c) for c in position))),
                (f"xformOp:rotate{up}", Sdf.ValueTypeNames.Float, float(inst.rotation_deg)),
                ("xformOp:scale", Sdf.ValueTypeNames.Float3, Gf.Vec3f(*([inst.scale] * 3))),
            ):
                attr = Sdf.AttributeSpec(spec, op_name, type_name)
                attr.default = value
                ops.append(op_name)
            order = Sdf.AttributeSpec(
                spec, "xformOpOrder", Sdf.ValueTypeNames.TokenArray, Sdf.VariabilityUniform
            )
            order.default = ops
            spec.customData = {
                "treegen": {
                    "source": inst.source,
                    "lod": inst.lod,
                    "time_offset_s": float(offset / tcps) if tcps else 0.0,
                }
            }
    return stage


def write_forest_usd(scene: Forest, path) -> None:
    """Write the forest to exactly `path` (.usda text, .usdc crate, .usdz package)."""
    path = Path(path)
    suffix = check_suffix(path)  # before the stage is built
    textures = TextureFiles(path)
    # keep the stage alive: it owns the layer
    stage = build_forest_stage(scene, up_axis(None, suffix), textures, suffix != ".usdz")
    write_stage(stage, path, path.stem + ".usdc", textures.files)
