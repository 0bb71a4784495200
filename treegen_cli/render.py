"""Headless OpenGL renderer for previews: moderngl on an EGL context (Mesa llvmpipe will do).

What it draws, so a picture says something about the asset before an engine opens it:
  - a sky gradient and a ground plane fading into the horizon,
  - the tree skinned in the vertex shader exactly like an engine does (per vertex Σ wᵢ·Sᵢ with
    Sᵢ = joint world matrix · inverse bind matrix, four influences), so a broken skin shows,
  - a sun with a shadow map (the tree shades itself and the ground) plus a sky/ground
    hemisphere ambient; leaves are lit from both sides with some light through them;
    impostor cards cast shadows but receive none (Part.receives_shadows),
  - textures as an engine samples them: base colour (sRGB, mipmapped, trilinear) times the
    material colour, alpha-tested cut-outs (also in the shadow pass, so leaf shadows have leaf
    shapes) and tangent-space normal maps with tangents from screen-space derivatives (no
    tangent attribute needed); mips are built on the CPU in linear light, and minified
    cut-outs turn into hashed alpha tests so small or distant leaves keep their share of
    coverage instead of all or nothing,
  - 2×2 supersampling, box-filtered down on the CPU.

World space here is Y up (glTF's), metres. Everything the renderer needs comes in a
`drawable.Drawable`; loading files and assets into one is drawable.py's and exchange's job.
Parts: render_view.py (cameras, CPU skinning), render_shaders.py (GLSL), render_gl.py (the
context, mip levels); this module uploads a Drawable, draws a frame and reads it back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .drawable import Drawable, Part, crown
from .errors import TreegenError
from .leafshapes import card_corners
from .render_gl import GL_SRGB8_ALPHA8, gl_context, mip_chain
from .render_shaders import DEPTH_FS, GROUND_FS, GROUND_VS, SKY_FS, SKY_VS, TREE_FS, TREE_VS
from .render_view import Camera, direction, look_at, orthographic

SUPERSAMPLE = 2  # rendered at SUPERSAMPLE× the size, box-filtered down
SHADOW_SIZE = 2048  # shadow map texels per side
SKY_ZENITH = (0.23, 0.42, 0.78)  # linear RGB
SKY_HORIZON = (0.72, 0.80, 0.90)
GROUND = (0.085, 0.10, 0.045)
SUN_COLOR = (2.6, 2.45, 2.2)  # linear, HDR (tone-mapped in the shader)
MIP_BIAS = -0.5  # sharper than the 1:1 mip: the 2× supersampling averages
ANISOTROPY = 1.0  # off: Mesa llvmpipe's anisotropic path costs ~100× (a 200 px
# fir took 48 s for its bark, 0.5 s without) and the 2×2
# supersampling already averages along grazing bark
HASH_LOD = 1.0  # mip level from which cut-outs fade into hashed alpha tests


_WRAP_CODE = {"REPEAT": 0, "CLAMP": 1, "MIRROR": 2}


@dataclass
class _GpuPart:
    vao: object
    depth_vao: object
    part: Part
    tex: object = None
    nmap: object = None


class Renderer:
    """Draws one Drawable from one Camera, any number of poses; owns its GL context."""

    def __init__(self, scene: Drawable, width: int, height: int, supersample: int = SUPERSAMPLE):
        if width < 8 or height < 8 or width > 8192 or height > 8192:
            raise TreegenError(f"--size {width}x{height}: each side must be in 8..8192 pixels")
        self.scene = scene
        self.width, self.height, self.ss = width, height, supersample
        ctx = self.ctx = gl_context()
        self.tree_prog = ctx.program(vertex_shader=TREE_VS, fragment_shader=TREE_FS)
        self.depth_prog = ctx.program(vertex_shader=TREE_VS, fragment_shader=DEPTH_FS)
        self.sky_prog = ctx.program(vertex_shader=SKY_VS, fragment_shader=SKY_FS)
        self.ground_prog = ctx.program(vertex_shader=GROUND_VS, fragment_shader=GROUND_FS)
        W, H = width * supersample, height * supersample
        self.color = ctx.renderbuffer((W, H), 4)
        self.depth = ctx.depth_renderbuffer((W, H))
        self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)
        self.shadow_tex = ctx.depth_texture((SHADOW_SIZE, SHADOW_SIZE))
        self.shadow_tex.compare_func = "<="
        self.shadow_tex.repeat_x = self.shadow_tex.repeat_y = False
        self.shadow_fbo = ctx.framebuffer(depth_attachment=self.shadow_tex)
        self.skin_tex = ctx.texture((4, max(scene.n_joints, 1)), 4, dtype="f4")
        self._textures: dict = {}
        self.parts = [self._upload(p) for p in scene.parts if len(p.indices)]
        quad = np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4")
        self.sky_vao = ctx.vertex_array(self.sky_prog, [(ctx.buffer(quad.tobytes()), "2f", "in_ndc")])
        self.ground_vao = ctx.vertex_array(self.ground_prog, [(ctx.buffer(quad.tobytes()), "2f", "in_xz")])
        self._setup_lighting()

    def _upload(self, p: Part) -> _GpuPart:
        ctx = self.ctx
        bufs = [
            (ctx.buffer(np.ascontiguousarray(p.positions, "f4").tobytes()), "3f", "in_pos"),
            (ctx.buffer(np.ascontiguousarray(p.normals, "f4").tobytes()), "3f", "in_normal"),
            (ctx.buffer(np.ascontiguousarray(p.joints, "f4").tobytes()), "4f", "in_joints"),
            (ctx.buffer(np.ascontiguousarray(p.weights, "f4").tobytes()), "4f", "in_weights"),
        ]
        if p.uvs is not None:
            bufs.append((ctx.buffer(np.ascontiguousarray(p.uvs, "f4").tobytes()), "2f", "in_uv"))
        ibo = ctx.buffer(np.ascontiguousarray(p.indices, "u4").tobytes())
        vao = ctx.vertex_array(self.tree_prog, bufs, index_buffer=ibo, index_element_size=4)
        dvao = ctx.vertex_array(
            self.depth_prog, [b for b in bufs if b[2] != "in_normal"], index_buffer=ibo, index_element_size=4
        )
        tex = self._shared(p.texture, True, p.wrap) if p.textured else None
        nmap = self._shared(p.normal_map, False, p.normal_wrap) if p.bumpy else None
        return _GpuPart(vao, dvao, p, tex, nmap)

    def _shared(self, image: np.ndarray, srgb: bool, wrap):
        """One GL texture per image array (a forest's trees share their prototype's)."""
        key = (id(image), srgb, tuple(wrap))
        if key not in self._textures:
            self._textures[key] = (image, self._texture(image, srgb, wrap))  # holds the array
        return self._textures[key][1]

    def _texture(self, image: np.ndarray, srgb: bool, wrap):
        """A mipmapped GL texture; rows flipped so texture t = the bottom-left-origin v."""
        img = np.asarray(image, np.uint8)
        if img.shape[2] == 3:  # RGBA texels: no row alignment fuss
            img = np.concatenate([img, np.full(img.shape[:2] + (1,), 255, np.uint8)], axis=2)
        levels = mip_chain(img[::-1], srgb)
        h, w = img.shape[:2]
        tex = self.ctx.texture(
            (w, h), 4, levels[0].tobytes(), internal_format=GL_SRGB8_ALPHA8 if srgb else None
        )
        tex.build_mipmaps(0, len(levels) - 1)  # allocates; our levels replace them
        for k, lv in enumerate(levels[1:], 1):
            tex.write(lv.tobytes(), level=k)
        tex.repeat_x, tex.repeat_y = (m == "REPEAT" for m in wrap)
        tex.filter = (self.ctx.LINEAR_MIPMAP_LINEAR, self.ctx.LINEAR)
        tex.anisotropy = ANISOTROPY
        return tex

    def _setup_lighting(self) -> None:
        pts = np.concatenate(
            [p.positions for p in self.scene.parts if len(p.positions)] or [np.zeros((1, 3), np.float32)]
        ).astype(np.float64)
        self.bounds = (pts.min(0), pts.max(0))
        self.crown_center, self.crown_radius = crown(self.scene.parts)

    def _set(self, prog, name, value) -> None:
        if name in prog:
            u = prog[name]
            if isinstance(value, np.ndarray) and value.shape == (4, 4):
                u.write(np.ascontiguousarray(value.T, dtype="f4").tobytes())
            elif isinstance(value, (bool, np.bool_)):
                u.value = bool(value)
            elif isinstance(value, int):
                u.value = value
            elif isinstance(value, tuple) and all(isinstance(v, int) for v in value):
                u.value = value  # ivec
            else:
                u.value = tuple(float(v) for v in np.ravel(value)) if np.ndim(value) else float(value)

    def _material(self, prog, g: _GpuPart) -> None:
        """Texture bindings and cut-out uniforms of one part."""
        p = g.part
        self._set(prog, "has_tex", g.tex is not None)
        self._set(prog, "has_nmap", g.nmap is not None)
        if g.tex is not None:
            g.tex.use(location=2)
            self._set(prog, "tex_wrap", tuple(_WRAP_CODE[m] for m in p.wrap))
        if g.nmap is not None:
            g.nmap.use(location=3)
            self._set(prog, "nmap_wrap", tuple(_WRAP_CODE[m] for m in p.normal_wrap))
            self._set(prog, "normal_scale", p.normal_scale)
        cut = p.alpha_cutoff if g.tex is not None and p.alpha_cutoff is not None else -1.0
        self._set(prog, "alpha_cutoff", float(cut))
        self._set(prog, "opacity", p.opacity)
        # a far LOD's triangle cards hash and tint per triangle; cards (and outlines, as
        # before) per pair of triangles
        self._set(prog, "leaf_tris", 1 if card_corners(len(p.positions), len(p.indices)) == 3 else 2)

    def render(
        self,
        camera: Camera,
        skinning: np.ndarray | None = None,
        sun_azimuth_deg: float = 0.0,
        sun_elevation_deg: float = 50.0,
        draw_tree: bool = True,
    ) -> np.ndarray:
        """One frame as uint8 (height, width, 3), top row first. `draw_tree=False` renders the
        same view without the tree itself (its shadow stays): the background, for tests."""
        ctx = self.ctx
        J = max(self.scene.n_joints, 1)
        skin = np.broadcast_to(np.eye(4), (J, 4, 4)) if skinning is None else skinning
        self.skin_tex.write(np.ascontiguousarray(np.transpose(skin, (0, 2, 1)), "f4").tobytes())
        self.skin_tex.use(location=0)
        self.shadow_tex.use(location=1)

        lo, hi = self.bounds
        center = 0.5 * (lo + hi)
        radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3) * 1.1
        sun = direction(sun_azimuth_deg, sun_elevation_deg)
        light_vp = orthographic(radius, 0.0, 4 * radius) @ look_at(center + sun * 2 * radius, center)
        view_proj = camera.view_proj(self.width / self.height)
        texel_world = 2 * radius / SHADOW_SIZE
        common = {
            "sun_dir": sun,
            "sun_color": SUN_COLOR,
            "light_vp": light_vp,
            "shadow_map": 1,
            "shadow_bias": 1.5 * texel_world,
            "sky_zenith": SKY_ZENITH,
            "sky_horizon": SKY_HORIZON,
            "ground_color": GROUND,
        }

        # shadow pass: depth of the posed tree from the sun
        self.shadow_fbo.use()
        ctx.viewport = (0, 0, SHADOW_SIZE, SHADOW_SIZE)
        self.shadow_fbo.clear(depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.disable(ctx.CULL_FACE)
        self._set(self.depth_prog, "view_proj", light_vp)
        self._set(self.depth_prog, "skin", 0)
        self._set(self.depth_prog, "base_tex", 2)
        self._set(self.depth_prog, "mip_bias", MIP_BIAS)
        self._set(self.depth_prog, "hash_from", HASH_LOD)
        for g in self.parts:
            self._material(self.depth_prog, g)
            g.depth_vao.render()

        # main pass
        self.fbo.use()
        ctx.viewport = (0, 0, self.width * self.ss, self.height * self.ss)
        self.fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        ctx.disable(ctx.DEPTH_TEST)
        for k, v in common.items():
            self._set(self.sky_prog, k, v)
        self._set(self.sky_prog, "inv_view_proj", np.linalg.inv(view_proj))
        self.sky_vao.render(mode=ctx.TRIANGLE_STRIP)
        ctx.enable(ctx.DEPTH_TEST)
        size = float(np.max(hi - lo))
        for k, v in common.items():
            self._set(self.ground_prog, k, v)
        self._set(self.ground_prog, "view_proj", view_proj)
        self._set(self.ground_prog, "ground_y", lo[1])
        self._set(self.ground_prog, "ground_half", 40 * size)
        self._set(self.ground_prog, "ground_center", center)
        self._set(self.ground_prog, "eye", camera.eye)
        dist = float(np.linalg.norm(camera.eye - camera.target))
        self._set(self.ground_prog, "fog_start", dist + 1.0 * size)
        self._set(self.ground_prog, "fog_end", dist + 25 * size)
        self.ground_vao.render(mode=ctx.TRIANGLE_STRIP)
        for k, v in common.items():
            self._set(self.tree_prog, k, v)
        self._set(self.tree_prog, "view_proj", view_proj)
        self._set(self.tree_prog, "skin", 0)
        self._set(self.tree_prog, "eye", camera.eye)
        self._set(self.tree_prog, "base_tex", 2)
        self._set(self.tree_prog, "normal_tex", 3)
        self._set(self.tree_prog, "mip_bias", MIP_BIAS)
        self._set(self.tree_prog, "hash_from", HASH_LOD)
        for g in self.parts if draw_tree else []:
            self._set(self.tree_prog, "base_color", g.part.color)
            self._set(self.tree_prog, "leaf", g.part.double_sided)
            self._set(self.tree_prog, "receive_shadows", g.part.receives_shadows)
            centre, radius = g.part.crown or (self.crown_center, self.crown_radius)
            self._set(self.tree_prog, "crown_center", centre)
            self._set(self.tree_prog, "crown_radius", radius)
            self._material(self.tree_prog, g)
            if g.part.one_sided:  # an engine culls single-sided faces' backs
                ctx.enable(ctx.CULL_FACE)
            g.vao.render()
            ctx.disable(ctx.CULL_FACE)

        W, H = self.width * self.ss, self.height * self.ss
        data = np.frombuffer(self.fbo.read(components=3, alignment=1), dtype=np.uint8)
        img = data.reshape(H, W, 3)[::-1].astype(np.float32)
        img = img.reshape(self.height, self.ss, self.width, self.ss, 3).mean(axis=(1, 3))
        return np.round(img).astype(np.uint8)

    def release(self) -> None:
        self.ctx.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()
