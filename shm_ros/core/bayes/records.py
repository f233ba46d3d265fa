"""One time-domain likelihood over several records (events) at once.

Calibrating on several earthquakes is one likelihood: the records are independent given theta, so
it is built from one :class:`~.timedomain.TimeDomainLikelihood` per record (the same residual
model: an AR(p) per channel whose coefficients each record fixes once at the white-noise MAP,
``fix_ar``). By default the records share the prediction-error variance of each channel, so their
innovation sums of squares and counts add up before the variance is marginalised or sampled (as in
:mod:`.timedomain`). With ``per_record`` every record has its own variance per channel (marginalised
record by record): a model-form error that scales with the response (a planar model of a twisting
building, an equivalent-linear model of yielding springs) is a relative error, and one pooled
variance would let the strongest event's residuals, a hundred times the weakest's, decide the fit
alone; each event then weighs by its own residual level. The responses of a batch of parameter
sets (an ensemble sampler's walkers) are computed together
(:func:`shm_ros.core.response.batch.batch_responses`: one discretisation per set) and handed to each
record's likelihood.
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
from .timedomain import AccelerationRecord, TimeDomainLikelihood


@dataclass
class RecordSet:
    """Several acceleration records of the same channels (events), calibrated on jointly."""

    records: list[AccelerationRecord]
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.records:
            raise ValueError("a record set needs at least one record")
        ids = self.records[0].channel_ids
        for r in self.records[1:]:
            if r.channel_ids != ids:
                raise ValueError(f"records of a set must share their channels: {r.channel_ids} != {ids}")

    @property
    def n_windows(self) -> int:
        return len(self.records)

    @property
    def channel_ids(self) -> list[str]:
        return list(self.records[0].channel_ids)


class JointTimeDomainLikelihood:
    """The time-domain likelihood of a :class:`RecordSet` (same interface as ``TimeDomainLikelihood``):
    the per-record likelihoods in :attr:`parts`, their innovation sums of squares pooled per channel."""

    def __init__(self, model: AffineModel, data: RecordSet, *, variance: str = "marginal",
                 error_prior_shape: float = 1.0, error_guess: float = 0.1, ar_order: int = 2, chunk: int = 64,
                 per_record: bool = False):
        if variance not in ("marginal", "sampled"):
            raise ValueError(f"variance must be 'marginal' or 'sampled', got {variance!r}")
        if per_record and variance != "marginal":
            raise ValueError("a variance per record is marginalised: variance must be 'marginal'")
        from shm_ros.core.response import sensor_outputs

        self.parts = [TimeDomainLikelihood(model, r, variance=variance, error_prior_shape=error_prior_shape,
                                           error_guess=error_guess, ar_order=ar_order) for r in data.records]
        self.model, self.data, self.variance, self.chunk = model, data, variance, chunk
        self.ar_order = int(ar_order)
        self.outputs = sensor_outputs(model, data.channel_ids)
        self.n = sum(r.outputs.shape[0] for r in data.records)
        y2 = sum(np.sum(r.outputs ** 2, axis=0) for r in data.records)
        self.rms = np.sqrt(y2 / self.n)
        rms = np.where(self.rms > 0, self.rms, 1.0)
        # one variance per channel for all records: its prior from the pooled RMS
        self.priors = [InverseGamma.weak(error_guess * r, error_prior_shape) for r in rms]
        self.per_record = per_record  # per record and channel: each record's own priors (its RMS)
        self.variance_names = list(self.parts[0].variance_names)
        self.extra_names = [f"log_{n}" for n in self.variance_names] if variance == "sampled" else []
        self.n_theta = model.n_parameters

    @property
    def n_extra(self) -> int:
        return len(self.extra_names)

    @property
    def n_innovations(self) -> int:
        return sum(p.n_innovations for p in self.parts)

    @property
    def ar_coef(self) -> list[np.ndarray] | None:
        """Every record's AR coefficients once fixed (:meth:`fix_ar`), else None."""
        coefs = [p.ar_coef for p in self.parts]
        return None if any(c is None for c in coefs) else [c for c in coefs if c is not None]

    def fix_ar(self, theta: np.ndarray) -> None:
        """Each record's residual AR model, estimated once at ``theta`` (the white-noise MAP)."""
        for p in self.parts:
            p.fix_ar(theta)

    def _responses(self, thetas: np.ndarray, record: AccelerationRecord):
        from shm_ros.core.response.batch import batch_responses

        return batch_responses(self.model, thetas, record.inputs, record.dt, self.outputs, chunk=self.chunk)

    def residual_ss(self, thetas: np.ndarray) -> np.ndarray:
        """(B, channels) innovation sums of squares, summed over the records."""
        return self.record_ss(thetas).sum(axis=0)

    def record_ss(self, thetas: np.ndarray) -> np.ndarray:
        """(records, B, channels) innovation sums of squares of each record."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        from shm_ros.core.response.batch import record_responses

        ss = np.zeros((len(self.parts), thetas.shape[0], len(self.outputs)))
        recs = [(p.record.inputs, p.record.dt) for p in self.parts]
        for i, a, Y in record_responses(self.model, [thetas] * len(self.parts), recs, self.outputs, chunk=self.chunk):
            ss[i, a:a + Y.shape[0]] += self.parts[i].innovation_ss_batch(Y)
        return ss

    def prepare_at_map(self, theta: np.ndarray) -> bool:
        """Every record's residual AR model, estimated once at the white-noise MAP."""
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
        out = np.full(x.shape[0], -np.inf)
        ok = np.all(x[:, :self.n_theta] > 0, axis=1)
        if not ok.any():
            return out
        if self.per_record:
            rss = self.record_ss(x[ok, :self.n_theta])
            out[ok] = sum(ig_marginal_loglik(rss[i, :, j], part.n_innovations, p)
                          for i, part in enumerate(self.parts) for j, p in enumerate(part.priors))
            return out
        ss = self.residual_ss(x[ok, :self.n_theta])
        N = self.n_innovations
        if self.variance == "marginal":
            out[ok] = sum(ig_marginal_loglik(ss[:, j], N, p) for j, p in enumerate(self.priors))
        else:
            s2 = np.exp(x[ok, self.n_theta:])
            out[ok] = np.sum(-0.5 * N * np.log(2 * np.pi * s2) - 0.5 * ss / s2, axis=1)
        return out

    def variance_estimates(self, theta: np.ndarray) -> dict[str, float]:
        ss = self.residual_ss(np.asarray(theta, dtype=float))[0]
        N = self.n_innovations
        return {n: float(ig_posterior_mean(s, N, p))
                for n, s, p in zip(self.variance_names, ss, self.priors, strict=True)}

    def fit(self, theta: np.ndarray) -> dict:
        """NRMS per channel over all records (the building paper's eq. 28), and each channel's RMS."""
        from shm_ros.core.response.signals import strong_motion

        th = np.atleast_2d(np.asarray(theta, dtype=float))
        ss, ss_s, y2_s = (np.zeros(len(self.outputs)) for _ in range(3))
        for r in self.data.records:
            res = next(self._responses(th, r))[1][0] - r.outputs.T
            s = strong_motion(r.inputs[0])
            ss += np.sum(res ** 2, axis=1)
            ss_s += np.sum(res[:, s] ** 2, axis=1)
            y2_s += np.sum(r.outputs[s] ** 2, axis=0)
        nrms = np.sqrt(ss / self.n) / np.maximum(self.rms, 1e-300)
        ids = self.data.channel_ids
        # the strong-motion part (5-95 % of the input's Arias intensity) alone: the relative model
        # error a prediction's band scales with the response (shm_ros.core.predict.draws)
        strong = np.sqrt(ss_s / np.maximum(y2_s, 1e-300))
        return {"nrms": dict(zip(ids, map(float, nrms), strict=True)), "nrms_mean": float(np.mean(nrms)),
                "nrms_strong": dict(zip(ids, map(float, strong), strict=True)),
                "output_rms": dict(zip(ids, map(float, self.rms), strict=True)), "n_records": self.data.n_windows}
