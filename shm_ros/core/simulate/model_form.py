"""Model-form error: what the best-fitting analysis model still misses of the simulator's truth.

The analysis model is the nominal structure file's own model (:func:`shm_ros.core.models.build_model`)
with the file's ``parameters`` as factors. Its factors are fitted (least squares over log factors,
``scipy.optimize.least_squares``) to the truth's in-plane modes at reference conditions (no hidden
effect acting): residuals ``f_model / f_truth - 1`` and ``1 - MAC`` at the output sensors, each truth
mode paired with the analysis mode of largest MAC. Whatever misfit is left is the model-form error a
calibration cannot remove; a posterior of the analysis model's factors is best compared with
:attr:`ModelFormReport.theta_best`, not with 1. The truth's out-of-plane modes (motion the analysis
model has no DOF for) are listed as well. ``truth.json`` carries the report under ``model_form``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from shm_ros.core.models import build_model
from shm_ros.core.models.base import AffineModel
from shm_ros.core.simulate.truth import ModalTruth, TruthModel

# weight of 1 - MAC against the relative frequency error: shapes at a few sensors are known less well
# than frequencies, and factors of stiffness barely move them (the usual modal-updating choice)
MAC_WEIGHT = 0.3


@dataclass
class ModeMisfit:
    truth_frequency_hz: float
    model_frequency_hz: float  # of the best-fitting analysis model
    relative_error: float  # model / truth - 1
    mac: float  # truth shape vs the best-fitting model's shape at the output sensors (:func:`cluster_mac`)
    nominal_frequency_hz: float  # the analysis model with every factor at 1


@dataclass
class ModelFormReport:
    kind: str
    in_plane_family: str
    sensor_ids: list[str]  # where the shapes are compared
    parameter_names: list[str]
    theta_best: dict[str, float]  # best-fitting factors of the nominal file's parameters
    modes: list[ModeMisfit]  # in-plane truth modes, ascending
    out_of_plane: list[dict[str, Any]] = field(default_factory=list)  # {frequency_hz, family, damping_ratio}
    cost: float = 0.0  # sum of squared residuals at the best fit

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["max_abs_relative_error"] = max((abs(m.relative_error) for m in self.modes), default=0.0)
        d["min_mac"] = min((m.mac for m in self.modes), default=1.0)
        return d


def mac(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, dtype=complex), np.asarray(b, dtype=complex)
    den = float(np.vdot(a, a).real * np.vdot(b, b).real)
    return float(abs(np.vdot(a, b)) ** 2 / den) if den > 0 else 0.0


def cluster_mac(truth: np.ndarray, model: np.ndarray, f: np.ndarray, j: int, tol: float = 0.01) -> float:
    """MAC of ``truth`` with the span of analysis mode ``j`` and the modes within ``tol`` of its
    frequency: near-coincident modes (e.g. the two outer spans of a symmetric girder) have no
    individual shapes, only a shared subspace, which any asymmetry of the truth rotates."""
    near = np.nonzero(np.abs(f / f[j] - 1.0) <= tol)[0]
    if near.size == 1:
        return mac(truth, model[:, j])
    q, _ = np.linalg.qr(model[:, near])
    t = np.asarray(truth, dtype=float)
    den = float(t @ t)
    return float(np.sum((q.T @ t) ** 2) / den) if den > 0 else 0.0


def _pairs(truth: np.ndarray, model: np.ndarray) -> list[int]:
    """Analysis mode paired with each truth mode (largest MAC, each used once, strongest first)."""
    macs = np.array([[mac(truth[:, i], model[:, j]) for j in range(model.shape[1])] for i in range(truth.shape[1])])
    out = [-1] * truth.shape[1]
    used: set[int] = set()
    for i in np.argsort(-macs.max(axis=1)):
        j = next(int(j) for j in np.argsort(-macs[i]) if int(j) not in used)
        out[int(i)] = j
        used.add(j)
    return out


def model_form_report(tm: TruthModel, modal: ModalTruth | None = None) -> ModelFormReport:
    """Fit the analysis model of ``tm.nominal`` to ``modal`` (default: the truth at reference
    conditions, ``tm.system({})``) and report the misfit per in-plane mode."""
    if modal is None:
        modal = tm.system({})[1]
    ip = modal.in_plane()
    ids = [s for s in tm.nominal.output_sensor_ids if s in modal.sensor_ids]
    rows = [modal.sensor_ids.index(s) for s in ids]
    f_t = modal.frequencies_hz[ip]
    phi_t = modal.shapes[np.ix_(np.asarray(rows, dtype=int), ip)]
    model: AffineModel = build_model(tm.nominal)
    S = model.sensor_matrix(ids)
    n_m = min(model.n_dof, ip.size + 3)

    def solve(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sol = model.modes(np.exp(x), n_modes=n_m)
        return sol.frequencies_hz, S @ sol.shapes

    def residual(x: np.ndarray, pair: list[int]) -> np.ndarray:
        f, phi = solve(x)
        return np.concatenate([f[pair] / f_t - 1.0,
                               [MAC_WEIGHT * (1.0 - cluster_mac(phi_t[:, i], phi, f, j)) for i, j in enumerate(pair)]])

    x = np.zeros(model.n_parameters)
    f0, phi0 = solve(x)
    pair0 = _pairs(phi_t, phi0)
    pair = pair0
    cost = 0.0
    if model.n_parameters and ip.size:
        for _ in range(2):  # fit, pair again at the fit, refit
            fit = least_squares(residual, x, args=(pair,), bounds=(np.log(0.2), np.log(5.0)), x_scale=0.1)
            x, cost = fit.x, float(2 * fit.cost)
            pair = _pairs(phi_t, solve(x)[1])
    f, phi = solve(x)
    modes = [ModeMisfit(truth_frequency_hz=float(f_t[i]), model_frequency_hz=float(f[j]),
                        relative_error=float(f[j] / f_t[i] - 1.0), mac=cluster_mac(phi_t[:, i], phi, f, j),
                        nominal_frequency_hz=float(f0[pair0[i]])) for i, j in enumerate(pair)]
    others = [j for j in range(modal.frequencies_hz.size) if j not in set(ip.tolist())]
    oop = [{"frequency_hz": float(modal.frequencies_hz[j]), "family": modal.families[j],
            "damping_ratio": float(modal.damping_ratios[j])} for j in others]
    return ModelFormReport(kind=tm.kind, in_plane_family=modal.in_plane_family, sensor_ids=ids,
                           parameter_names=list(model.parameter_names),
                           theta_best={n: float(v) for n, v in zip(model.parameter_names, np.exp(x), strict=True)},
                           modes=modes, out_of_plane=oop, cost=cost)
