"""The impostor atlas in one batched draw: every view of a hemi-octahedral grid rendered at once.

    albedo, normal_depth = render_atlas(drawable, centre, radius, grid=16, cell=128)
    # Result: two uint8 (grid·cell, grid·cell, 4) images, top row first: sRGB albedo + alpha
    # (coverage), and (a, b, up)-frame normals · 0.5 + 0.5 with depth in alpha.

Each view is an orthographic camera on the bounding sphere (centre, radius) looking at the
centre from the direction its cell's centre decodes to (impostor.cell_direction: the same
formula, in GLSL here). One instanced draw call per part: the vertex shader picks the instance's
cell, projects the rest-pose vertex into the view and places it inside the cell, whose square
holds the whole sphere, so nothing leaks into a neighbour (`AtlasRenderer.strip` draws a few
chosen views side by side instead, at their own size: the cards'). Rendered on render_gl.py's context with
render.py's texture conventions; a plain cut-out test (the views are small: one sample a pixel). Space
is the generator's (Z up): a, b, up = +X, +Y, +Z.

Cost (llvmpipe, CPU): the leaves are most of it, a fixed price per few-pixel card and view,
so their program is lean: colour, tint and occlusion come per vertex (leaf_shading), depth from
gl_FragCoord, and they sample a 256² copy of the leaf atlas (shrink). Bark, a few hundred long
triangles, keeps its occlusion per pixel.
"""

from __future__ import annotations

import numpy as np

from .drawable import Drawable
from .errors import TreegenError
from .impostor_shading import leaf_shading
from .render_gl import GL_SRGB8_ALPHA8, gl_context

# Bark inside the crown is shaded by its leaves (the aspen's white limbs showed as specks);
# a crown whose leaves show less than LEAFY of its area shades it in proportion (a desert
# bush's few leaves turned its whole bare bush dark, and a leafless plant's crown is no crown).
CROWN_SHADE = 0.4
LEAFY = 0.5


def leafiness(leaf_share: float) -> float:
    """How fully a crown whose leaves are `leaf_share` of what it shows shades its bark, 0..1."""
    return min(max(leaf_share, 0.0) / LEAFY, 1.0)


# Both programs share the view: instance → cell → orthographic projection into the cell.
_VIEW = """
#version 330
uniform vec3 centre;
uniform float radius;
uniform int grid;
uniform int n_cells;                              // > 0: instance i draws only cells[i]
uniform ivec2 cells[4];
uniform int strip;                                // > 0: instance i draws into slot i of a
                                                  // strip of that many views (the cards')

vec3 cell_direction(int col, int row) {        // hemi-octahedral decode of the cell centre
    vec2 q = (vec2(col, row) + 0.5) / float(grid) * 2.0 - 1.0;
    q.y = -q.y;                                   // rows count from the top of the image
    vec2 p = vec2(q.x + q.y, q.x - q.y) * 0.5;
    return normalize(vec3(p, 1.0 - abs(p.x) - abs(p.y)));
}

vec3 project(vec3 pos) {                          // sets gl_Position; returns the view coords
    int col = gl_InstanceID % grid, row = gl_InstanceID / grid;
    if (n_cells > 0) { col = cells[gl_InstanceID].x; row = cells[gl_InstanceID].y; }
    vec3 d = cell_direction(col, row);            // from the centre towards the viewer
    vec3 right = cross(vec3(0.0, 0.0, 1.0), d);
    right = dot(right, right) > 1e-10 ? normalize(right) : vec3(0.0, 1.0, 0.0);
    vec3 up = cross(d, right);
    vec3 rel = (pos - centre) / radius;
    vec3 l = vec3(dot(rel, right), dot(rel, up), dot(rel, d));
    float n = float(grid);
    if (strip > 0) {
        float x = (float(gl_InstanceID) + 0.5 + 0.5 * l.x) / float(strip) * 2.0 - 1.0;
        gl_Position = vec4(x, l.y, -l.z, 1.0);
        return l;
    }
    gl_Position = vec4((float(col) + 0.5 + 0.5 * l.x) / n * 2.0 - 1.0,
                       1.0 - (float(row) + 0.5 - 0.5 * l.y) / n * 2.0, -l.z, 1.0);
    return l;                                     // depth 0.5 + 0.5·l.z = 1 − gl_FragCoord.z
}
"""

# Bark: few triangles (the coarsest LOD's widest), long ones, so its occlusion is per pixel.
_BARK_VS = (
    _VIEW
    + """
in vec3 in_pos;
in vec3 in_normal;
in vec2 in_uv;
in float in_keep;
out vec3 v_normal;
out vec2 v_uv;
out vec3 v_rel;
flat out float v_keep;

void main() {
    project(in_pos);
    v_normal = in_normal;
    v_uv = in_uv;
    v_rel = (in_pos - centre) / radius;
    v_keep = in_keep;
}
"""
)

_BARK_FS = """
#version 330
uniform bool has_tex;
uniform sampler2D base_tex;
uniform float alpha_cutoff;    // < 0: opaque
uniform float opacity;
uniform vec3 base_color;
uniform vec3 crown_centre;
uniform vec3 crown_radius;
uniform float crown_shade;     // CROWN_SHADE, less in a crown of few leaves (leafiness)
in vec3 v_normal;
in vec2 v_uv;
in vec3 v_rel;
flat in float v_keep;
layout(location = 0) out vec4 f_albedo;
layout(location = 1) out vec4 f_normal;

void main() {
    vec4 texel = has_tex ? texture(base_tex, v_uv) : vec4(1.0);
    if (texel.a * opacity < alpha_cutoff) discard;
    if (v_keep < 0.5) discard;  // a thin stem left out (impostor_atlas._bark_at_least)
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    // baked, as cards have no crown to shade them: the inner crown gets less sky (render.py's
    // occlusion)
    float r = length((v_rel - crown_centre) / crown_radius);
    float ao = mix(0.45, 1.0, smoothstep(0.1, 1.0, r));
    // branches inside the crown are shaded by its leaves as the leaves shade each other (the
    // aspen's white limbs showed as bright specks in the crown); the trunk below keeps its light
    ao *= mix(crown_shade, 1.0, smoothstep(0.8, 1.1, r));
    f_albedo = vec4(base_color * texel.rgb * ao, 1.0);     // linear; sRGB-encoded by the target
    f_normal = vec4(n * 0.5 + 0.5, 1.0 - gl_FragCoord.z);
}
"""

# Leaves: hundreds of thousands of few-pixel cards (most of the atlas's cost, fragment work on
# llvmpipe), so everything that is constant over a leaf comes in per vertex: `in_shade` =
# base colour × the leaf's tint × LEAF_SHADE × the occlusion at the vertex (leaf_shading).
_LEAF_VS = (
    _VIEW
    + """
in vec3 in_pos;
in vec3 in_normal;
in vec2 in_uv;
in vec3 in_shade;
out vec3 v_normal;
out vec2 v_uv;
out vec3 v_shade;

void main() {
    project(in_pos);
    v_normal = in_normal;
    v_uv = in_uv;
    v_shade = in_shade;
}
"""
)

_LEAF_FS = """
#version 330
uniform sampler2D base_tex;
uniform float alpha_cutoff;    // already divided by the opacity
in vec3 v_normal;
in vec2 v_uv;
in vec3 v_shade;
layout(location = 0) out vec4 f_albedo;
layout(location = 1) out vec4 f_normal;

void main() {
    vec4 texel = texture(base_tex, v_uv);
    if (texel.a < alpha_cutoff) discard;
    vec3 n = normalize(v_normal);
    f_albedo = vec4(texel.rgb * v_shade, 1.0);
    f_normal = vec4((gl_FrontFacing ? n : -n) * 0.5 + 0.5, 1.0 - gl_FragCoord.z);
}
"""


def _texture(ctx, image: np.ndarray, wrap):
    """An sRGB texture without mips (rows flipped: t = bottom-up v). Unfiltered by distance on
    purpose: a cut-out sampled at each pixel's centre keeps a leaf's expected coverage, and
    llvmpipe's mipmap generation would cost more than the whole atlas draw."""
    img = np.asarray(image, np.uint8)
    if img.shape[2] == 3:
        img = np.concatenate([img, np.full(img.shape[:2] + (1,), 255, np.uint8)], axis=2)
    h, w = img.shape[:2]
    tex = ctx.texture((w, h), 4, np.ascontiguousarray(img[::-1]).tobytes(), internal_format=GL_SRGB8_ALPHA8)
    tex.repeat_x, tex.repeat_y = (m == "REPEAT" for m in wrap)
    tex.filter = (ctx.LINEAR, ctx.LINEAR)
    return tex


LEAF_TEXTURE_PX = 256  # the leaf atlas is box-filtered down to this side for the views


def shrink(image: np.ndarray, side: int = LEAF_TEXTURE_PX) -> np.ndarray:
    """`image` box-filtered by the largest power of two that divides it and keeps it at least
    `side` texels high and wide. A leaf is a few atlas pixels across, so the views sample a
    texel per leaf either way; the smaller texture stays in cache (the aspen's leaf pass:
    1.5× faster from a 512² atlas, coverage IoU 0.9995 against it). Colour is averaged
    without alpha weighting, as bilinear sampling of the original mixes it (the generated
    atlas's transparent texels carry their blade's colour)."""
    img = np.asarray(image, np.uint8)
    h, w = img.shape[:2]
    f = 1
    while min(h, w) >= 2 * f * side and h % (2 * f) == 0 and w % (2 * f) == 0:
        f *= 2
    if f == 1:
        return img
    total = np.zeros((h // f, w // f, img.shape[2]), np.uint32)
    for dy in range(f):
        for dx in range(f):
            total += img[dy::f, dx::f]
    return ((total + f * f // 2) // (f * f)).astype(np.uint8)


def _set(prog, name, value) -> None:
    if name in prog:
        prog[name].value = value


def _buffer(ctx, array, dtype: str):
    return ctx.buffer(np.ascontiguousarray(array, dtype).tobytes())


MAX_CELLS = 4  # cells one partial draw can pick (the shader's `cells` array)


class AtlasRenderer:
    """One GL context, pair of programs and framebuffer for several draws of one atlas layout
    (centre, radius, grid × grid cells of `cell` pixels): the atlas, and the quick draws of a
    few cells that calibrate its thinned leaves (impostor.render_views)."""

    def __init__(self, centre: np.ndarray, radius: float, grid: int, cell: int, leafy: float = 1.0):
        try:
            self.ctx = ctx = gl_context()
        except TreegenError as e:  # the default make must say what to do without EGL
            raise TreegenError(
                f"impostor: {str(e).removeprefix('preview: ')} (make it with --no-impostor)"
            ) from None
        try:
            self.grid, self.cell, self.size, self.leafy = grid, cell, grid * cell, float(leafy)
            self.centre, self.radius = np.asarray(centre, np.float64), float(radius)
            self.bark = ctx.program(vertex_shader=_BARK_VS, fragment_shader=_BARK_FS)
            self.leaf = ctx.program(vertex_shader=_LEAF_VS, fragment_shader=_LEAF_FS)
            size = self.size
            albedo = ctx.texture((size, size), 4, internal_format=GL_SRGB8_ALPHA8)
            normal = ctx.texture((size, size), 4)
            depth = ctx.depth_renderbuffer((size, size))
            self.fbo = ctx.framebuffer(color_attachments=[albedo, normal], depth_attachment=depth)
            for prog in (self.bark, self.leaf):
                _set(prog, "centre", tuple(float(x) for x in self.centre))
                _set(prog, "radius", self.radius)
                _set(prog, "grid", int(grid))
                _set(prog, "base_tex", 0)
            self._white = np.full((1, 1, 4), 255, np.uint8)
            self._textures: dict[int, object] = {}
        except BaseException:
            ctx.release()
            raise

    def __enter__(self) -> AtlasRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.ctx.release()

    def draw(self, scene: Drawable, cells=None, keep: dict | None = None, target=None) -> None:
        """Clear and draw `scene`'s rest pose into every cell, or only into `cells` [(col, row)],
        clearing only those (for `covered`: a 2048² clear cost llvmpipe 5 ms, more than 2 cells).
        `keep`: {bark part index: (V,) 1 where drawn, 0 where not} (else all); `target`: (fbo,
        (w, h)) of a strip (`strip`) instead of the atlas."""
        ctx, c, radius = self.ctx, self.centre, self.radius
        fbo, (w, h) = target or (self.fbo, (self.size, self.size))
        fbo.use()
        ctx.viewport = (0, 0, w, h)
        for rect in [self._rect(col, row) for col, row in cells] if cells and not target else [None]:
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=rect)  # None: all of it
        ctx.enable(ctx.DEPTH_TEST)
        ctx.enable_direct(0x8DB9)  # GL_FRAMEBUFFER_SRGB: linear → sRGB
        ctx.disable(ctx.CULL_FACE)
        picked = list(cells or [])[:MAX_CELLS]
        pad = picked + [(0, 0)] * (MAX_CELLS - len(picked))
        for prog in (self.bark, self.leaf):
            _set(prog, "n_cells", len(picked))
            if "cells" in prog:
                prog["cells"].value = [tuple(int(v) for v in rc) for rc in pad]
        leaves = [p.positions for p in scene.parts if p.double_sided and len(p.positions)]
        crown = (
            np.concatenate(leaves).astype(np.float64)
            if leaves
            else np.concatenate([p.positions for p in scene.parts])
        )
        clo, chi = (crown.min(0) - c) / radius, (crown.max(0) - c) / radius
        crown_centre, crown_radius = 0.5 * (clo + chi), np.maximum(0.5 * (chi - clo), 0.05)
        bark, leaf = self.bark, self.leaf
        _set(bark, "crown_centre", tuple(float(x) for x in crown_centre))
        _set(bark, "crown_radius", tuple(float(x) for x in crown_radius))
        shade = CROWN_SHADE if self.leafy >= 1.0 else 1.0 - (1.0 - CROWN_SHADE) * self.leafy
        _set(bark, "crown_shade", float(shade))
        for i, p in enumerate(scene.parts):
            if not len(p.indices) or (p.double_sided and p.opacity <= 0):
                continue
            uvs = p.uvs if p.uvs is not None else np.zeros((len(p.positions), 2), np.float32)
            bufs = [
                (_buffer(ctx, p.positions, "f4"), "3f", "in_pos"),
                (_buffer(ctx, p.normals, "f4"), "3f", "in_normal"),
                (_buffer(ctx, uvs, "f4"), "2f", "in_uv"),
            ]
            cut = p.alpha_cutoff if p.textured and p.alpha_cutoff is not None else -1.0
            if p.double_sided:
                prog = leaf
                shade = leaf_shading(p, c, radius, crown_centre, crown_radius)
                bufs.append((_buffer(ctx, shade, "f4"), "3f", "in_shade"))
                _set(prog, "alpha_cutoff", float(cut) / float(p.opacity))
                tex = self._texture(p.texture if p.textured else None, p.wrap, small=True)
            else:
                prog = bark
                share = (keep or {}).get(i)
                share = np.ones(len(p.positions), np.float32) if share is None else share
                bufs.append((_buffer(ctx, share, "f4"), "1f", "in_keep"))
                tex = self._texture(p.texture, p.wrap) if p.textured else None
                _set(prog, "has_tex", tex is not None)
                _set(prog, "alpha_cutoff", float(cut))
                _set(prog, "opacity", float(p.opacity))
                _set(prog, "base_color", tuple(float(x) for x in p.color))
            if tex is not None:
                tex.use(location=0)
            vao = ctx.vertex_array(
                prog, bufs, index_buffer=_buffer(ctx, p.indices, "u4"), index_element_size=4
            )
            vao.render(instances=len(picked) or self.grid * self.grid)
            vao.release()
            for b in bufs:
                b[0].release()

    def _texture(self, image, wrap, small: bool = False):
        """The GL texture of a part's image, made once per image (calibration draws reuse it)."""
        key = (id(image), small)
        if key not in self._textures:
            img = self._white if image is None else (shrink(image) if small else image)
            self._textures[key] = (_texture(self.ctx, img, wrap), image)  # keeps `image` alive
        return self._textures[key][0]

    def strip(self, scene: Drawable, cells, keep: dict | None, cell: int) -> tuple[np.ndarray, np.ndarray]:
        """The views of `cells` side by side, `cell` px each (the cards' own images, finer than
        the atlas's cells), as read() gives the atlas: (albedo, normal + depth) uint8."""
        ctx, w = self.ctx, cell * len(cells)
        made: list = []  # released whatever happens
        try:
            made += [ctx.texture((w, cell), 4, internal_format=GL_SRGB8_ALPHA8), ctx.texture((w, cell), 4)]
            made.append(ctx.depth_renderbuffer((w, cell)))
            fbo = ctx.framebuffer(color_attachments=made[:2], depth_attachment=made[2])
            made.append(fbo)
            for prog in (self.bark, self.leaf):
                _set(prog, "strip", len(cells))
            self.draw(scene, cells, keep, (fbo, (w, cell)))
            out = [fbo.read(components=4, attachment=k, alignment=1) for k in range(2)]
        finally:
            for prog in (self.bark, self.leaf):
                _set(prog, "strip", 0)
            for res in reversed(made):
                res.release()
        albedo, normal = (np.frombuffer(d, np.uint8).reshape(cell, w, 4)[::-1] for d in out)
        return albedo, normal

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """(albedo RGBA, normal + depth RGBA) uint8 images of the last draw, top row first."""
        out = []
        for k in range(2):  # bottom row first: flipped as a view, copied once by the caller
            data = self.fbo.read(components=4, attachment=k, alignment=1)
            out.append(np.frombuffer(data, np.uint8).reshape(self.size, self.size, 4)[::-1])
        return out[0], out[1]

    def _rect(self, col: int, row: int) -> tuple[int, int, int, int]:
        """Cell (col, row)'s GL viewport (x, y, w, h): GL rows count from the bottom."""
        return (col * self.cell, self.size - (row + 1) * self.cell, self.cell, self.cell)

    def covered(self, cells) -> int:
        """Texels the last draw covered in `cells` [(col, row)] (alpha > 0)."""
        reads = (self.fbo.read(viewport=self._rect(*rc), components=4, alignment=1) for rc in cells)
        return sum(int(np.count_nonzero(np.frombuffer(data, np.uint8)[3::4])) for data in reads)


def render_atlas(
    scene: Drawable, centre: np.ndarray, radius: float, grid: int, cell: int
) -> tuple[np.ndarray, np.ndarray]:
    """(albedo RGBA, normal + depth RGBA) uint8 atlases of `scene`'s rest pose (generator
    space: pass a Drawable whose parts are Z up), top row first, as read-only views.
    Double-sided parts are leaves (the lean program), the others bark."""
    with AtlasRenderer(centre, radius, grid, cell) as r:
        r.draw(scene)
        return r.read()
