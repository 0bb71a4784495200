"""The headless OpenGL context (moderngl on EGL; Mesa llvmpipe will do), and textures' mip
levels made on the CPU in linear light, as GL's own mipmap generation is not specified to."""

from __future__ import annotations

import numpy as np

from .errors import TreegenError

GL_SRGB8_ALPHA8 = 0x8C43


# The GL and EGL libraries by their usual sonames (libglvnd, Mesa): left unnamed, glcontext
# looks each up with ctypes.util.find_library, which forks `ldconfig -p`, twice per context
# (13 ms of CPU in a process the size of `make`'s). If they do not load, the lookup runs.
# GLCONTEXT_LINUX_LIBGL / GLCONTEXT_LINUX_LIBEGL still override either.
GL_LIBRARIES = {"libgl": "libGL.so.1", "libegl": "libEGL.so.1"}


def gl_context():
    """A headless OpenGL 3.3 context on EGL, or a one-line TreegenError saying why not (moderngl
    is imported here: only drawing pays for it)."""
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
        ctx = gl_context()
    except TreegenError:
        return False
    ctx.release()
    return True


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
