"""Eigenvalues of a real matrix now, eigenvectors of chosen eigenvalues later.

A stabilization diagram needs every eigenvalue of the state matrix of every model order (about
200 matrices of up to 100 x 100 per window with both estimates of ``A``), but mode shapes only of
the poles that can become modes (those that recur at the neighbouring order). ``scipy.linalg.eig``
computes all eigenvectors or none. LAPACK does the split itself: ``dlahqr``/``dhseqr`` give the
eigenvalues of the Hessenberg form, ``dhsein`` the eigenvectors of selected eigenvalues by inverse
iteration (O(n^2) each) and ``dormhr`` takes them back to the original basis. scipy ships these
in ``scipy.linalg.cython_lapack`` but does not wrap them for Python, so they are called here
through their C entry points with ``ctypes`` (the project's only hand-written LAPACK glue; without
them, e.g. on another scipy build, everything falls back to ``scipy.linalg.eig``).

Steps for a matrix ``A``: optional balancing by diagonal scaling ``D`` (as ``dgeev`` does),
Hessenberg form ``D^-1 A D = Q H Q^T`` (``dgehrd``), eigenvalues of ``H``; later, for chosen
eigenvalues, vectors ``x`` of ``H`` and ``v = D Q x``.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

__all__ = ["Eigenvalues", "eigenvalues", "eigenvectors", "AVAILABLE"]


# LAPACK's Fortran calling convention: every argument by reference, no return value. Character
# options are single bytes, integers 32-bit (scipy's LAPACK is not ILP64), matrices contiguous in
# column-major order: each prototype below spells this out. Arrays go as their data address
# (``_DBL``/``_I32``), checked by :func:`_call` for type and layout: numpy's ``ndpointer`` does
# the same check but costs about 5 us an argument, a fifth of a small matrix's whole call.
_CHR = ctypes.c_char_p
_INT = ctypes.POINTER(ctypes.c_int)
_DBL = ctypes.c_void_p  # float64 matrix, vector or workspace, column-major
_I32 = ctypes.c_void_p  # int32 vector
_PROTOTYPES: dict[str, tuple] = {
    # job, compz, n, ilo, ihi, h, ldh, wr, wi, z, ldz, work, lwork, info
    "dhseqr": (_CHR, _CHR, _INT, _INT, _INT, _DBL, _INT, _DBL, _DBL, _DBL, _INT, _DBL, _INT, _INT),
    # wantt, wantz, n, ilo, ihi, h, ldh, wr, wi, iloz, ihiz, z, ldz, info
    "dlahqr": (_INT, _INT, _INT, _INT, _INT, _DBL, _INT, _DBL, _DBL, _INT, _INT, _DBL, _INT, _INT),
    # side, eigsrc, initv, select, n, h, ldh, wr, wi, vl, ldvl, vr, ldvr, mm, m, work, ifaill,
    # ifailr, info
    "dhsein": (_CHR, _CHR, _CHR, _I32, _INT, _DBL, _INT, _DBL, _DBL, _DBL, _INT, _DBL, _INT, _INT,
               _INT, _DBL, _I32, _I32, _INT),
    # side, trans, m, n, ilo, ihi, a, lda, tau, c, ldc, work, lwork, info
    "dormhr": (_CHR, _CHR, _INT, _INT, _INT, _INT, _DBL, _INT, _DBL, _DBL, _INT, _DBL, _INT, _INT),
}


def _capsule_pointer(capsule: object) -> int | None:
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype = ctypes.c_char_p
    get_name.argtypes = [ctypes.py_object]
    get_ptr = ctypes.pythonapi.PyCapsule_GetPointer
    get_ptr.restype = ctypes.c_void_p
    get_ptr.argtypes = [ctypes.py_object, ctypes.c_char_p]
    return get_ptr(capsule, get_name(capsule))


def _bind(name: str) -> Callable[..., None] | None:
    """The LAPACK routine ``name`` of scipy's own LAPACK, typed by its prototype, or None."""
    try:
        import scipy.linalg.cython_lapack as cl

        ptr = _capsule_pointer(cl.__pyx_capi__[name])
    except (ImportError, KeyError, AttributeError, ValueError):
        return None
    if not ptr:
        return None
    fn: Callable[..., None] = ctypes.CFUNCTYPE(None, *_PROTOTYPES[name])(ptr)
    return fn


_HSEQR = _bind("dhseqr")
_LAHQR = _bind("dlahqr")
_HSEIN = _bind("dhsein")
_ORMHR = _bind("dormhr")
AVAILABLE = None not in (_HSEQR, _LAHQR, _HSEIN, _ORMHR)
# dhseqr hands matrices above 75 to the multishift QR with aggressive early deflation, which on
# the 75..150 state matrices of a diagram is ~40 % slower than the double-shift dlahqr it uses
# below that size; dlahqr is therefore called directly up to this size.
_LAHQR_MAX = 150


def _int(v: int) -> ctypes.c_int:
    return ctypes.c_int(v)


def _address(a: np.ndarray) -> int:
    """Data address of a float64 or int32 array in column-major order (a vector: contiguous)."""
    if a.dtype not in (np.float64, np.int32) or not a.flags.f_contiguous:
        raise TypeError(f"LAPACK argument must be a column-major float64/int32 array, got {a.dtype}")
    return a.ctypes.data


def _call(fn: Callable[..., None] | None, *args: bytes | ctypes.c_int | np.ndarray) -> None:
    """Call a LAPACK entry point; ``c_int`` arguments go by reference, arrays by address."""
    assert fn is not None, "LAPACK entry point missing (callers check AVAILABLE)"
    fn(*[a if isinstance(a, (ctypes.c_int, bytes)) else _address(a) for a in args])


@dataclass
class Eigenvalues:
    """Eigenvalues of one real matrix, with what is needed to compute eigenvectors later."""

    values: np.ndarray  # (n,) complex; a conjugate pair is stored at k, k+1 with imag(k) > 0
    hessenberg: np.ndarray  # (n, n) Fortran-ordered H
    reflectors: np.ndarray  # dgehrd output (reflectors below the subdiagonal), Fortran-ordered
    tau: np.ndarray
    scale: np.ndarray | None  # balancing scale D (None = not balanced)
    dense_vectors: np.ndarray | None = None  # fallback path: all eigenvectors of A


def _dense(a: np.ndarray) -> Eigenvalues:
    w, v = sla.eig(a, check_finite=False)
    order = _pairs_first_positive(w)
    e = np.zeros((0, 0))
    return Eigenvalues(w[order], e, e, np.zeros(0), None, v[:, order])


def eigenvalues(a: np.ndarray, balance: bool = True) -> Eigenvalues:
    """All eigenvalues of the real square matrix ``a`` (``a`` is not modified).

    ``balance=False`` skips the diagonal scaling, for matrices already in a well-scaled basis.
    Whenever a LAPACK step fails, the whole decomposition is redone by ``scipy.linalg.eig`` on
    the original ``a`` (never on its balanced form), so eigenvectors are always those of ``a``.
    """
    n = a.shape[0]
    if not AVAILABLE or n < 2:
        return _dense(a)
    work, scale = a, None
    if balance:
        work, (scale, _) = sla.matrix_balance(a, permute=False, separate=True)
    refl, tau, info = sla.lapack.dgehrd(work)
    if info != 0:
        return _dense(a)
    refl = np.asfortranarray(refl)
    h = np.triu(refl, -1).copy(order="F")
    wr, wi, info = _qr_eigenvalues(h, n <= _LAHQR_MAX)
    if info != 0 and n <= _LAHQR_MAX:
        wr, wi, info = _qr_eigenvalues(h, False)
    if info != 0:  # QR iteration did not converge: let LAPACK's driver try
        return _dense(a)
    return Eigenvalues(wr + 1j * wi, h, refl, np.ascontiguousarray(tau), scale)


def _qr_eigenvalues(h: np.ndarray, small: bool) -> tuple[np.ndarray, np.ndarray, int]:
    """Eigenvalues of the Hessenberg ``h`` (not modified) by dlahqr (``small``) or dhseqr."""
    n = h.shape[0]
    work_h = h.copy(order="F")
    wr = np.empty(n)
    wi = np.empty(n)
    info = _int(0)
    dummy = np.empty(1)
    if small:
        _call(_LAHQR, _int(0), _int(0), _int(n), _int(1), _int(n), work_h, _int(n), wr, wi, _int(1),
              _int(1), dummy, _int(1), info)
    else:
        lwork = 11 * n
        _call(_HSEQR, b"E", b"N", _int(n), _int(1), _int(n), work_h, _int(n), wr, wi, dummy,
              _int(1), np.empty(lwork), _int(lwork), info)
    return wr, wi, int(info.value)


def _pairs_first_positive(w: np.ndarray) -> np.ndarray:
    """Index order that puts each conjugate pair at k, k+1 with positive imaginary part first."""
    out: list[int] = []
    used = np.zeros(w.size, bool)
    for k in range(w.size):
        if used[k]:
            continue
        used[k] = True
        if w[k].imag == 0:
            out.append(k)
            continue
        rest = np.flatnonzero(~used)
        j = rest[np.argmin(np.abs(w[rest] - np.conj(w[k])))] if rest.size else k
        used[j] = True
        pos, neg = (k, j) if w[k].imag > 0 else (j, k)
        out += [pos, neg]
    return np.array(out, dtype=int)


def eigenvectors(ev: Eigenvalues, which: np.ndarray) -> np.ndarray:
    """Right eigenvectors (n, k) complex of the eigenvalues ``ev.values[which]``.

    ``which`` must point at real eigenvalues or at the first (positive-imaginary) member of a pair.
    """
    which = np.asarray(which, dtype=int)
    n = ev.values.size
    if which.size == 0:
        return np.zeros((n, 0), complex)
    if ev.dense_vectors is not None:
        return ev.dense_vectors[:, which]
    if np.any(np.diff(which) <= 0):  # dhsein returns the vectors in eigenvalue order, once each
        uniq, back = np.unique(which, return_inverse=True)
        return eigenvectors(ev, uniq)[:, back]
    select = np.zeros(n, np.int32)
    select[which] = 1
    wr = np.ascontiguousarray(ev.values.real)
    wi = np.ascontiguousarray(ev.values.imag)
    width = np.where(wi[which] != 0, 2, 1)
    mm = int(width.sum())
    vr = np.empty((n, mm), order="F")
    ifaill = np.empty(mm, np.int32)
    ifailr = np.zeros(mm, np.int32)
    info = _int(0)
    _call(_HSEIN, b"R", b"Q", b"N", select, _int(n), ev.hessenberg, _int(n), wr, wi, np.empty(1),
          _int(1), vr, _int(n), _int(mm), _int(0), np.empty((n + 2) * n), ifaill, ifailr, info)
    if info.value < 0:
        raise ValueError(f"dhsein: argument {-info.value} invalid")
    if np.any(ifailr != 0):
        # inverse iteration did not converge for some eigenvalue (tight clusters): redo densely
        first = np.concatenate([[0], np.cumsum(width)[:-1]])
        w, v = sla.eig(ev.hessenberg, check_finite=False)
        for c in np.unique(np.searchsorted(first, np.flatnonzero(ifailr), side="right") - 1):
            x = v[:, np.argmin(np.abs(w - ev.values[which[c]]))]
            vr[:, first[c]] = x.real
            if width[c] == 2:
                vr[:, first[c] + 1] = x.imag
    # back to the basis of A: v = D Q x, Q applied from its reflectors
    lwork = 64 * mm + 4160
    info = _int(0)
    _call(_ORMHR, b"L", b"N", _int(n), _int(mm), _int(1), _int(n), ev.reflectors, _int(n), ev.tau,
          vr, _int(n), np.empty(lwork), _int(lwork), info)
    if info.value != 0:
        raise ValueError(f"dormhr: argument {-info.value} invalid")
    first = np.concatenate([[0], np.cumsum(width)[:-1]])
    x = vr[:, first].astype(complex)
    pair = width == 2
    x[:, pair] += 1j * vr[:, first[pair] + 1]
    return x if ev.scale is None else ev.scale[:, None] * x
