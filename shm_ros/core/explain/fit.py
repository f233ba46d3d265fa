"""Fit one candidate: MAP, evidence by two independent estimators, intervals, prior sensitivity.

Everything works in the unit cube of the candidate's bounded priors (uniform, or log-uniform for
``ParamSpec.log``), where the prior density is 1, so the evidence gain over the nominal model is
``ln E_prior[exp(gain(theta))]`` with ``gain`` from :class:`.likelihood.CandidateLikelihood`.

* MAP: a batch of random prior draws plus a scan of each grid parameter (knee, change time) on a
  fine grid with the others at the best draw and at ``PROFILE`` settings spread over their prior
  (a Latin hypercube), then a batched pattern search (:func:`pattern_search`) from the best few.
  With a misfit that drifts a change time's peak is one window wide and high only near the right
  size: random draws rarely hit both, and a scan at a wrong size sees nothing.
* Evidence, primary: **importance sampling** with a defensive mixture proposal (15 % the prior,
  85 % a product of a multivariate Student-t for the smooth parameters and a piecewise-constant
  density on a fine grid for the grid parameters), adapted in two stages (the second stage's
  proposal comes from the first stage's weighted draws; only the second stage is used). Its standard
  error follows from the weights' variance.
* Evidence, check: **nested sampling** (dynesty, :func:`shm_ros.core.bayes.evidence.nested_evidence`)
  on the same likelihood and prior - a different algorithm with its own error estimate.
* 95 % intervals: weighted quantiles of the importance draws.
* Prior sensitivity: the evidence gain with every prior width halved and doubled (about the null
  value where the parameter has one, else about the centre), by importance sampling again.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.logexp import logsumexp

from .candidates.base import ParamSpec

GainFn = Callable[[np.ndarray], np.ndarray]  # theta (B, p) -> gain (B,)
DEFENSIVE = 0.15
N_GRID = 512
BATCH = 64
PROFILE = 8  # settings of the other parameters at which each grid parameter is scanned


@dataclass
class Box:
    """The prior box of a candidate's parameters; maps the unit cube to parameter values."""

    specs: list[ParamSpec]

    @property
    def dim(self) -> int:
        return len(self.specs)

    def to_theta(self, u: np.ndarray) -> np.ndarray:
        u = np.atleast_2d(u)
        out = np.empty_like(u, dtype=float)
        for i, p in enumerate(self.specs):
            if p.log:
                out[:, i] = np.exp(np.log(p.lo) + u[:, i] * (np.log(p.hi) - np.log(p.lo)))
            else:
                out[:, i] = p.lo + u[:, i] * (p.hi - p.lo)
        return out

    def to_unit(self, theta: np.ndarray) -> np.ndarray:
        th = np.atleast_2d(theta)
        out = np.empty_like(th, dtype=float)
        for i, p in enumerate(self.specs):
            if p.log:
                out[:, i] = (np.log(th[:, i]) - np.log(p.lo)) / (np.log(p.hi) - np.log(p.lo))
            else:
                out[:, i] = (th[:, i] - p.lo) / (p.hi - p.lo)
        return out

    def scaled(self, factor: float) -> Box:
        """Every width x ``factor`` about the null (or the centre); log priors in ln."""
        out = []
        for p in self.specs:
            if p.log:
                c = math.log(p.null) if p.null else 0.5 * (math.log(p.lo) + math.log(p.hi))
                lo, hi = math.exp(c + factor * (math.log(p.lo) - c)), math.exp(c + factor * (math.log(p.hi) - c))
            else:
                c = p.null if p.null is not None else 0.5 * (p.lo + p.hi)
                lo, hi = c + factor * (p.lo - c), c + factor * (p.hi - c)
            out.append(ParamSpec(p.name, lo, hi, p.null, p.log, p.unit, p.grid))
        return Box(out)


@dataclass
class Evidence:
    log_z: float
    err: float
    u: np.ndarray  # (N, p) draws in the unit cube
    w: np.ndarray  # (N,) normalised importance weights
    n_eval: int


@dataclass
class FitResult:
    theta_map: np.ndarray
    gain_map: float
    evidence: Evidence
    check: float | None
    check_err: float | None
    check_method: str
    intervals: dict[str, tuple[float, float]]
    prior_sensitivity: dict[str, float]
    n_eval: int
    notes: list[str] = field(default_factory=list)


def _evaluate(fn: GainFn, box: Box, u: np.ndarray) -> np.ndarray:
    u = np.atleast_2d(u)
    out = np.full(u.shape[0], -np.inf)
    inside = np.all((u >= 0) & (u <= 1), axis=1)
    idx = np.flatnonzero(inside)
    for s in range(0, idx.size, BATCH):
        j = idx[s:s + BATCH]
        out[j] = fn(box.to_theta(u[j]))
    return np.where(np.isfinite(out), out, -np.inf)


def find_map(fn: GainFn, box: Box, rng: np.random.Generator, n_draws: int = 512,
             hint_u: np.ndarray | None = None) -> tuple[np.ndarray, float, int]:
    """MAP in the unit cube (see module docstring); returns (u, gain, evaluations)."""
    p = box.dim
    u0 = rng.random((n_draws, p))
    if hint_u is not None:
        u0 = np.vstack([u0, np.atleast_2d(hint_u)])
    g0 = _evaluate(fn, box, u0)
    n = len(g0)
    best = u0[np.argmax(g0)].copy()
    grid_ix = [i for i, s in enumerate(box.specs) if s.grid]
    starts = [best]
    for i in grid_ix:  # scan the grid parameter with the others at the best draw and spread over their prior
        scan = _profile_scan(box, best, i, rng)
        gs = _evaluate(fn, box, scan)
        n += len(scan)
        if gs.max() > g0.max():
            best = scan[np.argmax(gs)].copy()
        starts.append(scan[np.argmax(gs)].copy())
    order = np.argsort(g0)[::-1][:2]
    starts += [u0[j] for j in order]
    top_u, top_g, m = pattern_search(fn, box, np.array(starts), rng)
    n += m
    for i in grid_ix:  # polish the grid parameter once more at the optimum of the others
        scan = np.repeat(top_u[None], N_GRID, axis=0)
        scan[:, i] = (np.arange(N_GRID) + 0.5) / N_GRID
        gs = _evaluate(fn, box, scan)
        n += N_GRID
        if gs.max() > top_g:
            top_u, top_g = scan[np.argmax(gs)].copy(), float(gs.max())
        top_u[i] = plateau_middle(scan[:, i], gs, top_u[i], top_g)
    return top_u, top_g, n


def pattern_search(fn: GainFn, box: Box, starts: np.ndarray, rng: np.random.Generator, step: float = 0.05,
                   tol: float = 1e-5, max_iter: int = 200) -> tuple[np.ndarray, float, int]:
    """The best of a batched pattern search from every start at once (rows of ``starts``, unit cube):
    each round every start still moving tries a step of its own size along each axis, both ways, and
    along two random directions, all in one batched call; a start moves to its best try when that
    gains and widens its step by half, else halves it; it stops below ``tol``. Returns (u, gain,
    evaluations). One batched call a round instead of one call per point (a simplex method's)."""
    p = box.dim
    x = np.clip(np.atleast_2d(starts).astype(float), 0.0, 1.0)
    g = _evaluate(fn, box, x)
    n = len(x)
    h = np.full(len(x), step)
    axes = np.vstack([np.eye(p), -np.eye(p)])
    for _ in range(max_iter):
        live = np.flatnonzero(h > tol)
        if live.size == 0:
            break
        r = rng.standard_normal((2, p))
        r /= np.linalg.norm(r, axis=1, keepdims=True)
        d = np.vstack([axes, r, -r])  # (m, p)
        tries = np.clip(x[live, None, :] + h[live, None, None] * d[None], 0.0, 1.0)
        gt = _evaluate(fn, box, tries.reshape(-1, p)).reshape(live.size, len(d))
        n += gt.size
        j = np.argmax(gt, axis=1)
        gain = gt[np.arange(live.size), j]
        up = gain > g[live] + 1e-9
        x[live[up]] = tries[np.flatnonzero(up), j[up]]
        g[live[up]] = gain[up]
        h[live] = np.where(up, np.minimum(1.5 * h[live], 0.25), 0.5 * h[live])
    k = int(np.argmax(g))
    return x[k].copy(), float(g[k]), n


def _profile_scan(box: Box, at: np.ndarray, i: int, rng: np.random.Generator) -> np.ndarray:
    """Points (N_GRID (1 + PROFILE), p): grid parameter ``i`` on its fine grid, the smooth parameters
    at ``at`` and at ``PROFILE`` Latin-hypercube settings of their prior (other grid parameters stay
    at ``at``)."""
    settings = np.repeat(at[None], 1 + PROFILE, axis=0)
    for j, s in enumerate(box.specs):
        if not s.grid:
            settings[1:, j] = (rng.permutation(PROFILE) + rng.random(PROFILE)) / PROFILE
    scan = np.repeat(settings, N_GRID, axis=0)
    scan[:, i] = np.tile((np.arange(N_GRID) + 0.5) / N_GRID, 1 + PROFILE)
    return scan


def plateau_middle(u: np.ndarray, g: np.ndarray, at: float, top: float, tol: float = 1e-6) -> float:
    """The middle of the run of grid cells ``u`` (ascending) around ``at`` whose gain ``g`` equals
    ``top`` (within ``tol`` nats), or ``at`` off such a run. A change time anywhere between two
    training windows (a held-out block between them) or a knee between two measured temperatures fits
    the training data alike: the optimiser's point on that plateau is arbitrary, its middle is not."""
    j = int(np.argmin(np.abs(u - at)))
    flat = np.abs(g - top) <= tol
    if not flat[j]:
        return float(at)
    lo, hi = j, j
    while lo > 0 and flat[lo - 1]:
        lo -= 1
    while hi < len(u) - 1 and flat[hi + 1]:
        hi += 1
    return float(0.5 * (u[lo] + u[hi])) if hi > lo else float(at)


class _Proposal:
    """Defensive mixture: prior (uniform on the cube) + t (smooth params) x histogram (grid params)."""

    def __init__(self, box: Box, u: np.ndarray, w: np.ndarray):
        self.grid = np.array([s.grid for s in box.specs], dtype=bool)
        self.dim = box.dim
        uc = u[:, ~self.grid]
        if uc.shape[1]:
            self.mean = np.sum(w[:, None] * uc, axis=0)
            d = uc - self.mean
            cov = (w[:, None] * d).T @ d
            self.cov = 2.0 * cov + np.eye(uc.shape[1]) * 1e-8  # wider than the posterior: safe tails
            self.chol = np.linalg.cholesky(self.cov)
        self.hist = []
        for i in np.flatnonzero(self.grid):
            cnt = np.bincount(np.minimum((u[:, i] * N_GRID).astype(int), N_GRID - 1), weights=w, minlength=N_GRID)
            h = np.convolve(cnt, np.ones(3) / 3, mode="same") + 1e-3 / N_GRID  # neighbours and a floor
            self.hist.append(h / h.sum())

    _NU = 5.0

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        u = rng.random((n, self.dim))
        mix = rng.random(n) >= DEFENSIVE
        m = int(mix.sum())
        if (~self.grid).any():
            z = rng.standard_normal((m, int((~self.grid).sum())))
            chi = rng.chisquare(self._NU, m) / self._NU
            u[np.ix_(mix, ~self.grid)] = self.mean + (z @ self.chol.T) / np.sqrt(chi)[:, None]
        for h, i in zip(self.hist, np.flatnonzero(self.grid), strict=True):
            cells = rng.choice(N_GRID, size=m, p=h)
            u[mix, i] = (cells + rng.random(m)) / N_GRID
        return u

    def logpdf(self, u: np.ndarray) -> np.ndarray:
        lp = np.zeros(u.shape[0])
        if (~self.grid).any():
            d = u[:, ~self.grid] - self.mean
            k = d.shape[1]
            sol = np.linalg.solve(self.chol, d.T).T
            q = np.sum(sol ** 2, axis=1)
            from scipy.special import gammaln

            lp += (gammaln((self._NU + k) / 2) - gammaln(self._NU / 2) - 0.5 * k * math.log(self._NU * math.pi)
                   - np.sum(np.log(np.diag(self.chol))) - 0.5 * (self._NU + k) * np.log1p(q / self._NU))
        for h, i in zip(self.hist, np.flatnonzero(self.grid), strict=True):
            cells = np.clip((u[:, i] * N_GRID).astype(int), 0, N_GRID - 1)
            lp += np.log(h[cells] * N_GRID)
        inside = np.all((u >= 0) & (u <= 1), axis=1)
        return np.logaddexp(np.where(inside, math.log(DEFENSIVE), -np.inf), math.log(1 - DEFENSIVE) + lp)


def importance_evidence(fn: GainFn, box: Box, pilot_u: np.ndarray, pilot_w: np.ndarray,
                        rng: np.random.Generator, n: int) -> Evidence:
    """ln Z by importance sampling from a proposal adapted to the weighted pilot draws."""
    prop = _Proposal(box, pilot_u, pilot_w)
    u = prop.sample(rng, n)
    g = _evaluate(fn, box, u)
    lw = g - prop.logpdf(u)
    mx = float(np.max(lw[np.isfinite(lw)])) if np.isfinite(lw).any() else 0.0
    w = np.exp(lw - mx)
    m = float(np.mean(w))
    log_z = math.log(m) + mx if m > 0 else -np.inf
    err = float(np.std(w) / (m * math.sqrt(n))) if m > 0 else np.inf
    return Evidence(log_z, err, u, w / max(w.sum(), 1e-300), n)


def _laplace_pilot(fn: GainFn, box: Box, u_map: np.ndarray, rng: np.random.Generator, n: int = 400
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Weighted pilot draws around the MAP: smooth parameters from a local Gaussian (finite-difference
    curvature), grid parameters from their conditional scan."""
    p = box.dim
    grid = np.array([s.grid for s in box.specs], dtype=bool)
    sd = np.full(p, 0.05)
    g0 = float(_evaluate(fn, box, u_map)[0])
    for i in np.flatnonzero(~grid):
        for h in (1e-3, 1e-2):
            e = np.zeros(p)
            e[i] = h
            pts = np.clip(np.vstack([u_map + e, u_map - e]), 0, 1)
            gp, gm = _evaluate(fn, box, pts)
            curv = -(gp + gm - 2 * g0) / (np.abs(pts[0, i] - pts[1, i]) / 2) ** 2
            if np.isfinite(curv) and curv > 0:
                sd[i] = min(max(1.0 / math.sqrt(curv), 1e-6), 0.3)
                break
    u = np.repeat(u_map[None], n, axis=0)
    u[:, ~grid] += rng.standard_normal((n, int((~grid).sum()))) * sd[~grid]
    w = np.ones(n)
    for i in np.flatnonzero(grid):
        scan = np.repeat(u_map[None], N_GRID, axis=0)
        scan[:, i] = (np.arange(N_GRID) + 0.5) / N_GRID
        gs = _evaluate(fn, box, scan)
        pr = np.exp(gs - gs.max())
        pr /= pr.sum()
        u[:, i] = (rng.choice(N_GRID, size=n, p=pr) + rng.random(n)) / N_GRID
    u = np.clip(u, 0, 1)
    return u, w / w.sum()


def _grid_log_z(fn: GainFn, box: Box, lo: np.ndarray, hi: np.ndarray, n: int) -> tuple[float, np.ndarray]:
    """ln of the integral of exp(gain) over the box [lo, hi] of the unit cube by the midpoint rule on
    n points per dimension; also the values (n,)*d."""
    d = len(lo)
    axes = [lo[i] + (np.arange(n) + 0.5) * (hi[i] - lo[i]) / n for i in range(d)]
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
    vals = np.concatenate([_evaluate(fn, box, mesh[i:i + 4096]) for i in range(0, len(mesh), 4096)])
    cell = float(np.prod((hi - lo) / n))
    return float(logsumexp(vals)) + math.log(cell), vals.reshape((n,) * d)


def quadrature_check(fn: GainFn, box: Box, u_peak: np.ndarray | None = None) -> tuple[float, float]:
    """ln Z by deterministic quadrature on the unit cube, for up to three parameters: a grid over the
    whole prior finds where the likelihood lives (within 30 nats of its peak), and grids zoomed on that
    region (twice) integrate it by the midpoint rule (batched evaluations); the error is the
    difference to the last grid at half the resolution. Independent of the importance sampler: no
    proposal, no random numbers. ``u_peak`` (the fit's MAP in the unit cube): a peak narrower than
    the grid's cells can fall between its points; the region the grid sees then holds a lesser mode
    only and the integral misses the peak's mass (a freezing knee on 864 windows: 3,281 against
    3,431 nats). So the peak's cell is kept in the zoomed region, and when the peak lies more than
    30 nats above every grid point the region is the peak's neighbourhood."""
    d = box.dim
    n = {1: 2001, 2: 101, 3: 31}[d]  # points a side (61 and 21 missed a change time's one-window peak by 1.1 nats)
    lo, hi = np.zeros(d), np.ones(d)
    g_peak = -math.inf if u_peak is None else float(_evaluate(fn, box, u_peak)[0])
    z, zoomed = math.nan, True  # zoomed: (lo, hi) has not been integrated yet
    for _ in range(3):
        z, vals = _grid_log_z(fn, box, lo, hi, n)
        zoomed = False
        step = (hi - lo) / n
        idx = np.argwhere(vals >= max(float(np.max(vals)), g_peak) - 30.0)
        if u_peak is not None:  # the peak's own cell is in the region, whatever the grid saw
            cell = np.clip(((np.asarray(u_peak, float).reshape(-1) - lo) / step).astype(int), 0, n - 1)
            idx = np.vstack([idx, cell[None]])
        new_lo = np.clip(lo + idx.min(axis=0) * step - 2 * step, 0.0, 1.0)
        new_hi = np.clip(lo + (idx.max(axis=0) + 1) * step + 2 * step, 0.0, 1.0)
        if np.all(new_hi - new_lo > 0.8 * (hi - lo)):
            break  # the likelihood fills the box: no zoom gains resolution
        lo, hi, zoomed = new_lo, new_hi, True
    if zoomed:
        z, _ = _grid_log_z(fn, box, lo, hi, n)
    half, _ = _grid_log_z(fn, box, lo, hi, (n + 1) // 2)
    return z, abs(z - half)


def evidence_check(fn: GainFn, box: Box, n_live: int, seed: int, theta_peak: np.ndarray | None = None
                   ) -> tuple[float, float, str]:
    """The second estimator of ln Z: quadrature for up to three parameters (told where the fit's peak
    is, ``theta_peak``), nested sampling above."""
    if box.dim <= 3:
        z, err = quadrature_check(fn, box, None if theta_peak is None else box.to_unit(np.atleast_2d(theta_peak)))
        return z, err, "quadrature (midpoint rule on zoomed grids)"
    z, err = nested_check(fn, box, n_live, seed)
    return z, err, "nested sampling (dynesty)"


def nested_check(fn: GainFn, box: Box, n_live: int, seed: int) -> tuple[float, float]:
    """ln Z by nested sampling (dynesty) on the unit cube."""
    from shm_ros.core.bayes.evidence import nested_evidence
    from shm_ros.core.priors import JointPrior, Prior

    prior = JointPrior([Prior.make("uniform", {"low": 0.0, "high": 1.0}, s.name) for s in box.specs])
    res = nested_evidence(lambda u: _evaluate(fn, box, u), prior, n_live=n_live, dlogz=0.1, seed=seed,
                          bound="multi" if any(s.grid for s in box.specs) else "single", sample="rwalk"
                          if any(s.grid for s in box.specs) else "auto")
    return res.log_evidence, res.log_evidence_err


def weighted_quantile(x: np.ndarray, w: np.ndarray, q: list[float]) -> np.ndarray:
    o = np.argsort(x)
    c = np.cumsum(w[o])
    c = c / c[-1]
    return np.interp(q, c, x[o])


def fit(fn: GainFn, specs: list[ParamSpec], *, seed: int = 0, n_is: int = 3000, nested: bool = False,
        n_live: int = 150, sensitivity: bool = True, hint_u: np.ndarray | None = None) -> FitResult:
    """Fit a candidate whose gain over the nominal model is ``fn`` (see module docstring)."""
    box = Box(specs)
    rng = np.random.default_rng(seed)
    u_map, g_map, n_eval = find_map(fn, box, rng, hint_u=hint_u)
    pu, pw = _laplace_pilot(fn, box, u_map, rng)
    stage1 = importance_evidence(fn, box, pu, pw, rng, n_is // 2)
    ev = importance_evidence(fn, box, stage1.u, stage1.w, rng, n_is)
    n_eval += stage1.n_eval + ev.n_eval + 2 * N_GRID
    th = box.to_theta(ev.u)
    intervals = {}
    for i, s in enumerate(specs):
        lo, hi = weighted_quantile(th[:, i], ev.w, [0.025, 0.975])
        intervals[s.name] = (float(lo), float(hi))
    sens: dict[str, float] = {}
    if sensitivity:
        for label, f in (("halved", 0.5), ("doubled", 2.0)):
            b2 = box.scaled(f)
            u2 = np.clip(b2.to_unit(th), -1, 2)
            keep = np.all((u2 >= 0) & (u2 <= 1), axis=1)
            if keep.sum() >= 10 and ev.w[keep].sum() > 0:
                w2, u2 = ev.w[keep], u2[keep]
            else:  # the posterior lies outside the narrower box: start from the prior
                w2, u2 = np.ones(len(ev.w)), rng.random((len(ev.w), box.dim))
            e2 = importance_evidence(fn, b2, u2, w2 / w2.sum(), rng, n_is // 2)
            n_eval += e2.n_eval
            sens[label] = float(e2.log_z)
    check = check_err = None
    method = "none"
    if nested:
        check, check_err = nested_check(fn, box, n_live, seed + 1)
        method = "nested sampling (dynesty)"
    return FitResult(box.to_theta(u_map)[0], g_map, ev, check, check_err, method, intervals, sens, n_eval)
