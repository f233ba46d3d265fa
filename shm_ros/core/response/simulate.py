"""Run a discretised system from rest over a record, like ``scipy.signal.lsim`` but exact.

The recursion z[k+1] = Phi z[k] + d[k] (d from the inputs, computed for all k at once) is run in
modal coordinates when Phi has a well-conditioned eigenbasis: each eigenvalue is then a first-order
filter (``scipy.signal.lfilter``, compiled). Otherwise (integrator states of supports form a Jordan
block) the recursion runs step by step.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from .discretize import DiscreteSystem

_MAX_COND = 1e8  # eigenbasis condition number up to which the modal route keeps ~1e-8 accuracy


def simulate(sys: DiscreteSystem, u: np.ndarray) -> np.ndarray:
    """Outputs (n_outputs, N) for inputs ``u`` (n_inputs, N) sampled every ``sys.dt``, from rest."""
    u = np.atleast_2d(np.asarray(u, dtype=float))
    if u.shape[0] != sys.G1.shape[1]:
        raise ValueError(f"u must have {sys.G1.shape[1]} rows (one per input), got {u.shape}")
    N = u.shape[1]
    n = sys.n_states
    z = np.zeros((n, N))
    if n and N > 1:
        drive = sys.G1 @ u[:, :-1] + sys.G2 @ np.diff(u, axis=1)  # (n, N - 1)
        z[:, 1:] = _recursion(sys.Phi, drive)
    return sys.C @ z + sys.D @ u


def _recursion(Phi: np.ndarray, drive: np.ndarray) -> np.ndarray:
    """z[k+1] = Phi z[k] + drive[:, k] from z[0] = 0; returns z[1:] (n, N - 1)."""
    lam, V = np.linalg.eig(Phi)
    if np.linalg.cond(V) < _MAX_COND:
        g = np.linalg.solve(V, drive)
        q = np.empty_like(g)
        for k in range(lam.size):
            q[k] = lfilter([1.0], [1.0, -lam[k]], g[k])
        return np.real(V @ q)
    out = np.empty_like(drive)
    zk = np.zeros(Phi.shape[0])
    for k in range(drive.shape[1]):
        zk = Phi @ zk + drive[:, k]
        out[:, k] = zk
    return out
