"""Exact discrete-time response of linear structures by complex modal superposition.

A linear structure with inputs ``u`` (loads at points, or a base acceleration) and acceleration outputs
``y`` is written in first-order modal form

    z_j' = lambda_j z_j + b_j . u          y = sum_j 2 Re(c_j z_j) + D u   (one of each conjugate pair)

so that every mode is a one-pole complex filter. Each pole is discretised exactly for an input that is
linear between samples (first-order hold), which keeps a measured base input and the response on the
same sample instants without the half-sample lag of a zero-order hold. The filters run through
``scipy.signal.lfilter``; the per-pole hold coefficients are closed-form (no library offers them for
a complex one-pole filter, hence the few lines below).

Two builders give that form:

* :func:`from_real_modes` for classically damped models (large FE models: only the modes below a
  cut-off are kept; the direct term keeps the kept modes' instantaneous share of the load),
* :func:`from_state_space` for any small linear model, including non-proportional damping and
  Maxwell damper braces with internal states (eigen-decomposition of the full first-order matrix).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter


@dataclass
class ModalSystem:
    """First-order modal form of a linear structure (see module doc).

    ``poles`` (m,) complex; ``conjugate`` (m,) bool - True where the pole stands for a conjugate pair
    (output doubled, real part taken); ``B`` (m, n_in) complex; ``C`` (n_out, m) complex;
    ``D`` (n_out, n_in) real. ``shapes`` (n_out, m) complex displacement shapes at the outputs and
    ``modal`` a bool mask of the poles that are vibration modes (under-damped pairs).
    """

    poles: np.ndarray
    conjugate: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    shapes: np.ndarray
    # classical modes: B = residue[:, None] * participation with real participation; lets
    # :meth:`simulate` run one real biquad per mode instead of a complex one-pole filter
    residue: np.ndarray | None = None
    participation: np.ndarray | None = None

    @property
    def n_poles(self) -> int:
        return int(self.poles.size)

    def frequencies_hz(self) -> np.ndarray:
        """Undamped natural frequency |lambda| / 2 pi of each pole."""
        return np.abs(self.poles) / (2 * np.pi)

    def damping_ratios(self) -> np.ndarray:
        return -self.poles.real / np.abs(self.poles)

    def simulate(self, u: np.ndarray, dt: float) -> np.ndarray:
        """Outputs (n, n_out) for inputs ``u`` (n, n_in) sampled every ``dt`` s, at rest at k = 0."""
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u[:, None]
        y = u @ self.D.T
        if self.n_poles == 0:
            return y
        if self.participation is not None and np.all(self.conjugate) and np.allclose(self.C.imag, 0.0):
            return y + self._simulate_real(u, dt)
        # each pole's filter (c1 + c0 q^-1) / (1 - phi q^-1), times (1 - conj(phi) q^-1) above and
        # below: a real denominator run over the real and imaginary parts of the modal input (real
        # filters are several times faster than complex ones), then three complex taps folded into
        # the output matrix
        a = self.B.real @ u.T  # (m, n): rows filtered in place, contiguous
        b = self.B.imag @ u.T
        weight = np.where(self.conjugate, 2.0, 1.0)
        taps = np.empty((3, self.n_poles), complex)
        for j, lam in enumerate(self.poles):
            c1, c0, phi = _foh_coefficients(complex(lam), dt)
            den = [1.0, -2.0 * phi.real, abs(phi) ** 2]
            a[j] = lfilter([1.0], den, a[j])
            b[j] = lfilter([1.0], den, b[j])
            taps[:, j] = (c1, c0 - c1 * np.conj(phi), -c0 * np.conj(phi))
        n = u.shape[0]
        for t in range(3):
            G = (self.C * (weight * taps[t])).T  # (m, n_out)
            y[t:] += a[:, : n - t].T @ G.real - b[:, : n - t].T @ G.imag
        return y


    def simulate_modal(self, Pm: np.ndarray, dt: float) -> np.ndarray:
        """Outputs for classical modes driven by modal forces ``Pm`` (n, m) = u @ participation.T
        (lets a caller form modal forces without the full load history)."""
        if self.participation is None:
            raise ValueError("simulate_modal needs a model from from_real_modes")
        return Pm @ self.C.real.T + self._filter_real(Pm, dt)

    def _simulate_real(self, u: np.ndarray, dt: float) -> np.ndarray:
        assert self.participation is not None  # classical modes only (from_real_modes)
        return self._filter_real(u @ self.participation.T, dt)

    def _filter_real(self, Pm: np.ndarray, dt: float) -> np.ndarray:
        # the conjugate pair 2 Re(R (c1 + c0 q^-1) / (1 - phi q^-1)) as one real biquad
        assert self.residue is not None  # classical modes only (from_real_modes)
        Q = np.ascontiguousarray(Pm.T)  # (m, n): each mode's row filtered in place, contiguous
        for j, lam in enumerate(self.poles):
            c1, c0, phi = _foh_coefficients(complex(lam), dt)
            R = complex(self.residue[j])
            b = [2 * (R * c1).real, 2 * (R * c0 - R * c1 * np.conj(phi)).real, -2 * (R * c0 * np.conj(phi)).real]
            a = [1.0, -2 * phi.real, abs(phi) ** 2]
            Q[j] = lfilter(b, a, Q[j])
        return Q.T @ self.C.real.T


def _foh_coefficients(lam: complex, h: float) -> tuple[complex, complex, complex]:
    """z[k+1] = phi z[k] + c0 w[k] + c1 w[k+1] for z' = lam z + w, w linear between samples."""
    phi = np.exp(lam * h)
    x = lam * h
    if abs(x) < 1e-6:  # series of the integrals below for a (near) zero pole
        g0 = h * (1 + x / 2 + x * x / 6)
        g1 = h * h * (0.5 + x / 6 + x * x / 24)
    else:
        g0 = (phi - 1.0) / lam
        g1 = (phi - 1.0 - x) / (lam * lam)
    c1 = g1 / h
    c0 = g0 - c1
    return c1, c0, phi


def from_real_modes(frequencies_hz: np.ndarray, damping: np.ndarray, load_participation: np.ndarray,
                    output_shapes: np.ndarray, direct_extra: np.ndarray | None = None) -> ModalSystem:
    """Classically damped modes: ``q_j'' + 2 z w q_j' + w^2 q_j = P_j . u`` and ``y = Phi_out q''``.

    ``load_participation`` (m, n_in): modal force per unit input (phi_j^T L); ``output_shapes``
    (n_out, m): mass-normalised shapes at the outputs. ``direct_extra`` (n_out, n_in) is added to D
    (e.g. the base acceleration itself for absolute outputs of a base-excited model).
    """
    w = 2 * np.pi * np.asarray(frequencies_hz, dtype=float)
    z = np.asarray(damping, dtype=float)
    if np.any(z >= 1.0):
        raise ValueError("from_real_modes: damping ratios must be below 1 (under-damped modes)")
    lam = -z * w + 1j * w * np.sqrt(1.0 - z * z)
    # s^2 / ((s - lam)(s - conj lam)) = 1 + R/(s - lam) + conj(R)/(s - conj lam), R = lam^2/(lam - conj lam)
    R = lam * lam / (lam - np.conj(lam))
    P = np.asarray(load_participation, dtype=float)
    Phi = np.asarray(output_shapes, dtype=float)
    D = Phi @ P
    if direct_extra is not None:
        D = D + direct_extra
    return ModalSystem(poles=lam, conjugate=np.ones(lam.size, bool), B=R[:, None] * P,
                       C=Phi.astype(complex), D=D, shapes=Phi.astype(complex), residue=R, participation=P)


def from_state_space(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray,
                     Cdisp: np.ndarray | None = None, tol: float = 1e-9) -> ModalSystem:
    """Diagonalise ``x' = A x + B u, y = C x + D u``; conjugate pairs are kept once (Im > 0).

    ``Cdisp`` (n_out, n_states) reads displacements at the outputs, for the complex mode shapes.
    """
    from scipy.linalg import eig, solve

    lam, V = eig(A)
    Bm = solve(V, B.astype(complex))
    keep, conj = [], []
    scale = max(1.0, float(np.max(np.abs(lam))))
    for j, lam_j in enumerate(lam):
        if abs(lam_j.imag) <= tol * scale:
            keep.append(j)
            conj.append(False)
        elif lam_j.imag > 0:
            keep.append(j)
            conj.append(True)
    keep_a = np.array(keep, dtype=int)
    Cm = C.astype(complex) @ V[:, keep_a]
    shapes = (Cdisp.astype(complex) @ V[:, keep_a]) if Cdisp is not None else Cm
    poles = lam[keep_a].copy()
    # a real pole of a real system has real B and C up to a complex scale; keep products exact
    return ModalSystem(poles=poles, conjugate=np.array(conj, bool), B=Bm[keep_a], C=Cm,
                       D=np.asarray(D, float), shapes=shapes)
