"""Prior distributions of the updating parameters (docs/interfaces.md section 2) and of error variances.

The one place that knows the prior families: the structure-file reader takes its field names from
:data:`PRIOR_FIELDS` and its distributions from :class:`Prior`.

Each prior offers a vectorised ``logpdf`` (hot path of every sampler, hence written out in numpy
rather than through ``scipy.stats``, whose per-call overhead dominates for a handful of values), and
``ppf``/``sample`` through ``scipy.stats`` (used by nested sampling and by walker initialisation).

Parametrisations follow the structure file:

* ``normal {mean, std}``
* ``lognormal {mean, std}`` - mean and standard deviation of the factor itself (not of its log),
  or ``lognormal {mu_ln, sigma_ln}`` - mean and standard deviation of its logarithm (one form only)
* ``weibull {scale, shape}`` - lambda and eta of the Weibull density
* ``uniform {low, high}``
* ``inverse_gamma {shape, scale}`` - for prediction-error variances
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import special

from shm_ros.errors import InputError

# family -> its fields, in the order of the structure file
PRIOR_FIELDS: dict[str, tuple[str, ...]] = {
    "normal": ("mean", "std"),
    "lognormal": ("mean", "std"),
    "weibull": ("scale", "shape"),
    "uniform": ("low", "high"),
    "inverse_gamma": ("shape", "scale"),
}
# families with a second way of writing them: family -> the alternative fields
PRIOR_ALT_FIELDS: dict[str, tuple[str, ...]] = {"lognormal": ("mu_ln", "sigma_ln")}
PRIOR_KINDS = tuple(PRIOR_FIELDS)
PARAMETER_PRIORS = ("normal", "lognormal", "weibull", "uniform")  # families a structure parameter may use


class PriorError(InputError):
    """A prior specification that cannot be used (names the parameter and field)."""


@dataclass(frozen=True)
class Prior:
    """A one-dimensional prior; ``kind`` and ``params`` exactly as written in the structure file."""

    kind: str
    params: Mapping[str, float]
    name: str = ""
    _frozen: Any = field(default=None, repr=False, compare=False)

    # -- construction -------------------------------------------------------------------------
    @staticmethod
    def make(kind: str, params: Mapping[str, Any], name: str = "") -> Prior:
        kind = str(kind).lower().replace("-", "_")
        where = f"prior of parameter '{name}'" if name else "prior"
        if kind not in PRIOR_FIELDS:
            raise PriorError(f"{where}: unknown dist '{kind}' (use one of {', '.join(PRIOR_KINDS)})")
        fields = prior_fields(kind, params, where)
        clean: dict[str, float] = {}
        for key in fields:
            if key not in params:
                raise PriorError(f"{where}: '{kind}' needs field '{key}'")
            try:
                clean[key] = float(params[key])
            except (TypeError, ValueError) as exc:
                raise PriorError(f"{where}: field '{key}' must be a number, got {params[key]!r}") from exc
            if not math.isfinite(clean[key]):
                raise PriorError(f"{where}: field '{key}' must be finite")
        positive = {"normal": ("std",), "lognormal": ("mean", "std", "sigma_ln"), "weibull": ("scale", "shape"),
                    "uniform": (), "inverse_gamma": ("shape", "scale")}[kind]
        for key in (k for k in positive if k in clean):
            if clean[key] <= 0:
                raise PriorError(f"{where}: field '{key}' must be > 0, got {clean[key]}")
        if kind == "uniform" and not clean["high"] > clean["low"]:
            raise PriorError(f"{where}: uniform needs high > low, got [{clean['low']}, {clean['high']}]")
        return Prior(kind, clean, name, _frozen=_scipy_frozen(kind, clean))

    # -- density ----------------------------------------------------------------------------------
    def logpdf(self, x: np.ndarray | float) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        p = self.params
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.kind == "normal":
                z = (x - p["mean"]) / p["std"]
                out = -0.5 * z * z - math.log(p["std"]) - 0.5 * math.log(2 * math.pi)
            elif self.kind == "lognormal":
                mu, sig = lognormal_mu_sigma(p)
                lx = np.log(np.where(x > 0, x, 1.0))
                z = (lx - mu) / sig
                out = np.where(x > 0, -0.5 * z * z - lx - math.log(sig) - 0.5 * math.log(2 * math.pi),
                               -np.inf)
            elif self.kind == "weibull":
                lam, eta = p["scale"], p["shape"]
                xs = np.where(x > 0, x, 1.0) / lam
                out = np.where(x > 0, math.log(eta / lam) + (eta - 1) * np.log(xs) - xs**eta, -np.inf)
            elif self.kind == "uniform":
                inside = (x >= p["low"]) & (x <= p["high"])
                out = np.where(inside, -math.log(p["high"] - p["low"]), -np.inf)
            else:  # inverse_gamma
                a, b = p["shape"], p["scale"]
                xp = np.where(x > 0, x, 1.0)
                out = np.where(x > 0, a * math.log(b) - special.gammaln(a) - (a + 1) * np.log(xp) - b / xp,
                               -np.inf)
        return out

    # -- library-backed parts ---------------------------------------------------------------------
    @property
    def dist(self):  # scipy.stats frozen distribution
        return self._frozen if self._frozen is not None else _scipy_frozen(self.kind, self.params)

    def ppf(self, u: np.ndarray | float) -> np.ndarray:
        """Quantile function. Closed forms through ``scipy.special`` (nested sampling calls this for
        every proposal, and ``scipy.stats``' argument checking would cost most of the run)."""
        u = np.asarray(u, dtype=float)
        p = self.params
        if self.kind == "normal":
            return p["mean"] + p["std"] * special.ndtri(u)
        if self.kind == "lognormal":
            mu, sig = lognormal_mu_sigma(p)
            return np.exp(mu + sig * special.ndtri(u))
        if self.kind == "weibull":
            return p["scale"] * (-np.log1p(-u)) ** (1.0 / p["shape"])
        if self.kind == "uniform":
            return p["low"] + u * (p["high"] - p["low"])
        return p["scale"] / special.gammainccinv(p["shape"], u)  # inverse gamma

    def sample(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> np.ndarray:
        return self.dist.rvs(size=size, random_state=rng)

    @property
    def mean(self) -> float:
        return float(self.dist.mean())

    @property
    def std(self) -> float:
        return float(self.dist.std())

    def describe(self) -> dict[str, Any]:
        return {"dist": self.kind, **{k: float(v) for k, v in self.params.items()}}


def prior_fields(kind: str, params: Mapping[str, Any], where: str = "prior") -> tuple[str, ...]:
    """The fields ``params`` uses for family ``kind``: the usual ones, or the alternative form
    (:data:`PRIOR_ALT_FIELDS`) when any of its fields is present. Mixing the two forms is an error."""
    alt = PRIOR_ALT_FIELDS.get(kind, ())
    used_alt = [k for k in alt if k in params]
    if not used_alt:
        return PRIOR_FIELDS[kind]
    used_main = [k for k in PRIOR_FIELDS[kind] if k in params]
    if used_main:
        raise PriorError(f"{where}: give either {{{', '.join(PRIOR_FIELDS[kind])}}} or {{{', '.join(alt)}}}, "
                         f"not both (found {', '.join(used_main + used_alt)})")
    return alt


def lognormal_mu_sigma(p: Mapping[str, float]) -> tuple[float, float]:
    """Mean and standard deviation of the logarithm of a lognormal factor, from either form."""
    if "mu_ln" in p:
        return float(p["mu_ln"]), float(p["sigma_ln"])
    mean, std = float(p["mean"]), float(p["std"])
    s2 = math.log1p((std / mean) ** 2)
    return math.log(mean) - 0.5 * s2, math.sqrt(s2)


def _scipy_frozen(kind: str, p: Mapping[str, float]):
    from scipy import stats  # here: the structure-file reader imports this module, rarely needs stats

    if kind == "normal":
        return stats.norm(loc=p["mean"], scale=p["std"])
    if kind == "lognormal":
        mu, sig = lognormal_mu_sigma(p)
        return stats.lognorm(s=sig, scale=math.exp(mu))
    if kind == "weibull":
        return stats.weibull_min(c=p["shape"], scale=p["scale"])
    if kind == "uniform":
        return stats.uniform(loc=p["low"], scale=p["high"] - p["low"])
    return stats.invgamma(a=p["shape"], scale=p["scale"])


def weibull_matching(mean: float, std: float) -> dict[str, float]:
    """Weibull ``{scale, shape}`` with the given mean and standard deviation (moment matching)."""
    from scipy.optimize import brentq

    cv = std / mean

    def cv_of(eta: float) -> float:
        g1 = special.gamma(1 + 1 / eta)
        return math.sqrt(special.gamma(1 + 2 / eta) / g1**2 - 1) - cv

    eta = brentq(cv_of, 0.2, 500.0)
    return {"scale": mean / special.gamma(1 + 1 / eta), "shape": eta}


class JointPrior:
    """Independent priors over a parameter vector, evaluated for a batch ``(n, d)`` at once."""

    def __init__(self, priors: Sequence[Prior]):
        if not priors:
            raise PriorError("no parameters to update: the structure file lists no 'parameters'")
        self.priors = list(priors)
        self.names = [p.name or f"theta{i}" for i, p in enumerate(self.priors)]

    @property
    def dim(self) -> int:
        return len(self.priors)

    def logpdf(self, theta: np.ndarray) -> np.ndarray:
        theta = np.atleast_2d(theta)
        out = np.zeros(theta.shape[0])
        for i, p in enumerate(self.priors):
            out = out + p.logpdf(theta[:, i])
        return out

    def transform(self, u: np.ndarray) -> np.ndarray:
        """Unit cube -> parameter space (the prior transform of nested sampling)."""
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            return np.array([float(p.ppf(ui)) for p, ui in zip(self.priors, u, strict=True)])
        return np.column_stack([p.ppf(u[:, i]) for i, p in enumerate(self.priors)])

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return np.column_stack([np.atleast_1d(p.sample(rng, n)) for p in self.priors])


def priors_from_specs(specs: Sequence[Any]) -> JointPrior:
    """Build the joint prior from parameter specs of a structure (``name`` + ``prior.dist/params``).

    Accepts objects with attributes ``name`` and ``prior`` (``prior.dist``, ``prior.params``) or
    mappings ``{"name":..., "prior": {"dist":..., ...}}``.
    """
    out = []
    for spec in specs:
        if isinstance(spec, Mapping):
            name = str(spec.get("name", ""))
            pr = spec.get("prior")
            if not isinstance(pr, Mapping):
                raise PriorError(f"parameter '{name}': missing 'prior'")
            dist = pr.get("dist")
            params = {k: v for k, v in pr.items() if k != "dist"}
        else:
            name = str(getattr(spec, "name", ""))
            pr = getattr(spec, "prior", None)
            if pr is None:
                raise PriorError(f"parameter '{name}': missing 'prior'")
            dist = getattr(pr, "dist", None)
            params = dict(getattr(pr, "params", {}) or {})
        if dist is None:
            raise PriorError(f"parameter '{name}': prior has no 'dist'")
        out.append(Prior.make(dist, params, name))
    return JointPrior(out)
