"""Unmeasured floors from the measured ones: the model's residual expanded on its mode shapes.

A planar model misses motion the building has (twist read by sensors off the stiffness centre,
modes coupled by eccentric masses, story-to-story scatter); the measured floors of the same event
show that misfit as their residual ``r_m(t) = y_m(t) - y_model,m(t)``. Its shape over the height is
that of the building's lowest modes, so it is expanded to the unmeasured floors with the model's
mode shapes (least squares on ``k`` modes, SEREP-style):

    y_u(t) = y_model,u(t) + S_u Phi (S_m Phi)^+ r_m(t),

with ``Phi`` the undamped modes of the (MAP) model, ``S_m``/``S_u`` the measured and unmeasured
rows, ``k`` one mode fewer than measured channels (a smooth fit, not an interpolation of the noise).
This is virtual sensing: the predicted event's measured records are used, and only for outputs no
sensor gives. Drifts stay model displacements: expanding the residual to them needs it
double-integrated, which changed the top-story drift by about +-1 point of NRMS on the acceptance
test's buildings (docs/predict.md), so it is not done.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh

from shm_ros.core.models.base import AffineModel


def expansion_matrix(model: AffineModel, theta: np.ndarray, measured_rows: np.ndarray,
                     target_rows: np.ndarray) -> np.ndarray:
    """(n_targets, n_measured): the map from the measured residual to the targets' (rows over the
    DOFs); zeros when nothing is measured."""
    m = measured_rows.shape[0]
    if m == 0 or target_rows.shape[0] == 0:
        return np.zeros((target_rows.shape[0], m))
    _, phi = eigh(model.stiffness(theta), model.mass(theta))
    k = max(1, min(m - 1, phi.shape[1]))
    phi = phi[:, :k]
    return target_rows @ phi @ np.linalg.pinv(measured_rows @ phi)
