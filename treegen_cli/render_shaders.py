"""GLSL of the preview renderer (render.py): the skinning vertex shader, the tree's lit
fragment shader (sun with a shadow map, hemisphere ambient, light through leaves, normal maps,
hashed cut-outs), the shadow pass's depth shader, the sky and the ground."""

from __future__ import annotations

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


TREE_VS = """
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
uniform int leaf_tris;         // triangles a leaf: 2 (card), 1 (triangle card): one hash a leaf

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
    uint x = q.x * 73856093u ^ q.y * 19349663u ^ (uint(gl_PrimitiveID) / uint(max(leaf_tris, 1))) * 83492791u;
    x ^= x >> 16; x *= 0x7feb352du; x ^= x >> 15; x *= 0x846ca68bu; x ^= x >> 16;
    float h = (float(x) + 0.5) / 4294967296.0;
    return alpha < mix(alpha_cutoff, h, smoothstep(hash_from, hash_from + 2.0, lod));
}
"""


TREE_FS = (
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
    if (leaf) {                                        // per-leaf tint
        float h = hash(uint(gl_PrimitiveID) / uint(max(leaf_tris, 1)));
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
    // inner crown gets less sky: a cheap ambient occlusion from the depth in the crown; not on
    // impostor cards, whose atlas has it baked (a card through the crown's centre got it twice)
    float r = length((v_pos - crown_center) / crown_radius);
    float ao = receive_shadows ? mix(0.45, 1.0, smoothstep(0.1, 1.0, r)) : 1.0;
    vec3 hemi = mix(ground_color * 0.6, sky_zenith * 0.9 + 0.1, 0.5 + 0.5 * n.y);
    vec3 c = albedo * (sun_color * max(ndl, 0.0) * vis + hemi * ao) + sun_color * vis * trans;
    f_color = vec4(tonemap(c), 1.0);
}
"""
)


DEPTH_FS = (
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


SKY_VS = """
#version 330
in vec2 in_ndc;
out vec2 v_ndc;
void main() { v_ndc = in_ndc; gl_Position = vec4(in_ndc, 0.9999, 1.0); }
"""


SKY_FS = (
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


GROUND_VS = """
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


GROUND_FS = (
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
