"""The one extension point of updating's likelihoods: a likelihood is a small class in this package.

A :class:`LikelihoodKind` registered by ``@LIKELIHOODS.register("<name>")`` builds, from the model,
the data and the settings (:class:`LikelihoodInputs`), an object that follows the :class:`Likelihood`
protocol: a batched log-likelihood of parameter vectors. Modal kinds (``modal = True``) read
:class:`~shm_ros.core.observations.ModalObservations` through a predictor of the model's modes and
a fixed pairing of the data's modes with the model's, both made by :func:`~shm_ros.core.bayes.update.update`;
the others read their data themselves (accelerations). Everything else - priors, the MAP, sampling,
the evidence, the summary - is shared. The built-in names are :class:`LikelihoodName`; a file of
this package, an entry point or a file named in ``SHM_ROS_KINDS`` adds one (:mod:`shm_ros.core.plugins`).
"""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

from shm_ros.core.plugins import KindRegistry

if TYPE_CHECKING:
    from shm_ros.core.bayes.update import UpdateConfig
    from shm_ros.core.models.base import AffineModel


class LikelihoodName(enum.StrEnum):
    """The built-in likelihoods (the registry's keys)."""

    MODEL_ERROR = "model-error"  # modal data with a systematic model error shared by the windows
    GAUSSIAN = "gaussian"  # Gaussian prediction error on modal data, windows independent
    FITNESS = "fitness"  # the bridge paper's exp(-J / 2k^2)
    TIME = "time"  # accelerations under the measured input


class Likelihood(Protocol):
    """A built likelihood: ``x`` (B, d + n_extra) holds the d structural parameters, then the
    likelihood's own sampled nuisance columns (``extra_names``, e.g. log-variances)."""

    extra_names: list[str]

    @property
    def n_extra(self) -> int: ...

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Log-likelihood (B,) of a batch."""

    def extra_logprior(self, extra: np.ndarray) -> np.ndarray:
        """Log prior (B,) of the nuisance columns."""

    def extra_initial(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Starting nuisance columns (n, n_extra)."""

    def variance_estimates(self, theta: np.ndarray) -> dict[str, float]:
        """Error variances (and the like) at one theta, for the report; may be empty."""

    def prepare_at_map(self, theta: np.ndarray) -> bool:
        """Called once at the first MAP; True when it changed the likelihood (the MAP is then
        searched again), e.g. a residual model estimated there."""


class NoNuisance:
    """Defaults for a likelihood with no nuisance columns, no error variances to report and nothing
    to prepare at the MAP (a new likelihood overrides what it has)."""

    extra_names: list[str] = []

    @property
    def n_extra(self) -> int:
        return len(self.extra_names)

    def extra_logprior(self, extra: np.ndarray) -> np.ndarray:
        return np.zeros(extra.shape[0])

    def extra_initial(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return np.zeros((n, 0))

    def variance_estimates(self, theta: np.ndarray) -> dict[str, float]:
        return {}

    def prepare_at_map(self, theta: np.ndarray) -> bool:
        return False


@dataclass
class LikelihoodInputs:
    """What a likelihood is built from. Modal kinds get ``predictor`` (the model's modes at the
    sensors) and ``pairing`` (model mode, 0-based, of every data mode) from the updating."""

    model: AffineModel
    data: Any
    config: UpdateConfig
    predictor: Any = None
    pairing: np.ndarray | None = None


class LikelihoodKind(ABC):
    """Base class of every likelihood (see module docstring)."""

    name: ClassVar[str]  # registry key, set by the registry
    modal: ClassVar[bool] = True  # reads ModalObservations through a predictor and a pairing
    uses_damping: ClassVar[bool] = False  # damping ratios may enter (``UpdateConfig.use_damping``)

    @abstractmethod
    def build(self, inputs: LikelihoodInputs) -> Likelihood:
        ...


LIKELIHOODS: KindRegistry[LikelihoodKind] = KindRegistry("likelihood", "shm_ros.core.bayes.likelihood_kinds")


def likelihood_kind(name: str) -> LikelihoodKind:
    """An instance of the likelihood registered as ``name`` (ValueError listing the known ones)."""
    return LIKELIHOODS.instance(name)
