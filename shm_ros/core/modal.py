"""Mode-shape helpers used by every stage: MAC, complex-to-real shapes, unit scaling.

* :func:`mac` - modal assurance criterion of pairs of shapes (along the last axis, broadcasting;
  components missing (NaN) in either shape are left out);
* :func:`mac_matrix` - MAC of every shape of one set against every shape of another (batched);
* :func:`real_shape` - a complex shape rotated to its best real phase, largest component +1;
* :func:`unit_max` - a real shape scaled so its largest-magnitude component is +1;
* :func:`sign_aligned` - real shapes with the sign that agrees with a reference (batched).

All accept complex shapes: MAC = |a^H b|^2 / (|a|^2 |b|^2), which is the usual real formula for real
shapes. Where a shape is all zeros the MAC is 0 (not NaN).
"""

from __future__ import annotations

import numpy as np

__all__ = ["mac", "mac_matrix", "real_shape", "sign_aligned", "unit_max"]


def mac(a: np.ndarray, b: np.ndarray, min_common: int = 1) -> np.ndarray:
    """MAC of shapes ``a`` and ``b`` along the last axis (broadcasting) -> shape of the broadcast
    without the last axis (a float for two vectors).

    Components that are not finite in either shape are left out of both; fewer than ``min_common``
    common components give 0 (MAC of one component is always 1, which says nothing).
    """
    a, b = np.broadcast_arrays(np.asarray(a), np.asarray(b))
    ok = np.isfinite(a) & np.isfinite(b)
    if not ok.all():
        a, b = np.where(ok, a, 0), np.where(ok, b, 0)
    num = np.abs(np.sum(np.conj(a) * b, axis=-1)) ** 2
    den = np.sum(np.abs(a) ** 2, axis=-1) * np.sum(np.abs(b) ** 2, axis=-1)
    usable = (den > 0) & (np.sum(ok, axis=-1) >= min_common)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(usable, num / np.where(den > 0, den, 1.0), 0.0)
    return out[()] if out.ndim == 0 else out


def mac_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """MAC of every row of ``a`` (..., p, n) against every row of ``b`` (..., q, n) -> (..., p, q).

    Leading axes broadcast (e.g. observed shapes (p, n) against a batch of model shapes (B, q, n)).
    No NaN handling: this is the hot path of the likelihoods; pass finite shapes.
    """
    a = np.asarray(a)
    b = np.asarray(b)
    bt = np.swapaxes(b, -1, -2)
    cross = (np.conj(a) if np.iscomplexobj(a) else a) @ bt
    num = np.abs(cross) ** 2 if np.iscomplexobj(cross) else cross * cross
    na = np.sum(np.abs(a) ** 2, axis=-1)[..., :, None]
    nb = np.sum(np.abs(b) ** 2, axis=-1)[..., None, :]
    den = na * nb
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def real_shape(shape: np.ndarray) -> np.ndarray:
    """A complex shape rotated to its best real phase, scaled so the largest |component| is +1.

    The rotation angle theta maximises sum Re(v e^{-i theta})^2, i.e. 2 theta = arg(sum v^2) (the
    principal axis of the points (Re v, Im v)). The result does not depend on a complex scale of
    ``shape``. An all-zero shape gives zeros.
    """
    v = np.asarray(shape, dtype=complex)
    theta = 0.5 * np.angle(np.sum(v * v))
    r = (v * np.exp(-1j * theta)).real
    return unit_max(r)


def unit_max(v: np.ndarray) -> np.ndarray:
    """``v`` divided by its largest-magnitude component (so that component is +1); zeros stay zeros."""
    v = np.asarray(v)
    if v.size == 0:
        return v.astype(float)
    k = int(np.argmax(np.abs(v)))
    return v / v[k] if v[k] != 0 else np.zeros(v.shape)


def sign_aligned(shape: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Real ``shape`` with the sign that agrees with ``ref`` (along the last axis, broadcasting) on
    their common finite components; unchanged where they share none or are orthogonal."""
    a, b = np.asarray(shape, dtype=float), np.asarray(ref, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    dot = np.sum(np.where(ok, a * b, 0.0), axis=-1, keepdims=True)
    return np.where(dot < 0, -a, a)
