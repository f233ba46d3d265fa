"""The one extension point of updating's samplers: a sampler is a small class in this package.

A :class:`SamplerKind` registered by ``@SAMPLERS.register("<name>")`` draws from a batched
log-posterior ``log_prob(X) -> (B,)`` started around the MAP with the Laplace covariance, until the
ArviZ diagnostics meet the targets of :class:`~shm_ros.core.bayes.samplers.SamplerSettings`, and
returns a :class:`~shm_ros.core.bayes.samplers.ChainResult` (burn-in removed). The built-in names
are :class:`SamplerName`; a file of this package, an entry point or a file named in
``SHM_ROS_KINDS`` adds one (:mod:`shm_ros.core.plugins`).
"""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from shm_ros.core.plugins import KindRegistry

if TYPE_CHECKING:
    from shm_ros.core.bayes.samplers import ChainResult, LogProb, SamplerSettings


class SamplerName(enum.StrEnum):
    """The built-in samplers (the registry's keys)."""

    EMCEE = "emcee"  # affine-invariant ensemble
    MH = "mh"  # adaptive Metropolis-Hastings


class SamplerKind(ABC):
    """Base class of every sampler (see module docstring)."""

    name: ClassVar[str]  # registry key, set by the registry

    @abstractmethod
    def run(self, log_prob: LogProb, center: np.ndarray, cov: np.ndarray, settings: SamplerSettings,
            names: list[str]) -> ChainResult:
        ...


SAMPLERS: KindRegistry[SamplerKind] = KindRegistry("sampler", "shm_ros.core.bayes.sampler_kinds")


def sampler_kind(name: str) -> SamplerKind:
    """An instance of the sampler registered as ``name`` (ValueError listing the known ones)."""
    return SAMPLERS.instance(name)
