"""The joint time-domain posterior of a set of events, with or without a candidate; MAP and evidence.

The likelihood is :class:`shm_ros.core.bayes.records.JointTimeDomainLikelihood` (each record has its own
prediction-error variance per channel by default, or the records share it, integrated out with its
inverse-gamma prior; an AR(p) residual model
per record whose coefficients are fixed once per model compared, at that model's white-noise MAP: a
model's residual model is estimated from its own residuals, as for the nominal model, so that the
nominal's large residual, whitened, does not make the misfit an effect removes cheap). Each event
gets the candidate's factors through :class:`.td_model.FactorModel`, or, within events, each segment
of it (:class:`Segments`, :mod:`.td_varying`). Parameters are searched in
unit coordinates ``u``: the nominal parameters as they are (factors near 1) and each candidate
parameter as its place in its prior range, so a uniform prior has density 1 there.

Evidence (``ln Z``, in ``u``): **Laplace** at the MAP of the nominal parameters and the candidate's
together (the baseline re-fitted with the effect and integrated by its Gaussian, not profiled: its
posterior is narrow and nearly Gaussian with thousands of samples per event, and profiling would drop
the volume change of the baseline between the two models), the Gaussian cut to the prior box; the
check is **importance sampling** from a Student-t centred there with the Laplace covariance widened
1.5 times, which makes no Gaussian assumption (it matters when the effect's MAP sits at its null
boundary, where the Laplace estimate is poor) and has its own standard error from the weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.optimize import minimize
from scipy.stats import norm

from shm_ros.core.bayes.likelihoods import ig_marginal_loglik
from shm_ros.core.bayes.records import JointTimeDomainLikelihood
from shm_ros.core.bayes.timedomain import ar_fit
from shm_ros.core.logexp import logsumexp
from shm_ros.core.predict.signals import nrms_pct
from shm_ros.core.priors import JointPrior
from shm_ros.core.response.batch import record_responses

from .candidates.base import Candidate
from .failures import require_finite
from .td_model import FactorModel, shape_logprior
from .td_varying import node_steps, varying_responses


@dataclass
class Segments:
    """Within-event resolution: every event's segments (:func:`.td_model.segment_amplitudes`)."""

    lengths: list[int]  # samples per segment, per event
    counts: list[int]  # segments per event
    weights: np.ndarray  # (all segments,) the response's mean square: what the fit is dominated by

    @property
    def offsets(self) -> list[int]:
        return [0, *np.cumsum(self.counts).tolist()]

    def columns(self, events: np.ndarray) -> np.ndarray:
        """The segment columns of ``events``."""
        o = self.offsets
        return np.concatenate([np.arange(o[e], o[e + 1]) for e in np.atleast_1d(events)]).astype(int)

THETA_BOUNDS = (0.1, 10.0)  # nominal parameters are factors on the file's values
FTOL, GTOL = 1e-12, 1e-7  # L-BFGS-B on the log posterior scaled by its value at the start (~2e5 nats)


@dataclass
class Laplace:
    u: np.ndarray  # MAP in unit coordinates
    log_post: float
    log_z: float
    cov: np.ndarray


class EventPosterior:
    """log p(theta, phi | events) in unit coordinates for the events ``idx`` of ``lik``'s records."""

    def __init__(self, lik: JointTimeDomainLikelihood, prior: JointPrior, candidate: Candidate | None,
                 idx: np.ndarray | None = None, chunk: int = 64, segments: Segments | None = None):
        self.lik, self.prior, self.cand, self.chunk = lik, prior, candidate, chunk
        # within-event resolution: the candidate's "windows" are every event's segments, in order
        self.segments = segments if candidate is not None else None
        fm = lik.model
        assert isinstance(fm, FactorModel)
        self.fm = fm
        self.nb = fm.n_base
        self.specs = candidate.params() if candidate is not None else []
        self.dim = self.nb + len(self.specs)
        n_all = len(lik.parts)
        self.idx = np.arange(n_all) if idx is None else np.asarray(idx, dtype=int)
        self.n = sum(lik.parts[e].n_innovations for e in self.idx)
        if candidate is not None:
            for g in candidate.modify(np.array([[s.lo for s in self.specs]])).groups:
                if g != "EI":
                    raise ValueError(f"time-domain explain: group {g!r} is not supported (EI: every story)")

    def phi(self, u: np.ndarray) -> np.ndarray:
        """Candidate parameters (B, p) from unit coordinates (B, dim)."""
        cols = [s.lo * (s.hi / s.lo) ** u[:, self.nb + j] if s.log else s.lo + (s.hi - s.lo) * u[:, self.nb + j]
                for j, s in enumerate(self.specs)]
        return np.column_stack(cols) if cols else np.zeros((u.shape[0], 0))

    def factors(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stiffness factor, damping factor and added damping (B, all events), or (B, all segments)
        within events (the columns of :class:`.td_model.FactorModel`)."""
        n_w = len(self.lik.parts) if self.segments is None else self.segments.offsets[-1]
        ones = np.ones((u.shape[0], n_w))
        if self.cand is None:
            return ones, ones, np.zeros_like(ones)
        mod = self.cand.modify(self.phi(u))
        s = np.asarray(mod.groups.get("EI", ones), float)
        d = np.asarray(mod.damping if mod.damping is not None else ones, float)
        g = np.asarray(mod.added_damping, float) if mod.added_damping is not None else np.zeros_like(ones)
        # relative to the geometric mean over the fitted events: the nominal parameters then stand for
        # the average event with or without the effect, so the nominal MAP is a good start for any effect
        # size (the response's phase makes the time-domain posterior multimodal in the stiffness)
        # (within events: weighted by the response's mean square, so that the reference is the strong
        # motion the nominal fit was dominated by, not the quiet start and end of each record); the
        # damping by its first mode's total, inherent and added (both divided alike: they stay positive)
        if self.segments is None:
            w = np.zeros(n_w)
            w[self.idx] = 1.0
        else:
            w = np.zeros(n_w)
            cols = self.segments.columns(self.idx)
            w[cols] = self.segments.weights[cols]
        w = w / w.sum()
        s = s / np.exp(np.log(s) @ w)[:, None]
        G = np.exp(np.log(d + g) @ w)[:, None]
        return s, d / G, g / G

    @property
    def varies(self) -> int:
        """The :class:`.td_model.FactorModel` column (offset from ``nb``) the candidate changes."""
        if self.cand is None:
            return 0
        col = getattr(self.cand, "factor_column", None) or self.acts_on
        return {"stiffness": 0, "damping": 1, "added_damping": 2}[col]

    def rows(self, u: np.ndarray, e: int) -> np.ndarray:
        """Parameter rows of event ``e`` (within events: the factors of its first segment; the one
        that changes within the event is set per segment by :func:`.td_varying.node_steps`)."""
        s, d, g = self.factors(u)
        c = e if self.segments is None else self.segments.offsets[e]
        return np.column_stack([u[:, :self.nb], s[:, c], d[:, c], g[:, c]])

    def _responses(self, v: np.ndarray, events: np.ndarray):
        """Yield (event, first row, Y (B, outputs, N)) for the rows ``v`` (in unit coordinates)."""
        if self.segments is None:
            ev = [int(e) for e in events]
            recs = [(self.lik.parts[e].record.inputs, self.lik.parts[e].record.dt) for e in ev]
            for k, a, Y in record_responses(self.fm, [self.rows(v, e) for e in ev], recs, self.lik.outputs,
                                            chunk=self.chunk):
                yield ev[k], a, Y
            return
        seg = self.segments
        col = self.nb + self.varies
        step = max(1, self.chunk // 2)
        for a in range(0, v.shape[0], step):
            w = v[a:a + step]
            f = self.factors(w)[self.varies]
            base = self.rows(w, 0)
            used = f[:, seg.columns(events)]
            lo, hi = used.min(axis=1), used.max(axis=1)
            if self.varies == 2:
                # added damping starts from 0 in the quiet parts: interpolated in log above a floor of
                # 1/50 of the draw's largest over the events (below it the added damping is < 2 % of the
                # largest and the response there is small), so the nodes span at most a factor of 50
                lo = np.maximum(np.maximum(lo, hi / 50.0), 1e-9)
                hi = np.maximum(hi, lo)
                f = np.maximum(f, lo[:, None])
            steps = {}
            for e in events:
                part = self.lik.parts[e]
                dt = part.record.dt
                if dt not in steps:
                    steps[dt] = node_steps(self.fm, base, col, lo, hi, dt, self.lik.outputs)
                vals = f[:, seg.offsets[e]:seg.offsets[e + 1]]
                yield int(e), a, varying_responses(steps[dt], vals, seg.lengths[e], part.record.inputs)

    @property
    def acts_on(self) -> str:
        return "damping" if self.cand is not None and self.cand.vocabulary.endswith("damping") else "stiffness"

    def inside(self, u: np.ndarray) -> np.ndarray:
        th = u[:, :self.nb]
        ok = np.all((th > THETA_BOUNDS[0]) & (th < THETA_BOUNDS[1]), axis=1)
        return ok & np.all((u[:, self.nb:] >= 0.0) & (u[:, self.nb:] <= 1.0), axis=1)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        u = np.atleast_2d(np.asarray(u, dtype=float))
        out = np.full(u.shape[0], -np.inf)
        ok = self.inside(u)
        if not ok.any():
            return out
        v = u[ok]
        ss = {int(e): np.zeros((v.shape[0], len(self.lik.outputs))) for e in self.idx}
        for e, a, Y in self._responses(v, self.idx):
            ss[e][a:a + Y.shape[0]] += self.lik.parts[e].innovation_ss_batch(Y)
        ll = self._marginal(ss)
        # the file's parameters' prior, and the damping shape's (the last baseline column)
        lp = self.prior.logpdf(v[:, :self.nb - 1]) if self.nb > 1 else 0.0
        lp = lp + shape_logprior(v[:, self.nb - 1])
        # log-uniform candidate parameters: density 1 in u as well (u is the log position)
        logp = ll + lp
        out[ok] = np.where(np.isnan(logp), -np.inf, logp)  # a wild draw (response inf - inf)
        return out

    def _marginal(self, ss: dict[int, np.ndarray]) -> np.ndarray:
        """log p(events | u) with each channel's variance integrated out: one variance per event and
        channel (``lik.per_record``: the model error of a yielding or twisting building is relative, and
        one pooled variance lets the strongest event decide the fit alone), else one per channel."""
        lik = self.lik
        out = np.zeros(next(iter(ss.values())).shape[0])
        if lik.per_record:
            for e, s in ss.items():
                for j, p in enumerate(lik.parts[e].priors):
                    out = out + ig_marginal_loglik(s[:, j], lik.parts[e].n_innovations, p)
            return out
        pooled = np.sum(list(ss.values()), axis=0)
        for j, p in enumerate(lik.priors):
            out = out + ig_marginal_loglik(pooled[:, j], self.n, p)
        return out

    def predict(self, u: np.ndarray, e: int) -> np.ndarray:
        """Response (N, channels) of event ``e`` at ``u`` (dim,)."""
        _, _, Y = next(self._responses(np.atleast_2d(u), np.array([e])))
        return Y[0].T

    def nrms(self, u: np.ndarray, events: np.ndarray) -> np.ndarray:
        """Per event: NRMS (%) over its channels (``nrms_pct`` of every channel, averaged)."""
        out = []
        for e in events:
            y, yh = self.lik.parts[e].record.outputs, self.predict(u, int(e))
            out.append(float(np.mean([nrms_pct(y[:, c], yh[:, c]) for c in range(y.shape[1])])))
        return np.array(out)

    def fix_ar(self, u: np.ndarray) -> None:
        """Every event's residual AR model, estimated once at ``u`` (this model's white-noise MAP)."""
        for e in range(len(self.lik.parts)):
            part = self.lik.parts[e]
            if part.ar_order:
                part.ar_coef = ar_fit(part.record.outputs - self.predict(u, e), part.ar_order)

    def white(self) -> None:
        """White residuals (AR coefficients zero) until :meth:`fix_ar`."""
        for part in self.lik.parts:
            part.ar_coef = None

    def ar_state(self) -> list[np.ndarray | None]:
        return [p.ar_coef for p in self.lik.parts]

    def set_ar(self, state: list[np.ndarray | None]) -> None:
        for p, c in zip(self.lik.parts, state, strict=True):
            p.ar_coef = c


def spectral_starts(post: EventPosterior, rng: np.random.Generator, n: int = 160, keep: int = 2) -> list[np.ndarray]:
    """Starting points of the nominal parameters: the file's values, then the ``keep`` prior draws ranked
    best by the misfit of the smoothed amplitude spectra of the records, which unlike the time-domain
    likelihood ignores phase and so has one broad basin (a stiffness 10-20 % off is many cycles out of
    phase over an event). The file's values always: with a relative model error the likelihood's peak
    near them can sit beyond a valley (a stiffness off by 20-40 % is out of phase) that the best-ranked
    draws fall into."""
    draws = post.prior.sample(rng, n - 1)  # the file's parameters; the damping shape starts at 1
    th = np.vstack([np.ones(post.nb), np.column_stack([draws, np.ones(n - 1)])])
    th = np.clip(th, THETA_BOUNDS[0] * 1.05, THETA_BOUNDS[1] * 0.95)
    u = np.column_stack([th, np.zeros((n, post.dim - post.nb))])
    mis = np.zeros(n)
    recs = [post.lik.parts[int(e)].record for e in post.idx]
    spectra = []
    for rec in recs:
        width = max(1, int(round(0.2 * rec.outputs.shape[0] * rec.dt)))  # 0.2 Hz
        Y = uniform_filter1d(np.abs(np.fft.rfft(rec.outputs, axis=0)), width, axis=0)
        spectra.append((width, Y, Y > 1e-2 * Y.max(axis=0)))
    for k, a, R in record_responses(post.fm, [post.rows(u, int(e)) for e in post.idx],
                                    [(rec.inputs, rec.dt) for rec in recs], post.lik.outputs, chunk=post.chunk):
        width, Y, band = spectra[k]
        P = uniform_filter1d(np.abs(np.fft.rfft(R, axis=2)), width, axis=2)  # (B, c, F)
        r = np.log(np.maximum(P, 1e-300)) - np.log(np.maximum(Y.T, 1e-300))[None]
        mis[a:a + R.shape[0]] += np.sum(np.where(band.T[None], r ** 2, 0.0), axis=(1, 2))
    return [u[0], *(u[i] for i in np.argsort(mis)[:keep] if i != 0)]  # row 0: the file's values


def _grad(post: EventPosterior, u: np.ndarray, h: float = 1e-6) -> tuple[float, np.ndarray]:
    pts = np.vstack([u, u + h * np.eye(u.size), u - h * np.eye(u.size)])
    f = post(pts)
    with np.errstate(invalid="ignore"):  # a step outside the prior box: -inf on both sides, slope 0 below
        g = (f[1:u.size + 1] - f[u.size + 1:]) / (2 * h)
    return float(f[0]), np.where(np.isfinite(g), g, 0.0)


def find_map(post: EventPosterior, starts: list[np.ndarray]) -> tuple[np.ndarray, float]:
    """Best local maximum from ``starts`` (L-BFGS-B on batched central-difference gradients)."""
    lo = np.r_[np.full(post.nb, THETA_BOUNDS[0] * 1.01), np.zeros(post.dim - post.nb)]
    hi = np.r_[np.full(post.nb, THETA_BOUNDS[1] * 0.99), np.ones(post.dim - post.nb)]
    best_u, best_f = starts[0], -math.inf
    for u0 in starts:
        f0 = float(post(u0)[0])
        scale = max(abs(f0), 1.0) if math.isfinite(f0) else 1.0

        def obj(u: np.ndarray, scale: float = scale) -> tuple[float, np.ndarray]:
            f, g = _grad(post, np.clip(u, lo, hi))
            return (-f / scale, -g / scale) if math.isfinite(f) else (1e30, np.zeros_like(u))

        r = minimize(obj, np.clip(u0, lo, hi), jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi, strict=True)),
                     options={"maxiter": 200, "ftol": FTOL, "gtol": GTOL})
        f = float(post(r.x)[0])
        if f > best_f:
            best_u, best_f = np.asarray(r.x, float), f
    return best_u, best_f


def hessian(post: EventPosterior, u: np.ndarray, h: np.ndarray, axes: list[int] | None = None,
            grad: list | None = None) -> np.ndarray:
    """Central-difference Hessian of log p at ``u`` with steps ``h`` (one batch of evaluations), over
    the coordinates ``axes`` (default all); the gradient from the same points is appended to ``grad``."""
    ax = list(range(u.size)) if axes is None else list(axes)
    d = len(ax)
    E = np.zeros((d, u.size))
    E[np.arange(d), ax] = h[ax]
    h = h[ax]
    pts = [u]
    pairs = [(i, j) for i in range(d) for j in range(i + 1, d)]
    for i in range(d):
        pts += [u + E[i], u - E[i]]
    for i, j in pairs:
        pts += [u + E[i] + E[j], u + E[i] - E[j], u - E[i] + E[j], u - E[i] - E[j]]
    f = post(np.array(pts))
    H = np.zeros((d, d))
    if grad is not None:
        grad.append(np.array([(f[1 + 2 * i] - f[2 + 2 * i]) / (2 * h[i]) for i in range(d)]))
    with np.errstate(invalid="ignore"):  # a point off the prior (-inf) leaves NaN: the callers judge it
        for i in range(d):
            H[i, i] = (f[1 + 2 * i] - 2 * f[0] + f[2 + 2 * i]) / h[i] ** 2
        for k, (i, j) in enumerate(pairs):
            a = 1 + 2 * d + 4 * k
            H[i, j] = H[j, i] = (f[a] - f[a + 1] - f[a + 2] + f[a + 3]) / (4 * h[i] * h[j])
    return H


def _steps(post: EventPosterior, u: np.ndarray) -> np.ndarray:
    """Finite-difference steps per coordinate, about 0.3 posterior standard deviations (a first
    diagonal pass with steps of 1e-4)."""
    h0 = np.full(u.size, 1e-4)
    inner = u.copy()
    inner[post.nb:] = np.clip(u[post.nb:], 2e-4, 1 - 2e-4)
    diag = np.diag(hessian(post, inner, h0))
    h = np.clip(0.3 / np.sqrt(np.maximum(-diag, 1e-12)), 1e-7, 0.05)
    h[post.nb:] = np.minimum(h[post.nb:], 0.2)
    return h


def newton_polish(post: EventPosterior, u: np.ndarray, f: float, max_steps: int = 4) -> tuple[np.ndarray, float]:
    """Newton steps with the central-difference Hessian from a local search's end point.

    These posteriors are very ill-conditioned (an effect's parameter ~1e-5 wide in its unit coordinate,
    correlated with the stiffnesses through the factors' normalisation), and L-BFGS-B can stop on its
    relative-reduction test tens of nats short of the maximum (softening seed 2: 56 nats, seen as a
    disagreement of the two evidence estimators). Only where no candidate parameter sits at its bound
    (there the Laplace evidence integrates the bound axis one-sidedly)."""
    for _ in range(max_steps):
        if np.any((u[post.nb:] < 1e-3) | (u[post.nb:] > 1 - 1e-3)):
            break
        h = _steps(post, u)
        g: list = []
        H = -hessian(post, u, h, grad=g)
        if not np.all(np.isfinite(H)) or not np.all(np.isfinite(g[0])):
            break
        w, V = np.linalg.eigh(H)
        if w.min() <= 0:
            break
        step = V @ ((V.T @ g[0]) / w)
        for frac in (1.0, 0.5, 0.25):
            v = u + frac * step
            fv = float(post(v)[0])
            if fv > f + 1e-3:
                break
        else:
            break
        gained = fv - f
        u, f = v, fv
        if gained < 0.01:
            break
    return u, f


def laplace(post: EventPosterior, u: np.ndarray, f: float) -> Laplace:
    """Laplace evidence at the MAP ``u`` (log posterior ``f``); steps set from a first diagonal pass.
    A coordinate at a bound gets a one-sided (half-Gaussian) volume."""
    d = u.size
    h0 = np.full(d, 1e-4)
    inner = np.clip(u, h0 * 2, None)  # a point inside the box for the step-finding pass
    inner[:post.nb] = u[:post.nb]
    inner[post.nb:] = np.clip(u[post.nb:], 2e-4, 1 - 2e-4)
    diag = np.diag(hessian(post, inner, h0))
    h = np.clip(0.3 / np.sqrt(np.maximum(-diag, 1e-12)), 1e-7, 0.05)
    h[post.nb:] = np.minimum(h[post.nb:], 0.2)
    inner[post.nb:] = np.clip(u[post.nb:], 2.01 * h[post.nb:], 1 - 2.01 * h[post.nb:])  # every point in the box
    H = -hessian(post, inner, h)
    require_finite("Laplace evidence: the Hessian's diagonal at the MAP", np.diag(H))
    if not np.all(np.isfinite(H)):  # a corner point fell outside the prior: keep the diagonal
        H = np.diag(np.where(np.isfinite(np.diag(H)), np.diag(H), 1.0 / h ** 2))
    w, V = np.linalg.eigh(H)
    w = np.maximum(w, 1e-12 * max(float(np.max(np.abs(w))), 1e-300))
    cov = (V / w) @ V.T
    # at a bound of the box the slope need not vanish: along such an axis (the effect pushed to its
    # null) log p ~ f + g v - c v^2 / 2 from one-sided differences at the MAP, integrated over the box
    # exactly; the other axes by their Gaussian, with the Hessian taken at the MAP on them alone
    at_bound = [j for j in range(post.nb, d) if u[j] < 1e-3 or u[j] > 1 - 1e-3]
    if at_bound:
        inner_ax = [j for j in range(d) if j not in at_bound]
        # the inner effect axes a step inside the box, as for H (a step past a bound is off the prior)
        ui = u.copy()
        eff = [j for j in inner_ax if j >= post.nb]
        ui[eff] = np.clip(u[eff], 2.01 * h[eff], 1 - 2.01 * h[eff])
        Hi = -hessian(post, ui, h, inner_ax)
        require_finite("Laplace evidence: the Hessian's diagonal at the MAP (parameters inside their range)",
                       np.diag(Hi))
        if not np.all(np.isfinite(Hi)):  # a corner point fell outside the prior: keep the diagonal
            Hi = np.diag(np.where(np.isfinite(np.diag(Hi)), np.diag(Hi), 1.0 / h[inner_ax] ** 2))
        wi = np.linalg.eigvalsh(Hi) if inner_ax else np.zeros(0)
        wi = np.maximum(wi, 1e-12 * max(float(np.max(np.abs(wi), initial=0.0)), 1e-300))
        log_z = f + 0.5 * len(inner_ax) * math.log(2 * math.pi) - 0.5 * float(np.sum(np.log(wi)))
        cov = np.zeros((d, d))  # the importance proposal's: inner block, and each bound axis' own scale
        if inner_ax:
            cov[np.ix_(inner_ax, inner_ax)] = np.linalg.pinv(Hi)
        for j in at_bound:
            hj = min(float(h[j]), 0.25)
            e = np.zeros(d)
            e[j] = hj if u[j] < 0.5 else -hj
            f1, f2 = post(np.array([u + e, u + 2 * e]))
            g = (-3 * f + 4 * f1 - f2) / (2 * hj)
            c = -(f - 2 * f1 + f2) / hj ** 2
            # the MAP sits at the bound, so log p cannot rise inwards: a positive slope or a negative
            # curvature here is finite-difference noise, not a reason for evidence
            log_z += _log_truncated(min(float(g), 0.0), max(float(c), 0.0))
            scale = min(1.0 / max(-float(g), 1e-12), 1.0 / math.sqrt(max(float(c), 1e-12)), 0.5)
            cov[j, j] = scale ** 2
        return Laplace(u, f, log_z, cov)
    log_z = f + 0.5 * d * math.log(2 * math.pi) - 0.5 * float(np.sum(np.log(w)))
    for j in range(post.nb, d):
        sd = math.sqrt(max(cov[j, j], 1e-300))  # mass of the Gaussian inside [0, 1]
        mass = norm.cdf((1 - u[j]) / sd) - norm.cdf(-u[j] / sd)
        log_z += math.log(max(float(mass), 1e-300))
    return Laplace(u, f, log_z, cov)


def _log_truncated(g: float, h: float) -> float:
    """ln of the integral over [0, 1] of exp(g v - h v^2 / 2)."""
    if h < 1e-9:
        return math.log(math.expm1(g) / g) if abs(g) > 1e-12 else 0.0
    m, r = g / h, math.sqrt(h)
    a, b = -m * r, (1.0 - m) * r
    la, lb = float(norm.logsf(a)), float(norm.logsf(b))  # mass between a and b, from the upper tail
    return 0.5 * math.log(2 * math.pi / h) + 0.5 * g * m + la + math.log1p(-math.exp(min(lb - la, 0.0)) + 1e-300)


def importance_log_z(post: EventPosterior, lap: Laplace, n: int, rng: np.random.Generator,
                     nu: float = 4.0, widen: float = 1.5) -> tuple[float, float]:
    """ln Z and its standard error by importance sampling from a multivariate t around the MAP."""
    d = lap.u.size
    L = np.linalg.cholesky(lap.cov * widen ** 2 + 1e-18 * np.eye(d))
    z = rng.standard_normal((n, d))
    g = rng.chisquare(nu, n) / nu
    x = lap.u + (z @ L.T) / np.sqrt(g)[:, None]
    q = (z / np.sqrt(g)[:, None])  # standardised draws
    m = np.sum(q ** 2, axis=1)
    from scipy.special import gammaln

    log_q = (gammaln((nu + d) / 2) - gammaln(nu / 2) - 0.5 * d * math.log(nu * math.pi)
             - float(np.sum(np.log(np.diag(L)))) - 0.5 * (nu + d) * np.log1p(m / nu))
    lw = post(x) - log_q
    if not np.any(np.isfinite(lw)):
        return -math.inf, math.inf
    lz = float(logsumexp(lw) - math.log(n))
    w = np.exp(lw - np.max(lw))
    se = float(np.std(w) / max(np.mean(w), 1e-300) / math.sqrt(n))
    return lz, se
