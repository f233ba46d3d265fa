"""Time-domain likelihood (the building paper's eq. 27): measured vs predicted accelerations.

The structure is driven by its measured inputs (the structure file's ``input``/``inputs``: ground
or floor accelerations, forces); for each theta the model's absolute accelerations at the output
sensors are simulated and

    log p(D | theta, sigma^2) = sum_i [ -N/2 log(2 pi sigma_i^2) - SS_i(theta) / (2 sigma_i^2) ]

with one prediction-error variance per channel, each with an inverse-gamma prior (marginalised in
closed form by default, or sampled as log-variances).

Residual samples are not independent: model error (an unmodelled mode, a wrong damping) leaves a
narrow-band residual whose neighbouring samples are nearly equal, and treating thousands of them as
independent makes the posterior far narrower than the estimate's actual error. So each channel's
residual follows an AR(p) model (``ar_order``, default 2: one resonance), whose coefficients are
estimated once by least squares from the residual at the white-noise MAP and then held fixed
(:meth:`TimeDomainLikelihood.fix_ar`; refitted for every theta they would reward a large but
smooth residual); the likelihood above then applies to the innovations (the first p samples
conditioned on), N - p of them per channel. ``ar_order=0`` is the
white-noise model.

The response comes from
:mod:`shm_ros.core.response`: the model's full state space (non-classical damping, dampers, every
input kind) discretised exactly for inputs linear between samples, so the likelihood and the
prediction stage share one implementation of the dynamics.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.models.base import AffineModel

from .likelihoods import (
    InverseGamma,
    ig_marginal_loglik,
    ig_posterior_mean,
    log_variance_initial,
    log_variance_logprior,
)


@dataclass
class AccelerationRecord:
    """Measured inputs and the measured output accelerations on one sample grid.

    ``input_accel``: (N,) for one input or (n_inputs, N), one row per input of the model in the
    order of the structure file (``model.inputs``): accelerations for base and floor inputs, the
    force sensor's record for force inputs (each input's gain is applied by the model).
    """

    dt: float
    input_accel: np.ndarray  # (N,) or (n_inputs, N): the input sensors' records
    outputs: np.ndarray  # (N, n_channels) m/s^2, absolute accelerations
    channel_ids: list[str]
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.input_accel = np.asarray(self.input_accel, dtype=float)
        if self.input_accel.ndim != 2 or self.input_accel.shape[0] == 1:
            self.input_accel = self.input_accel.reshape(-1)
        self.outputs = np.asarray(self.outputs, dtype=float)
        if self.outputs.ndim == 1:
            self.outputs = self.outputs[:, None]
        n = self.input_accel.shape[-1]
        if self.outputs.shape != (n, len(self.channel_ids)):
            raise ValueError(f"outputs must be (samples, channels) = "
                             f"{(n, len(self.channel_ids))}, got {self.outputs.shape}")
        if not (np.all(np.isfinite(self.input_accel)) and np.all(np.isfinite(self.outputs))):
            raise ValueError("acceleration record contains NaN/inf; cut the record to a clean stretch")
        if self.dt <= 0:
            raise ValueError(f"dt must be > 0, got {self.dt}")

    @property
    def inputs(self) -> np.ndarray:
        """The input records as (n_inputs, N)."""
        return np.atleast_2d(self.input_accel)


def base_response(model: AffineModel, theta: np.ndarray, record_input: np.ndarray, dt: float,
                  channel_ids: list[str], n_modes: int | None = None) -> np.ndarray:
    """Absolute accelerations (N, n_channels) of ``model`` at ``theta`` under its inputs.

    ``record_input``: (N,) or (n_inputs, N), one row per ``model.inputs`` entry; a model without
    inputs is driven at its base (ground acceleration). The response is exact in all DOFs
    (:mod:`shm_ros.core.response`); ``n_modes`` is accepted for compatibility and not used.
    """
    from shm_ros.core.response import sensor_accelerations
    from shm_ros.core.structure import InputKind, InputSpec

    inputs = list(model.inputs) or [InputSpec("base", InputKind.BASE, {}, model.direction or "x")]
    return sensor_accelerations(model, theta, record_input, dt, list(channel_ids), inputs)


def ar_fit(residual: np.ndarray, order: int) -> np.ndarray:
    """Least-squares AR(``order``) coefficients (c, order) of each column of ``residual`` (N, c),
    conditional on the first ``order`` samples."""
    r = np.asarray(residual, dtype=float)
    n = r.shape[0]
    coef = np.zeros((r.shape[1], order))
    for c in range(r.shape[1]):
        X = np.column_stack([r[order - j: n - j, c] for j in range(1, order + 1)])
        coef[c], *_ = np.linalg.lstsq(X, r[order:, c], rcond=None)
    return coef


def innovation_ss_rows(residual: np.ndarray, order: int, coef: np.ndarray) -> np.ndarray:
    """Per channel: the sum of squared one-step prediction errors of an AR(``order``) model with
    coefficients ``coef`` (c, order) of residuals with time last, (..., c, N) (e.g. a batch of draws;
    the products run along contiguous samples); ``order=0``: the plain sum of squares."""
    r = np.asarray(residual, dtype=float)
    n = r.shape[-1]
    with np.errstate(over="ignore", invalid="ignore"):  # a wild draw's response: inf, and log p -inf
        e = r[..., order:].copy()
        for j in range(1, order + 1):
            e -= coef[:, j - 1, None] * r[..., order - j: n - j]
        return np.einsum("...n,...n->...", e, e)


class TimeDomainLikelihood:
    """Gaussian prediction error on accelerations, per-channel variances with IG priors."""

    def __init__(self, model: AffineModel, record: AccelerationRecord, *, variance: str = "marginal",
                 error_prior_shape: float = 1.0, error_guess: float = 0.1, n_modes: int | None = None,
                 ar_order: int = 2):
        if variance not in ("marginal", "sampled"):
            raise ValueError(f"variance must be 'marginal' or 'sampled', got {variance!r}")
        if not 0 <= int(ar_order) < record.outputs.shape[0] // 4:
            raise ValueError(f"ar_order must be >= 0 and well below the record length, got {ar_order}")
        self.ar_order = int(ar_order)
        self.ar_coef: np.ndarray | None = None  # (channels, ar_order), set by fix_ar
        known = set(model.sensor_rows) | set(model.sensor_dofs)
        missing = [c for c in record.channel_ids if c not in known]
        if missing:
            raise ValueError(f"channel(s) {missing} of the record are not output sensors of model "
                             f"'{model.name}' (known: {sorted(known)})")
        self.model, self.record = model, record
        self.variance = variance
        self.n_modes = n_modes
        rms = np.sqrt(np.mean(record.outputs**2, axis=0))
        rms = np.where(rms > 0, rms, 1.0)
        # weak prior: error std of about error_guess x the channel's RMS
        self.priors = [InverseGamma.weak(error_guess * r, error_prior_shape) for r in rms]
        self.variance_names = [f"sigma2_accel_{c}" for c in record.channel_ids]
        self.extra_names = [f"log_{n}" for n in self.variance_names] if variance == "sampled" else []
        self.n_theta = model.n_parameters

    @property
    def n_extra(self) -> int:
        return len(self.extra_names)

    def predict(self, theta: np.ndarray) -> np.ndarray:
        r = self.record
        return base_response(self.model, np.asarray(theta, dtype=float), r.inputs, r.dt,
                             r.channel_ids, self.n_modes)

    def residual_ss(self, theta: np.ndarray) -> np.ndarray:
        """Per channel: the sum of squared innovations of the residual's AR(p) model, whose
        coefficients are held fixed (:meth:`fix_ar`; zero, i.e. white, until then)."""
        return self.innovation_ss(self.predict(theta))

    def innovation_ss(self, predicted: np.ndarray) -> np.ndarray:
        """Per channel: the sum of squared innovations of ``outputs - predicted`` ((N, c), e.g. one
        of a batch of responses computed elsewhere) under the fixed AR coefficients."""
        return self.innovation_ss_batch(np.asarray(predicted, float).T[None])[0]

    def innovation_ss_batch(self, Y: np.ndarray) -> np.ndarray:
        """(B, c) sums of squared innovations of the responses ``Y`` (B, c, N), as :meth:`innovation_ss`."""
        coef = self.ar_coef if self.ar_coef is not None else np.zeros((len(self.record.channel_ids), self.ar_order))
        return innovation_ss_rows(self.record.outputs.T[None] - Y, self.ar_order, coef)

    def fix_ar(self, theta: np.ndarray) -> None:
        """Estimate the residual's AR coefficients once, at ``theta`` (the white-noise MAP), and keep
        them for every theta. Refitting them for each theta would reward a large but smooth residual
        (a smooth residual is easy to predict one step ahead), pulling theta away from the fit."""
        if self.ar_order:
            self.ar_coef = ar_fit(self.record.outputs - self.predict(np.asarray(theta, dtype=float)), self.ar_order)

    @property
    def n_innovations(self) -> int:
        return self.record.outputs.shape[0] - self.ar_order

    def prepare_at_map(self, theta: np.ndarray) -> bool:
        """The residual's AR model, estimated once at the white-noise MAP (True: the MAP moves)."""
        if not self.ar_order or self.ar_coef is not None:
            return False
        self.fix_ar(theta)
        return True

    def extra_logprior(self, extra: np.ndarray) -> np.ndarray:
        return log_variance_logprior(self.priors, extra, self.variance == "sampled")

    def extra_initial(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return log_variance_initial(self.priors, rng, n, self.variance == "sampled")

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        N = self.n_innovations
        out = np.empty(x.shape[0])
        for b in range(x.shape[0]):
            theta = x[b, : self.n_theta]
            if np.any(theta <= 0):
                out[b] = -np.inf
                continue
            ss = self.residual_ss(theta)
            if self.variance == "marginal":
                out[b] = sum(float(ig_marginal_loglik(s, N, p)) for s, p in zip(ss, self.priors, strict=True))
            else:
                s2 = np.exp(x[b, self.n_theta:])
                out[b] = float(np.sum(-0.5 * N * np.log(2 * np.pi * s2) - 0.5 * ss / s2))
        return out

    def variance_estimates(self, theta: np.ndarray) -> dict[str, float]:
        ss = self.residual_ss(np.asarray(theta, dtype=float))
        N = self.n_innovations
        return {n: float(ig_posterior_mean(s, N, p))
                for n, s, p in zip(self.variance_names, ss, self.priors, strict=True)}

    def fit(self, theta: np.ndarray) -> dict:
        """NRMS = ||y - y_hat|| / ||y|| per channel (the building paper's eq. 28)."""
        y = self.record.outputs
        yh = self.predict(theta)
        nrms = np.linalg.norm(y - yh, axis=0) / np.maximum(np.linalg.norm(y, axis=0), 1e-300)
        return {"nrms": dict(zip(self.record.channel_ids, map(float, nrms), strict=True)),
                "nrms_mean": float(np.mean(nrms)),
                "output_rms": dict(zip(self.record.channel_ids, map(float, np.sqrt(np.mean(y**2, axis=0))),
                                       strict=True))}
