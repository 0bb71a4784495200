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

With `all_lods` a prototype keeps all its LODs (LODRootAPI + the "LOD" variant set from
exchange.usd); otherwise one prototype prim per (prototype, LOD) actually used.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import TreegenError
from ..asset import Forest
from .usd import (_identifier, _sample_rate, _snap, build_stage, check_suffix, new_stage,
                  write_stage)


def _prototype_asset(forest: Forest, p: int, lods: list[int], loop: bool):
    """Prototype p with only `lods`; its clips over two periods (Forest.looped) when looping."""
    asset = forest.looped[p] if loop else forest.prototypes[p]
    return replace(asset, lods=[asset.lods[k] for k in lods])


def build_forest_stage(scene: Forest):
    """The whole forest as an in-memory stage (one layer)."""
    from pxr import Gf, Kind, Sdf, Usd, UsdGeom

    stage, root_path = new_stage(
        scene.name, "treegen: forest of instanced, skinned Weber-Penn trees (UsdSkel)",
        Kind.Tokens.assembly)
    layer = stage.GetRootLayer()
    protos_path = root_path.AppendChild("Prototypes")
    stage.CreateClassPrim(protos_path)

    tcps = None
    clips = [c for a in scene.prototypes for lod in a.lods for c in lod.clips if len(c.times) > 1]
    if clips and scene.loop > 0:
        tcps = _sample_rate(clips[0].times)
        stage.SetTimeCodesPerSecond(tcps)
        stage.SetFramesPerSecond(tcps)
        stage.SetStartTimeCode(0.0)
        stage.SetEndTimeCode(float(_snap(np.array([scene.loop * tcps]))[0]))

    # one prototype prim per (prototype, LOD) used, or per prototype with all LODs
    wanted: dict[tuple[int, int], None] = {}
    for inst in scene.instances:
        wanted[(inst.prototype, -1 if scene.all_lods else inst.lod)] = None
    proto_paths: dict[tuple[int, int], Sdf.Path] = {}
    used: set[str] = set()
    for p, k in sorted(wanted):       # per prototype: a few
        asset = scene.prototypes[p]
        lods = list(range(len(asset.lods))) if k < 0 else [k]
        sub = build_stage(_prototype_asset(scene, p, lods, tcps is not None))
        src = sub.GetDefaultPrim().GetPath()
        name = _identifier(f"{asset.name}_s{asset.extras.get('seed', p)}" + ("" if k < 0 else f"_lod{k}"))
        while name in used:
            name += "_"
        used.add(name)
        dst = protos_path.AppendChild(name)
        if not Sdf.CopySpec(sub.GetRootLayer(), src, layer, dst):
            raise TreegenError(f"prototype {name}: could not copy into the forest layer")
        proto_paths[(p, k)] = dst

    trees_path = root_path.AppendChild("Trees")
    trees = UsdGeom.Xform.Define(stage, trees_path).GetPrim()
    Usd.ModelAPI(trees).SetKind(Kind.Tokens.group)
    width = len(str(max(len(scene.instances) - 1, 0)))
    frames = (scene.loop * tcps) if tcps else 0.0
    with Sdf.ChangeBlock():
        for i, inst in enumerate(scene.instances):   # per tree: a handful of specs
            path = trees_path.AppendChild(f"tree{i:0{width}d}")
            spec = Sdf.CreatePrimInLayer(layer, path)
            spec.specifier = Sdf.SpecifierDef
            spec.typeName = "Xform"
            spec.instanceable = True
            offset = float(np.round(inst.time_offset * tcps)) % frames if tcps else 0.0
            ref = Sdf.Reference("", proto_paths[(inst.prototype, -1 if scene.all_lods else inst.lod)],
                                Sdf.LayerOffset(-offset, 1.0))
            spec.referenceList.Prepend(ref)
            ops = []
            for op_name, type_name, value in (
                    ("xformOp:translate", Sdf.ValueTypeNames.Double3, Gf.Vec3d(*inst.position)),
                    ("xformOp:rotateZ", Sdf.ValueTypeNames.Float, float(inst.rotation_deg)),
                    ("xformOp:scale", Sdf.ValueTypeNames.Float3, Gf.Vec3f(*([inst.scale] * 3)))):
                attr = Sdf.AttributeSpec(spec, op_name, type_name)
                attr.default = value
                ops.append(op_name)
            order = Sdf.AttributeSpec(spec, "xformOpOrder", Sdf.ValueTypeNames.TokenArray,
                                      Sdf.VariabilityUniform)
            order.default = ops
            spec.customData = {"treegen": {"source": inst.source, "lod": inst.lod,
                                           "time_offset_s": float(offset / tcps) if tcps else 0.0}}
    return stage


def write_forest_usd(scene: Forest, path) -> None:
    """Write the forest to exactly `path` (.usda text, .usdc crate, .usdz package)."""
    path = Path(path)
    check_suffix(path)                    # before the stage is built
    stage = build_forest_stage(scene)     # keep the stage alive: it owns the layer
    write_stage(stage, path, path.stem + ".usdc")
