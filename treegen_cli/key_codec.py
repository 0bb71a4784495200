"""What a client reads back from a compressed file's rotation keys, to the bit: normalized
int16, and meshoptimizer's QUATERNION filter (both of its decoders) and EXPONENTIAL filter.

Result: stored(rotations, wide, bits, simd) → (K, J, 4) rotations as that client decodes
them; key_plan checks its 1 mm bound against these, the glTF writer encodes the same keys.
"""

from __future__ import annotations

import numpy as np

from .axes import quat_from_y_up, quat_to_y_up
from .quat import unit


def quat_filter(q: np.ndarray, bits: np.ndarray, simd: bool = True) -> np.ndarray:
    """Unit quaternions (K, J, 4) as a client reads them back from meshoptimizer's QUATERNION
    filter at `bits` (J,), to the bit: the writer's source (Y up, float32), the encoder's
    float32 rounding of the three smallest components times √2 to bits − 1 bits (half away
    from zero), and one of its two decoders' float32 arithmetic (w = √(2s² − Σ) unscaled, then
    all four times 32767/√2/s, as int16). `simd`: the SIMD decoder (SSE/NEON, WebAssembly
    SIMD: Σ = x² + (y² + z²), rounded half to even); else the scalar one (WebAssembly without
    SIMD, native builds without SSE/NEON: 2s² − x² − y² − z² left to right, rounded half away
    from zero). The two differ by one int16 step on ~1 key in 600, a float64 model on ~1 in
    1,000, and one step of a crown-carrying joint moves the crown by ~0.2 mm."""
    f32 = np.float32
    src = unit(quat_to_y_up(q)).astype(f32)
    top = np.argmax(np.abs(src), axis=-1)[..., None]
    sign = np.where(np.take_along_axis(src, top, axis=-1) < 0, f32(-1.0), f32(1.0))
    s = (f32(2.0) ** (np.asarray(bits)[:, None] - 1) - f32(1.0)).astype(f32)
    v = np.clip(src * np.sqrt(f32(2.0)) * sign, f32(-1.0), f32(1.0))
    c = np.trunc(v * s + np.where(v >= 0, f32(0.5), f32(-0.5)))
    np.put_along_axis(c, top, f32(0.0), axis=-1)
    sq = np.take_along_axis(c * c, (top + np.arange(1, 4)) % 4, axis=-1)  # the stored order
    x2, y2, z2 = sq[..., :1], sq[..., 1:2], sq[..., 2:]
    ww = (s * s + s * s) - (x2 + (y2 + z2)) if simd else (s * s * f32(2.0) - x2) - y2 - z2
    np.put_along_axis(c, top, np.sqrt(np.maximum(ww, f32(0.0))), axis=-1)
    v = c * ((f32(32767.0) / np.sqrt(f32(2.0))) / s)
    out = np.rint(v) if simd else np.trunc(v + np.where(c >= 0, f32(0.5), f32(-0.5)))
    return quat_from_y_up(out.astype(np.float64) / 32767.0)


def exp_filter(q: np.ndarray, bits: np.ndarray) -> np.ndarray:
    """Unit quaternions (K, J, 4) as a client reads them back from meshoptimizer's EXPONENTIAL
    filter (one exponent per vector) at `bits` (J,) of mantissa, to the bit: the writer's
    float32 source (Y up) in steps of 2^(e + 1 − bits), e the largest component's binary
    exponent (frexp's: 0 for [0.5, 1), so steps of 2^(1 − bits) but where a component is ±1),
    rounded half away from zero."""
    f32 = np.float32
    src = unit(quat_to_y_up(q)).astype(f32)
    e = np.frexp(src)[1].max(axis=-1, keepdims=True) - (np.asarray(bits)[:, None] - 1)
    m = np.trunc(np.ldexp(src, -e) + np.where(src >= 0, f32(0.5), f32(-0.5)))
    return quat_from_y_up(np.ldexp(m.astype(np.float64), e))


def stored(
    rotations: np.ndarray, wide: np.ndarray, bits: np.ndarray | None = None, simd: bool = True
) -> np.ndarray:
    """Rotations (K, J, 4) as a client reads them back: normalized int16 (c / 32767, as
    compress.snorm16 writes them), or meshopt's QUATERNION filter at `bits` per joint when
    given (its SIMD or scalar decoder: `simd`), except the `wide` joints' float32 (meshopt:
    its EXPONENTIAL filter at `bits` of mantissa, the same in both decoders)."""
    if bits is None:
        out = np.rint(np.clip(rotations, -1.0, 1.0) * 32767.0) / 32767.0
        out[:, wide] = rotations[:, wide].astype(np.float32).astype(np.float64)
        return out
    out = quat_filter(rotations, np.minimum(bits, 16), simd)
    out[:, wide] = exp_filter(rotations[:, wide], bits[wide])
    return out


def decodes(bits: np.ndarray | None) -> tuple[bool, ...]:
    """The decoders a plan must hold for (`stored`'s `simd`): meshopt's QUATERNION filter has
    two that round some keys apart (SIMD, scalar), quantize's int16 one."""
    return (True,) if bits is None else (True, False)
