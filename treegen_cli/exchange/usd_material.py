"""USD materials: a Material as a UsdPreviewSurface with an st primvar reader and a UsdUVTexture
per texture file (base colour, normal map)."""

from __future__ import annotations

from ..asset import Material, Texture
from .usd_stage import identifier


def define_material(stage, looks_path, m: Material, texture_path=lambda tex: None):
    """UsdPreviewSurface; an st primvar reader wired to the material's frame:stPrimvarName
    interface input; a UsdUVTexture for each texture `texture_path` names a file for.

    Base texture: its rgb (times base_color, via the texture's scale, as glTF's factor) feeds
    diffuseColor; with an alpha_cutoff its alpha feeds opacity, cut at opacityThreshold.
    Normal texture: raw colour space, scale (2,2,2,1) and bias (-1,-1,-1,0) map 8-bit [0, 1]
    to the [-1, 1] tangent-space normal UsdPreviewSurface expects (OpenGL convention, +Y up,
    as the Asset's)."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade

    if not stage.GetPrimAtPath(looks_path):
        UsdGeom.Scope.Define(stage, looks_path)
    mpath = looks_path.AppendChild(identifier(m.name))
    material = UsdShade.Material.Define(stage, mpath)
    st_name = material.CreateInput("frame:stPrimvarName", Sdf.ValueTypeNames.String)
    st_name.Set("st")

    surf = UsdShade.Shader.Define(stage, mpath.AppendChild("PreviewSurface"))
    surf.CreateIdAttr("UsdPreviewSurface")
    r, g, b, a = (float(c) for c in m.base_color)
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(r, g, b))
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(m.roughness))
    surf.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(float(m.metallic))
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(a)
    if m.alpha_cutoff is not None:
        surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(float(m.alpha_cutoff))
    material.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")

    reader = UsdShade.Shader.Define(stage, mpath.AppendChild("stReader"))
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).ConnectToSource(st_name)
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)

    base = texture_path(m.base_texture)
    if base is not None:
        tex = _define_texture(
            stage, mpath.AppendChild("baseTexture"), base, m.base_texture, st, scale=(r, g, b, a)
        )
        surf.GetInput("diffuseColor").ConnectToSource(tex.ConnectableAPI(), "rgb")
        if m.alpha_cutoff is not None:
            surf.GetInput("opacity").ConnectToSource(tex.ConnectableAPI(), "a")
    normal = texture_path(m.normal_texture)
    if normal is not None:
        tex = _define_texture(
            stage,
            mpath.AppendChild("normalTexture"),
            normal,
            m.normal_texture,
            st,
            scale=(2.0, 2.0, 2.0, 1.0),
            bias=(-1.0, -1.0, -1.0, 0.0),
        )
        surf.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    return material


def _define_texture(stage, path, file: str, texture: Texture, st, scale, bias=None):
    """A UsdUVTexture reading `file` at the st reader's output; outputs rgb and a."""
    from pxr import Gf, Sdf, UsdShade

    wrap = "clamp" if texture.wrap.upper().startswith("CLAMP") else "repeat"
    tex = UsdShade.Shader.Define(stage, path)
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(file))
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
    tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(wrap)
    tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(wrap)
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB" if texture.srgb else "raw")
    tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*map(float, scale)))
    if bias is not None:
        tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*map(float, bias)))
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
    return tex
