"""What a prediction draws from a posterior: parameter sets and the model-error level per draw.

The prediction error of an acceleration channel is taken as ``e(t) ~ N(0, s0^2 + r^2 m(t))``:
``s0^2`` the error before the event (sensor noise, unmeasured ambient loads; from the record's
pre-event part), ``m(t)`` the local mean square of the predicted response and ``r^2`` the model
error relative to the response. ``r^2`` comes from a time-domain calibration: the NRMS of the
strong-motion part of its records at the MAP (a joint calibration over events reports it), else its
error variance divided by the mean square of the records (per draw when the variances were
sampled), else its NRMS at the MAP; a modal posterior or the nominal model carry none and use
``PredictConfig.relative_error``. Scaling with the response keeps the band honest for an event
stronger or weaker than the calibration events, and inside an event between its quiet and its
strong part.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from shm_ros.core.models.base import AffineModel

if TYPE_CHECKING:
    from .model_error import ModelError


@dataclass
class PosteriorDraws:
    """``theta`` (n, d) draws, ``theta_map`` (d,); ``rel2[channel]`` (n,) relative error variance
    per draw (channels not listed use ``rel2_default``)."""

    theta: np.ndarray
    theta_map: np.ndarray
    rel2: dict[str, np.ndarray] = field(default_factory=dict)
    rel2_default: float = 0.01
    source: str = "nominal"
    notes: list[str] = field(default_factory=list)
    # learnt out of sample over the calibration events (:mod:`.model_error`): replaces ``rel2``
    model_error: ModelError | None = None

    @property
    def n(self) -> int:
        return int(self.theta.shape[0])

    def rel2_for(self, channel: str) -> np.ndarray:
        v = self.rel2.get(channel)
        return np.full(self.n, self.rel2_default) if v is None else v

    def rel2_event(self, channels: list[str | None], pga: float) -> np.ndarray:
        """(n, len(channels)) relative error variances of one event (None: an unmeasured output,
        which takes the channels' mean) of input PGA ``pga``."""
        me = self.model_error
        if me is not None:
            return np.tile([me.rel2_at(c, pga) for c in channels], (self.n, 1))
        return np.stack([self.rel2_mean() if c is None else self.rel2_for(c) for c in channels], axis=1)

    def at_amplitude(self, pga: float, rng: np.random.Generator | None = None) -> PosteriorDraws:
        """These draws centred on the equivalent-linear parameters of an event of input PGA ``pga``
        (the learnt model error's, :meth:`.ModelError.theta_at`): every draw moved by the same
        factors as the MAP; with ``rng``, then by a lognormal factor per parameter of the
        calibration events' spread about them (``log_spread``: a new event's equivalent-linear
        parameters differ from the interpolation as the held-out events' did); unchanged without
        them."""
        from dataclasses import replace

        me = self.model_error
        target = None if me is None else me.theta_at(pga)
        if me is None or target is None:
            return self
        theta = self.theta * (target / self.theta_map)[None, :]
        if rng is not None and me.log_spread and self.n > 1:
            theta = theta * np.exp(np.asarray(me.log_spread)[None, :] * rng.standard_normal(theta.shape))
        return replace(self, theta=theta, theta_map=target)

    def with_model_error(self, model_error: ModelError) -> PosteriorDraws:
        """These draws with the cross-validated model error (the JSON's ``error_model`` says so)."""
        from dataclasses import replace

        note = (f"model error learnt by {model_error.method} cross-validation over {len(model_error.folds)} "
                f"calibration events")
        return replace(self, model_error=model_error, source="cross-validated model error",
                       notes=[*self.notes, note])

    def rel2_mean(self) -> np.ndarray:
        """Per draw, the mean over the calibrated channels (for unmeasured outputs)."""
        if not self.rel2:
            return np.full(self.n, self.rel2_default)
        return np.mean(np.stack(list(self.rel2.values())), axis=0)


def nominal_draws(model: AffineModel, relative_error: float) -> PosteriorDraws:
    """The nominal model alone (no posterior)."""
    th = model.nominal_theta()
    return PosteriorDraws(th[None, :], th, {}, relative_error ** 2, "nominal",
                          [f"nominal model; model error {100 * relative_error:g} % of the response (default)"])


def draws_from_posterior(post: Any, model: AffineModel, n_draws: int, rng: np.random.Generator,
                         relative_error: float) -> PosteriorDraws:
    """``n_draws`` parameter sets of ``post`` (a ``Posterior``: its samples, else independent
    normals from its summary) with their model-error levels (see module doc)."""
    names = list(post.parameter_names)
    if names != list(model.parameter_names):
        raise ValueError(f"posterior parameters {names} are not the model's {list(model.parameter_names)}")
    theta_map = np.array([post.parameters[n].map for n in names], dtype=float)
    samples = np.asarray(post.samples, dtype=float)
    notes: list[str] = []
    if n_draws <= 0:
        sel = np.zeros(0, dtype=int)
        theta = theta_map[None, :]
    elif samples.ndim == 2 and samples.shape[0] > 0:
        sel = rng.choice(samples.shape[0], n_draws, replace=samples.shape[0] < n_draws)
        theta = samples[sel]
    else:
        sel = np.zeros(0, dtype=int)
        mean = np.array([post.parameters[n].mean for n in names])
        std = np.array([post.parameters[n].std for n in names])
        theta = mean + std * rng.standard_normal((n_draws, len(names)))
        notes.append("no posterior samples: draws from independent normals of the summary")
    theta = np.where(theta > 0, theta, theta_map)  # a factor <= 0 is no structure
    rel2, source = _relative_errors(post, sel, theta.shape[0])
    if not rel2:
        notes.append(f"no time-domain calibration: model error {100 * relative_error:g} % of the response (default)")
    return PosteriorDraws(theta, theta_map, rel2, relative_error ** 2, source, notes)


def _relative_errors(post: Any, sel: np.ndarray, n: int) -> tuple[dict[str, np.ndarray], str]:
    diag = getattr(post, "diagnostics", {}) or {}
    fit = getattr(post, "fit", {}) or {}
    if diag.get("likelihood") != "time" or not isinstance(fit.get("nrms"), dict):
        return {}, "modal posterior" if diag else "posterior"
    rms = fit.get("output_rms") or {}
    noise = getattr(post, "noise", {}) or {}
    chains = np.asarray(getattr(post, "chains", np.zeros((0, 0, 0))))
    cols = list(getattr(post, "chain_names", []))
    flat = chains.reshape(-1, chains.shape[-1]) if chains.ndim == 3 and chains.size else None
    out: dict[str, np.ndarray] = {}
    strong = fit.get("nrms_strong") or {}
    if strong:  # the calibration's strong-motion error relative to the response: the best scale
        return {ch: np.full(n, float(v) ** 2) for ch, v in strong.items()}, "time-domain calibration"
    for ch, nrms in fit["nrms"].items():
        key = f"sigma2_accel_{ch}"
        r = rms.get(ch)
        if r and flat is not None and f"log_{key}" in cols and sel.size == n and flat.shape[0] > int(np.max(sel)):
            out[ch] = np.exp(flat[sel, cols.index(f"log_{key}")]) / r ** 2
        elif r and key in noise and "mean" in noise[key]:
            out[ch] = np.full(n, float(noise[key]["mean"]) / r ** 2)
        else:
            out[ch] = np.full(n, float(nrms) ** 2)
    return out, "time-domain calibration"
