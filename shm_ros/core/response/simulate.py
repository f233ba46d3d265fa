"""Run a discretised system from rest over a record, like ``scipy.signal.lsim`` but exact.

The recursion z[k+1] = Phi z[k] + G1 u[k] + G2 (u[k+1] - u[k]) runs in the system's own coordinates,
sample by sample, compiled (:func:`.kernels.segment_response` with one segment): no eigenbasis, so
integrator states of supports (a Jordan block) need no other route.
"""

from __future__ import annotations

import numpy as np

from .discretize import DiscreteSystem
from .kernels import segment_response


def simulate(sys: DiscreteSystem, u: np.ndarray) -> np.ndarray:
    """Outputs (n_outputs, N) for inputs ``u`` (n_inputs, N) sampled every ``sys.dt``, from rest."""
    u = np.atleast_2d(np.asarray(u, dtype=float))
    if u.shape[0] != sys.G1.shape[1]:
        raise ValueError(f"u must have {sys.G1.shape[1]} rows (one per input), got {u.shape}")
    if u.shape[1] == 0:
        return np.zeros((sys.C.shape[0], 0))
    return segment_response(sys.Phi[None, None], sys.G1[None, None], sys.G2[None, None], sys.C[None, None],
                            sys.D[None, None], u, u.shape[1])[0]
