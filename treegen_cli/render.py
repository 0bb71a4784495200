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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .drawable import Drawable, Part
from .errors import TreegenError

FOV_DEG = 30.0  # vertical field of view of the preview camera
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
GL_SRGB8_ALPHA8 = 0x8C43


def skin_points(
    points: np.ndarray, joints: np.ndarray, weights: np.ndarray, skinning: np.ndarray
) -> np.ndarray:
    """Linear blend skinning on the CPU: Σ_k w_k · S[j_k] · p for (V, 3) points and (J, 4, 4)
    matrices. Used for framing (animated bounds) and as the reference for the shader."""
    p = np.asarray(points, dtype=np.float64)
    out = np.zeros_like(p)
    for k in range(joints.shape[1]):  # four influence slots, not vertices
        m = skinning[np.asarray(joints[:, k], dtype=np.int64)]
        out += weights[:, k, None] * (np.einsum("vij,vj->vi", m[:, :3, :3], p) + m[:, :3, 3])
    return out


# --------------------------------------------------------------------------------- cameras


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    f = np.asarray(target, float) - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-9:
        r = np.cross(f, (0.0, 0.0, 1.0))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / np.tan(np.radians(fov_deg) / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(half: float, near: float, far: float) -> np.ndarray:
    m = np.eye(4)
    m[0, 0] = m[1, 1] = 1.0 / half
    m[2, 2], m[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
    return m


def direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector (Y up) from the tree towards the viewer. Azimuth is measured in the
    generator's Z-up frame, counter-clockwise from +X (so 0 looks from +X, -90 from −Y)."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    zx, zy, zz = np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)
    return np.array([zx, zz, -zy])  # Z up → Y up: (x, y, z) → (x, z, −y)


@dataclass(frozen=True)
class Camera:
    eye: np.ndarray
    target: np.ndarray
    near: float
    far: float
    fov_deg: float = FOV_DEG

    def view_proj(self, aspect: float = 1.0) -> np.ndarray:
        return perspective(self.fov_deg, aspect, self.near, self.far) @ look_at(self.eye, self.target)


def frame_points(
    points: np.ndarray,
    azimuth_deg: float,
    elevation_deg: float,
    margin: float = 0.08,
    fov_deg: float = FOV_DEG,
) -> Camera:
    """A camera looking from (azimuth, elevation) that fits every point inside the view with
    `margin` (fraction of the half-height) to spare, centred on the points' screen extent."""
    pts = np.asarray(points, dtype=np.float64)
    lo, hi = pts.min(0), pts.max(0)
    target = 0.5 * (lo + hi)
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    back = direction(azimuth_deg, elevation_deg)
    tan_half = np.tan(np.radians(fov_deg) / 2) * (1.0 - margin)
    dist = 3.0 * radius
    for _ in range(4):  # fit distance, re-centre on the projected extent, fit again
        view = look_at(target + back * dist, target)
        v = pts @ view[:3, :3].T + view[:3, 3]  # camera space, looking down −z
        depth = -v[:, 2]
        x, y = v[:, 0] / depth, v[:, 1] / depth  # tangents of the view angles
        cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
        right, up = view[0, :3], view[1, :3]
        target = target + dist * (cx * right + cy * up)
        # distance at which every point's |x|,|y| tangent from the new centre fits tan_half
        rel = pts - target
        along = rel @ back  # towards the camera
        lateral = np.maximum(np.abs(rel @ right), np.abs(rel @ up))
        dist = float(np.max(along + lateral / tan_half))
    near = max(dist - radius * 1.5, dist * 0.02)
    return Camera(eye=target + back * dist, target=target, near=near, far=dist + radius * 60)


# --------------------------------------------------------------------------------- shaders

_COMMON = """
uniform vec3 sun_dir;          // towards the sun
uniform vec3 sun_color;
uniform mat4 light_vp;
uniform sampler2DShadow shadow_map;
uniform float shadow_bias;
uniform vec3 sky_zenith;
uniform vec3 sky_horizon;
uniform vec3 ground_color;

float sun_visibility(vec3 p, vec3 n) {
    vec4 l = light_vp * vec4(p + n * shadow_bias, 1.0);
    vec3 c = l.xyz / l.w * 0.5 + 0.5;
    if (any(lessThan(c.xy, vec2(0.0))) || any(greaterThan(c.xy, vec2(1.0)))) return 1.0;
    float s = 0.0;
    vec2 texel = 1.0 / vec2(textureSize(shadow_map, 0));
    for (int i = -1; i <= 1; i++)
        for (int j = -1; j <= 1; j++)
            s += texture(shadow_map, vec3(c.xy + vec2(i, j) * texel, c.z - 0.0015));
    return s / 9.0;
}

vec3 sky(vec3 d) {
    float h = clamp(d.y, 0.0, 1.0);
    return mix(sky_horizon, sky_zenith, pow(h, 0.6));
}

vec3 tonemap(vec3 c) {   // Reinhard on luminance-ish, then sRGB-like gamma
    c = c / (1.0 + c * 0.35);
    return pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2));
}
"""

_TREE_VS = """
#version 330
uniform mat4 view_proj;
uniform sampler2D skin;        // texel (c, j): column c of joint j's skinning matrix
in vec3 in_pos;
in vec3 in_normal;
in vec4 in_joints;
in vec4 in_weights;
in vec2 in_uv;
out vec3 v_pos;
out vec3 v_normal;
out vec2 v_uv;

mat4 joint_matrix(float j) {
    int r = int(j + 0.5);
    return mat4(texelFetch(skin, ivec2(0, r), 0), texelFetch(skin, ivec2(1, r), 0),
                texelFetch(skin, ivec2(2, r), 0), texelFetch(skin, ivec2(3, r), 0));
}

void main() {
    mat4 m = in_weights.x * joint_matrix(in_joints.x) + in_weights.y * joint_matrix(in_joints.y)
           + in_weights.z * joint_matrix(in_joints.z) + in_weights.w * joint_matrix(in_joints.w);
    vec4 p = m * vec4(in_pos, 1.0);
    v_pos = p.xyz;
    v_normal = mat3(m) * in_normal;
    v_uv = in_uv;
    gl_Position = view_proj * p;
}
"""

_TEX = """
uniform bool has_tex;
uniform sampler2D base_tex;
uniform ivec2 tex_wrap;        // per axis: 0 repeat, 1 clamp, 2 mirror (done here, GL clamps)
uniform float alpha_cutoff;    // < 0: opaque
uniform float opacity;
uniform float mip_bias;
uniform float hash_from;       // mip level where the cut-out starts turning into a hashed test

vec2 wrap_uv(vec2 uv, ivec2 mode) {
    vec2 m = 1.0 - abs(mod(uv, 2.0) - 1.0);
    return vec2(mode.x == 2 ? m.x : uv.x, mode.y == 2 ? m.y : uv.y);
}

// Explicit gradients: mirrored coordinates fold, the footprint must not; and the bias.
vec4 sample_tex(sampler2D t, vec2 uv, ivec2 mode) {
    float k = exp2(mip_bias);
    return textureGrad(t, wrap_uv(uv, mode), dFdx(uv) * k, dFdy(uv) * k);
}

// Cut-out test that survives minification. Up close: alpha against the cutoff, as an engine
// does. Where a texel covers many pixels' worth of blade (small or distant leaves) the
// filtered alpha is the blade's coverage of the footprint, and a fixed cutoff would keep all
// or nothing of it; there the threshold becomes a per-sample hash (hashed alpha testing,
// Wyman & McGuire 2017), so on average `alpha` of the samples pass and the 2×2 supersampling
// turns that into partial coverage. Deterministic: the hash is of the pixel and the card.
bool cut_away(float alpha, vec2 uv) {
    if (alpha_cutoff < 0.0) return false;
    vec2 size = vec2(textureSize(base_tex, 0));
    vec2 dx = dFdx(uv) * size, dy = dFdy(uv) * size;
    float lod = 0.5 * log2(max(max(dot(dx, dx), dot(dy, dy)), 1e-12));
    uvec2 q = uvec2(gl_FragCoord.xy);
    uint x = q.x * 73856093u ^ q.y * 19349663u ^ uint(gl_PrimitiveID >> 1) * 83492791u;
    x ^= x >> 16; x *= 0x7feb352du; x ^= x >> 15; x *= 0x846ca68bu; x ^= x >> 16;
    float h = (float(x) + 0.5) / 4294967296.0;
    return alpha < mix(alpha_cutoff, h, smoothstep(hash_from, hash_from + 2.0, lod));
}
"""

_TREE_FS = (
    """
#version 330
"""
    + _COMMON
    + _TEX
    + """
uniform vec3 base_color;
uniform bool leaf;
uniform bool receive_shadows;  // false: impostor cards (their shading is baked in the atlas)
uniform vec3 crown_center;
uniform vec3 crown_radius;
uniform vec3 eye;
uniform bool has_nmap;
uniform sampler2D normal_tex;
uniform ivec2 nmap_wrap;
uniform float normal_scale;
in vec3 v_pos;
in vec3 v_normal;
in vec2 v_uv;
out vec4 f_color;

float hash(uint x) {
    x ^= x >> 16; x *= 0x7feb352du; x ^= x >> 15; x *= 0x846ca68bu; x ^= x >> 16;
    return float(x) / 4294967295.0;
}

// Tangent frame from screen-space derivatives of position and UV (Schüler 2013): T along +u,
// B along +v, so an OpenGL/glTF normal map (+Y = +v, bottom-left UV origin) reads right.
mat3 cotangent_frame(vec3 n, vec3 p, vec2 uv) {
    vec3 dp1 = dFdx(p), dp2 = dFdy(p);
    vec2 duv1 = dFdx(uv), duv2 = dFdy(uv);
    vec3 dp2perp = cross(dp2, n), dp1perp = cross(n, dp1);
    vec3 t = dp2perp * duv1.x + dp1perp * duv2.x;
    vec3 b = dp2perp * duv1.y + dp1perp * duv2.y;
    float m = max(dot(t, t), dot(b, b));
    float inv = m > 0.0 ? inversesqrt(m) : 0.0;
    return mat3(t * inv, b * inv, n);
}

void main() {
    vec4 texel = has_tex ? sample_tex(base_tex, v_uv, tex_wrap) : vec4(1.0);
    vec3 nm = has_nmap ? sample_tex(normal_tex, v_uv, nmap_wrap).xyz * 2.0 - 1.0 : vec3(0, 0, 1);
    mat3 tbn = cotangent_frame(normalize(v_normal), v_pos, v_uv);   // derivatives: uniform flow
    if (has_tex && cut_away(texel.a * opacity, v_uv)) discard;
    vec3 n = normalize(v_normal);
    if (has_nmap) {
        vec3 p = normalize(tbn * vec3(nm.xy * normal_scale, nm.z));
        if (dot(p, p) > 0.5) n = p;                   // degenerate UVs: keep the vertex normal
    }
    if (!gl_FrontFacing) n = -n;                       // light the face we look at
    vec3 albedo = base_color * texel.rgb;
    if (leaf) {                                        // per-leaf tint (2 triangles a card)
        float h = hash(uint(gl_PrimitiveID) >> 1u);
        float k = has_tex ? 0.5 : 1.0;                 // textures bring their own variation
        albedo *= 1.0 + k * (vec3(0.3 * h, 0.4 * h, 0.2 * h) - vec3(0.15, 0.2, 0.2));
    }
    float ndl = dot(n, sun_dir);
    float vis = receive_shadows ? sun_visibility(v_pos, n) : 1.0;
    // Light through a leaf (sun behind it) is filtered twice by the blade: yellower, and
    // brightest when looking into the sun (forward scattering).
    float toward = max(dot(normalize(v_pos - eye), sun_dir), 0.0);
    float through = leaf ? max(-ndl, 0.0) * (0.3 + 0.9 * toward * toward * toward) : 0.0;
    vec3 trans = albedo * vec3(1.15, 1.2, 0.5) * through;
    // inner crown gets less sky: a cheap ambient occlusion from the depth in the crown
    float r = length((v_pos - crown_center) / crown_radius);
    float ao = mix(0.45, 1.0, smoothstep(0.1, 1.0, r));
    vec3 hemi = mix(ground_color * 0.6, sky_zenith * 0.9 + 0.1, 0.5 + 0.5 * n.y);
    vec3 c = albedo * (sun_color * max(ndl, 0.0) * vis + hemi * ao) + sun_color * vis * trans;
    f_color = vec4(tonemap(c), 1.0);
}
"""
)

_DEPTH_FS = (
    """
#version 330
"""
    + _TEX
    + """
in vec2 v_uv;
void main() {        // cut-outs cast cut-out shadows
    if (has_tex && cut_away(sample_tex(base_tex, v_uv, tex_wrap).a * opacity, v_uv)) discard;
}
"""
)

_SKY_VS = """
#version 330
in vec2 in_ndc;
out vec2 v_ndc;
void main() { v_ndc = in_ndc; gl_Position = vec4(in_ndc, 0.9999, 1.0); }
"""

_SKY_FS = (
    """
#version 330
"""
    + _COMMON
    + """
uniform mat4 inv_view_proj;
in vec2 v_ndc;
out vec4 f_color;
void main() {
    vec4 a = inv_view_proj * vec4(v_ndc, -1.0, 1.0);
    vec4 b = inv_view_proj * vec4(v_ndc, 1.0, 1.0);
    vec3 d = normalize(b.xyz / b.w - a.xyz / a.w);
    f_color = vec4(tonemap(sky(d)), 1.0);
}
"""
)

_GROUND_VS = """
#version 330
uniform mat4 view_proj;
uniform float ground_y;
uniform float ground_half;
uniform vec3 ground_center;
in vec2 in_xz;
out vec3 v_pos;
void main() {
    v_pos = vec3(ground_center.x + in_xz.x * ground_half, ground_y,
                 ground_center.z + in_xz.y * ground_half);
    gl_Position = view_proj * vec4(v_pos, 1.0);
}
"""

_GROUND_FS = (
    """
#version 330
"""
    + _COMMON
    + """
uniform vec3 eye;
uniform float fog_start;
uniform float fog_end;
in vec3 v_pos;
out vec4 f_color;
void main() {
    vec3 n = vec3(0.0, 1.0, 0.0);
    float vis = sun_visibility(v_pos, n);
    vec3 c = ground_color * (sun_color * max(sun_dir.y, 0.0) * vis + sky_zenith * 0.8);
    float fog = smoothstep(fog_start, fog_end, length(v_pos.xz - eye.xz));
    vec3 d = normalize(v_pos - eye);
    f_color = vec4(tonemap(mix(c, sky(vec3(d.x, 0.0, d.z)), fog)), 1.0);
}
"""
)


# The GL and EGL libraries by their usual sonames (libglvnd, Mesa): left unnamed, glcontext
# looks each up with ctypes.util.find_library, which forks `ldconfig -p`, twice per context
# (13 ms of CPU in a process the size of `make`'s). If they do not load, the lookup runs.
# GLCONTEXT_LINUX_LIBGL / GLCONTEXT_LINUX_LIBEGL still override either.
GL_LIBRARIES = {"libgl": "libGL.so.1", "libegl": "libEGL.so.1"}


def _context():
    try:
        import moderngl
    except ImportError as e:
        raise TreegenError(f"preview needs moderngl (pip install moderngl): {e}") from None
    try:
        return moderngl.create_standalone_context(backend="egl", require=330, **GL_LIBRARIES)
    except Exception:
        pass
    try:
        return moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as e:  # no EGL / no GPU driver: say so in one line
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise TreegenError(f"preview: cannot create a headless OpenGL (EGL) context: {msg}") from None


def egl_available() -> bool:
    """True when a headless OpenGL 3.3 context can be made here (tests skip otherwise)."""
    try:
        ctx = _context()
    except TreegenError:
        return False
    ctx.release()
    return True


# --------------------------------------------------------------------------------- textures


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    x = c.astype(np.float32) / np.float32(255.0)
    return np.where(
        x <= 0.04045, x / np.float32(12.92), ((x + np.float32(0.055)) / np.float32(1.055)) ** np.float32(2.4)
    )


def _linear_to_srgb8(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)


def _half(a: np.ndarray) -> np.ndarray:
    """Next mip level of (H, W, C) float32, GL's size rule (each side floor(n / 2), at least 1):
    a 2-tap box on even sides, a 1-2-1 tent over the 2n + 1 texels of odd ones."""
    for axis in (0, 1):
        n = a.shape[axis]
        if n == 1:
            continue
        even = np.take(a, np.arange(0, n - 1, 2), axis=axis)
        odd = np.take(a, np.arange(1, n, 2), axis=axis)
        if n % 2 == 0:
            a = 0.5 * (even + odd)
        else:
            nxt = np.take(a, np.arange(2, n, 2), axis=axis)
            a = 0.25 * even + 0.5 * odd + 0.25 * nxt
    return a


def mip_chain(image: np.ndarray, srgb: bool) -> list[np.ndarray]:
    """Every mip level of a uint8 (H, W, C) image, level 0 first, box-filtered in linear light
    (GL's own mipmap generation is not specified to be; colour must not darken as it shrinks).

    Colour is averaged weighted by alpha (no dark fringes from transparent texels); alpha is the
    plain mean, the blade's coverage of the texel, which the hashed cut-out test relies on."""
    img = np.asarray(image)
    lin = img.astype(np.float32) / np.float32(255.0)
    if srgb:
        lin[..., :3] = _srgb_to_linear(img[..., :3])
    has_alpha = img.shape[2] == 4
    if has_alpha:
        lin[..., :3] *= lin[..., 3:]  # premultiplied while filtering
    levels, cur = [np.ascontiguousarray(img)], lin
    while cur.shape[0] > 1 or cur.shape[1] > 1:
        cur = _half(cur)
        out = cur.copy()
        if has_alpha:
            a = out[..., 3:]
            out[..., :3] = np.where(a > 1e-6, out[..., :3] / np.maximum(a, 1e-6), 0.0)
        enc = np.empty(out.shape, np.uint8)
        enc[..., :3] = (
            _linear_to_srgb8(out[..., :3])
            if srgb
            else np.round(np.clip(out[..., :3], 0, 1) * 255).astype(np.uint8)
        )
        if has_alpha:
            enc[..., 3] = np.round(out[..., 3] * 255).astype(np.uint8)
        levels.append(enc)
    return levels


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
        ctx = self.ctx = _context()
        self.tree_prog = ctx.program(vertex_shader=_TREE_VS, fragment_shader=_TREE_FS)
        self.depth_prog = ctx.program(vertex_shader=_TREE_VS, fragment_shader=_DEPTH_FS)
        self.sky_prog = ctx.program(vertex_shader=_SKY_VS, fragment_shader=_SKY_FS)
        self.ground_prog = ctx.program(vertex_shader=_GROUND_VS, fragment_shader=_GROUND_FS)
        W, H = width * supersample, height * supersample
        self.color = ctx.renderbuffer((W, H), 4)
        self.depth = ctx.depth_renderbuffer((W, H))
        self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)
        self.shadow_tex = ctx.depth_texture((SHADOW_SIZE, SHADOW_SIZE))
        self.shadow_tex.compare_func = "<="
        self.shadow_tex.repeat_x = self.shadow_tex.repeat_y = False
        self.shadow_fbo = ctx.framebuffer(depth_attachment=self.shadow_tex)
        self.skin_tex = ctx.texture((4, max(scene.n_joints, 1)), 4, dtype="f4")
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
        tex = self._texture(p.texture, True, p.wrap) if p.textured else None
        nmap = self._texture(p.normal_map, False, p.normal_wrap) if p.bumpy else None
        return _GpuPart(vao, dvao, p, tex, nmap)

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
        lo, hi = pts.min(0), pts.max(0)
        self.bounds = (lo, hi)
        leaves = [p.positions for p in self.scene.parts if p.double_sided and len(p.positions)]
        crown = np.concatenate(leaves).astype(np.float64) if leaves else pts
        clo, chi = crown.min(0), crown.max(0)
        self.crown_center = 0.5 * (clo + chi)
        self.crown_radius = np.maximum(0.5 * (chi - clo), 0.05 * max(float(np.max(hi - lo)), 1e-3))

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
        self._set(self.tree_prog, "crown_center", self.crown_center)
        self._set(self.tree_prog, "crown_radius", self.crown_radius)
        self._set(self.tree_prog, "eye", camera.eye)
        self._set(self.tree_prog, "base_tex", 2)
        self._set(self.tree_prog, "normal_tex", 3)
        self._set(self.tree_prog, "mip_bias", MIP_BIAS)
        self._set(self.tree_prog, "hash_from", HASH_LOD)
        for g in self.parts if draw_tree else []:
            self._set(self.tree_prog, "base_color", g.part.color)
            self._set(self.tree_prog, "leaf", g.part.double_sided)
            self._set(self.tree_prog, "receive_shadows", g.part.receives_shadows)
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
