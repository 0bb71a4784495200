"""The impostor atlas in one batched draw: every view of a hemi-octahedral grid rendered at once.

    albedo, normal_depth = render_atlas(drawable, centre, radius, grid=16, cell=128)
    # Result: two uint8 (grid·cell, grid·cell, 4) images, top row first: sRGB albedo + alpha
    # (coverage), and (a, b, up)-frame normals · 0.5 + 0.5 with depth in alpha.

Each view is an orthographic camera on the bounding sphere (centre, radius) looking at the
centre from the direction its cell's centre decodes to (impostor.cell_direction: the same
formula, in GLSL here). One instanced draw call per part: the vertex shader picks the instance's
cell, projects the rest-pose vertex into the view and places it inside the cell, whose square
holds the whole sphere, so nothing leaks into a neighbour. Rendered on render.py's context with
its texture conventions; a plain cut-out test (the views are small: one sample a pixel). Space is the generator's (Z up): a, b, up = +X, +Y, +Z.
"""
from __future__ import annotations

import numpy as np

from .drawable import Drawable
from .errors import TreegenError
from .render import GL_SRGB8_ALPHA8, _context

# A card faces the light as one surface; a crown's leaves face every way and shade each other.
# Leaves' albedo is scaled by this so the cards, lit by an engine, match the coarsest LOD's
# brightness at the switch (measured with the preview renderer: the aspen's cards came out
# 2.1× brighter than its LOD3 without it, 0.9-1.1× with it).
LEAF_SHADE = 0.4

_ATLAS_VS = """
#version 330
uniform vec3 centre;
uniform float radius;
uniform int grid;
in vec3 in_pos;
in vec3 in_normal;
in vec2 in_uv;
out vec3 v_normal;
out vec2 v_uv;
out float v_depth;
out vec3 v_rel;

vec3 cell_direction(int col, int row) {        // hemi-octahedral decode of the cell centre
    vec2 q = (vec2(col, row) + 0.5) / float(grid) * 2.0 - 1.0;
    q.y = -q.y;                                   // rows count from the top of the image
    vec2 p = vec2(q.x + q.y, q.x - q.y) * 0.5;
    return normalize(vec3(p, 1.0 - abs(p.x) - abs(p.y)));
}

void main() {
    int col = gl_InstanceID % grid, row = gl_InstanceID / grid;
    vec3 d = cell_direction(col, row);            // from the centre towards the viewer
    vec3 right = cross(vec3(0.0, 0.0, 1.0), d);
    right = dot(right, right) > 1e-10 ? normalize(right) : vec3(0.0, 1.0, 0.0);
    vec3 up = cross(d, right);
    vec3 rel = (in_pos - centre) / radius;
    vec3 l = vec3(dot(rel, right), dot(rel, up), dot(rel, d));
    float n = float(grid);
    gl_Position = vec4((float(col) + 0.5 + 0.5 * l.x) / n * 2.0 - 1.0,
                       1.0 - (float(row) + 0.5 - 0.5 * l.y) / n * 2.0, -l.z, 1.0);
    v_normal = in_normal;
    v_uv = in_uv;
    v_depth = 0.5 + 0.5 * l.z;
    v_rel = rel;
}
"""

_ATLAS_FS = """
#version 330
uniform bool has_tex;
uniform sampler2D base_tex;
uniform float alpha_cutoff;    // < 0: opaque
uniform float opacity;
uniform vec3 base_color;
uniform bool leaf;
uniform float leaf_shade;
uniform vec3 crown_centre;
uniform vec3 crown_radius;
in vec3 v_normal;
in vec2 v_uv;
in float v_depth;
in vec3 v_rel;
layout(location = 0) out vec4 f_albedo;
layout(location = 1) out vec4 f_normal;

void main() {
    vec4 texel = has_tex ? texture(base_tex, v_uv) : vec4(1.0);
    if (texel.a * opacity < alpha_cutoff) discard;
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    // baked, as cards have no crown to shade them: the inner crown gets less sky (render.py's
    // occlusion), and each leaf its own tint as the preview gives it (2 triangles a card)
    float r = length((v_rel - crown_centre) / crown_radius);
    float ao = mix(0.45, 1.0, smoothstep(0.1, 1.0, r));
    vec3 albedo = base_color * texel.rgb;
    if (leaf) {
        uint x = uint(gl_PrimitiveID) >> 1u;
        x ^= x >> 16; x *= 0x7feb352du; x ^= x >> 15; x *= 0x846ca68bu; x ^= x >> 16;
        float h = float(x) / 4294967295.0;
        albedo *= 1.0 + 0.5 * (vec3(0.3 * h, 0.4 * h, 0.2 * h) - vec3(0.15, 0.2, 0.2));
        albedo *= leaf_shade;
    }
    f_albedo = vec4(albedo * ao, 1.0);                      // linear; sRGB-encoded by the target
    f_normal = vec4(n * 0.5 + 0.5, v_depth);
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
    tex = ctx.texture((w, h), 4, np.ascontiguousarray(img[::-1]).tobytes(),
                      internal_format=GL_SRGB8_ALPHA8)
    tex.repeat_x, tex.repeat_y = (m == "REPEAT" for m in wrap)
    tex.filter = (ctx.LINEAR, ctx.LINEAR)
    return tex


def _set(prog, name, value) -> None:
    if name in prog:
        prog[name].value = value


def render_atlas(scene: Drawable, centre: np.ndarray, radius: float, grid: int,
                 cell: int) -> tuple[np.ndarray, np.ndarray]:
    """(albedo RGBA, normal + depth RGBA) uint8 atlases of `scene`'s rest pose (generator
    space: pass a Drawable whose parts are Z up), top row first."""
    try:
        ctx = _context()
    except TreegenError as e:          # the default make must say what to do without EGL
        raise TreegenError(f"impostor: {str(e).removeprefix('preview: ')} "
                           "(make it with --no-impostor)") from None
    try:
        prog = ctx.program(vertex_shader=_ATLAS_VS, fragment_shader=_ATLAS_FS)
        size = grid * cell
        albedo = ctx.texture((size, size), 4, internal_format=GL_SRGB8_ALPHA8)
        normal = ctx.texture((size, size), 4)
        depth = ctx.depth_renderbuffer((size, size))
        fbo = ctx.framebuffer(color_attachments=[albedo, normal], depth_attachment=depth)
        fbo.use()
        ctx.viewport = (0, 0, size, size)
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.enable_direct(0x8DB9)                       # GL_FRAMEBUFFER_SRGB: linear → sRGB
        ctx.disable(ctx.CULL_FACE)
        c = np.asarray(centre, np.float64)
        leaves = [p.positions for p in scene.parts if p.double_sided and len(p.positions)]
        crown = np.concatenate(leaves).astype(np.float64) if leaves else \
            np.concatenate([p.positions for p in scene.parts])
        clo, chi = (crown.min(0) - c) / radius, (crown.max(0) - c) / radius
        _set(prog, "centre", tuple(float(x) for x in c))
        _set(prog, "radius", float(radius))
        _set(prog, "grid", int(grid))
        _set(prog, "leaf_shade", LEAF_SHADE)
        _set(prog, "crown_centre", tuple(float(x) for x in 0.5 * (clo + chi)))
        _set(prog, "crown_radius", tuple(float(x) for x in np.maximum(0.5 * (chi - clo), 0.05)))
        _set(prog, "base_tex", 0)
        for p in scene.parts:
            if not len(p.indices):
                continue
            bufs = [(ctx.buffer(np.ascontiguousarray(p.positions, "f4").tobytes()), "3f", "in_pos"),
                    (ctx.buffer(np.ascontiguousarray(p.normals, "f4").tobytes()), "3f", "in_normal")]
            uvs = p.uvs if p.uvs is not None else np.zeros((len(p.positions), 2), np.float32)
            bufs.append((ctx.buffer(np.ascontiguousarray(uvs, "f4").tobytes()), "2f", "in_uv"))
            ibo = ctx.buffer(np.ascontiguousarray(p.indices, "u4").tobytes())
            vao = ctx.vertex_array(prog, bufs, index_buffer=ibo, index_element_size=4)
            tex = _texture(ctx, p.texture, p.wrap) if p.textured else None
            _set(prog, "has_tex", tex is not None)
            if tex is not None:
                tex.use(location=0)
            cut = p.alpha_cutoff if tex is not None and p.alpha_cutoff is not None else -1.0
            _set(prog, "alpha_cutoff", float(cut))
            _set(prog, "opacity", float(p.opacity))
            _set(prog, "base_color", tuple(float(x) for x in p.color))
            _set(prog, "leaf", bool(p.double_sided))
            vao.render(instances=grid * grid)
        out = []
        for k in range(2):
            data = fbo.read(components=4, attachment=k, alignment=1)
            out.append(np.frombuffer(data, np.uint8).reshape(size, size, 4)[::-1].copy())
        return out[0], out[1]
    finally:
        ctx.release()
