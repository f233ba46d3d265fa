"""A known thermal law of the structure's stiffness, for updating and predicting across temperatures.

When the frequencies follow the temperature through a law the model is given (the form explain
accepts for ``temperature_dependent_stiffness``, with the structure's thermal lag), the windows are
referred to a reference temperature *through the model* before updating, and a posterior's
predictions are carried back to any other temperature the same way:

    T*(t)  = the air temperature through a first-order lag of time constant ``lag_s``,
    F(T*)  = 1 + alpha (T* - t_ref) + below * min(T* - knee, 0)      (stiffness factor),
    r_k(F) = f_k(theta with ``parameter`` x F) / f_k(theta)          (the model's own ratio),

a window's frequencies divided by ``r_k(F(T*_w))`` are the reference-temperature frequencies, and a
draw of those times ``r_k(F(T*_new))`` is a prediction at ``T*_new``. The ratio is the model's
(its modes' share of the scaled stiffness), computed at the MAP; the model-error likelihood absorbs
the rest. A model-free baseline (the training windows' mean +- 1.96 sd) cannot follow a
temperature the training never saw; this does, as far as the law holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh

from shm_ros.core.models.base import AffineModel
from shm_ros.core.observations import ModalObservations


@dataclass(frozen=True)
class ThermalLaw:
    alpha_per_c: float = -0.004
    t_ref_c: float = 10.0
    knee_c: float = 0.0
    below_per_c: float = 0.0  # extra slope below the knee (freezing), per degC
    lag_s: float = 0.0  # first-order lag of the structure's temperature behind the air's

    def lagged(self, times_s: np.ndarray, air_c: np.ndarray) -> np.ndarray:
        """T* at ``times_s`` (ascending): the exact first-order lag of a piecewise-constant input."""
        t = np.asarray(times_s, float)
        a = np.asarray(air_c, float)
        if self.lag_s <= 0 or a.size == 0:
            return a.copy()
        out = np.empty_like(a)
        out[0] = a[0]
        for i in range(1, a.size):
            w = np.exp(-(t[i] - t[i - 1]) / self.lag_s)
            out[i] = w * out[i - 1] + (1 - w) * a[i]
        return out

    def factor(self, t_star: np.ndarray) -> np.ndarray:
        d = np.asarray(t_star, float)
        return 1.0 + self.alpha_per_c * (d - self.t_ref_c) + self.below_per_c * np.minimum(d - self.knee_c, 0.0)


def frequency_ratios(model: AffineModel, theta: np.ndarray, parameter: str, factors: np.ndarray,
                     n_modes: int) -> np.ndarray:
    """(len(factors), n_modes): ``r_k(F)`` of the model's lowest modes (module doc)."""
    i = model.parameter_names.index(parameter)

    def freqs(th: np.ndarray) -> np.ndarray:
        w2 = eigh(model.stiffness(th), model.mass(th), eigvals_only=True)[:n_modes]
        return np.sqrt(np.maximum(w2, 0.0))

    base = freqs(theta)
    out = []
    for f in np.atleast_1d(factors):
        th = np.array(theta, float)
        th[i] *= float(f)
        out.append(freqs(th) / base)
    return np.array(out)


def sensitivities(obs: ModalObservations, log_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per mode the data's sensitivity to the law relative to the model's, ``c_k`` in
    ``log f_wk = a_k + c_k log r_k(F_w) + e_wk`` (least squares over the windows), and its standard
    error (windows correlated in time: ``n_eff = n (1 - rho) / (1 + rho)``, rho the residuals'
    lag-1 autocorrelation). A model whose modes share the scaled stiffness as the structure's do
    has ``c = 1``; the planar model of a structure with restraints it lacks does not."""
    c = np.ones(obs.n_modes)
    se = np.zeros(obs.n_modes)
    for k in range(obs.n_modes):
        x, y = log_r[:, k], np.log(obs.frequencies_hz[:, k])
        ok = np.isfinite(x) & np.isfinite(y)
        if ok.sum() < 5 or np.ptp(x[ok]) <= 0:
            continue
        A = np.column_stack([np.ones(ok.sum()), x[ok]])
        coef, *_ = np.linalg.lstsq(A, y[ok], rcond=None)
        res = y[ok] - A @ coef
        rho = float(np.clip(np.corrcoef(res[:-1], res[1:])[0, 1], 0.0, 0.99)) if res.size > 3 else 0.0
        n_eff = max(3.0, res.size * (1 - rho) / (1 + rho))
        s2 = float(res @ res) / max(res.size - 2, 1)
        c[k] = coef[1]
        se[k] = np.sqrt(s2 / (np.sum((x[ok] - x[ok].mean()) ** 2) * n_eff / res.size))
    return c, se


def referred_by_law(obs: ModalObservations, model: AffineModel, theta: np.ndarray, parameter: str,
                    law: ThermalLaw, air_c: np.ndarray) -> tuple[ModalObservations, np.ndarray, np.ndarray]:
    """``obs`` with every window's frequencies referred to ``law.t_ref_c`` through the model's
    ratios raised to the data's sensitivities (:func:`sensitivities`), and those (c, se)."""
    F = law.factor(law.lagged(obs.times, air_c))
    log_r = np.log(frequency_ratios(model, theta, parameter, F, obs.n_modes))
    c, se = sensitivities(obs, log_r)
    out = obs.subset(np.arange(obs.n_windows))
    out.frequencies_hz = obs.frequencies_hz * np.exp(-c[None] * log_r)
    out.notes = [*obs.notes, f"frequencies referred to {law.t_ref_c:g} degC through the model's thermal law "
                 f"(parameter {parameter}, lag {law.lag_s / 3600:g} h; sensitivities " +
                 ", ".join(f"{x:.2f}" for x in c) + ")"]
    return out, c, se


def predicted_at(reference_draws: np.ndarray, model: AffineModel, theta: np.ndarray, parameter: str,
                 law: ThermalLaw, t_star: np.ndarray, c: np.ndarray, se: np.ndarray,
                 rng: np.random.Generator) -> np.ndarray:
    """(S, windows, modes): reference-temperature draws (S, modes) carried to each ``t_star``,
    with the sensitivities drawn from N(c, se^2) per draw."""
    log_r = np.log(frequency_ratios(model, theta, parameter, law.factor(t_star), reference_draws.shape[1]))
    cs = c[None] + se[None] * rng.standard_normal(reference_draws.shape)
    return reference_draws[:, None, :] * np.exp(cs[:, None, :] * log_r[None])
