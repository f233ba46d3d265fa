"""The truth model: the structure as "reality" has it, built with the project's own model builders.

It differs from the nominal structure file the way a real structure differs from its design model
(finer mesh, scattered properties, misplaced sensors, damping that is not what the file says), plus
the hidden effects the scenario switches on (:mod:`shm_ros.core.simulate.effects`). With
``model_form`` (the named scenarios' default) it is also richer than any analysis model of its kind:
motion the analysis model has no DOF for (a girder's lateral bending and torsion, a building's
y-sway and torsion from eccentric mass), physics it leaves out (shear deformation, partial rotational
restraint, non-classical damping); :mod:`shm_ros.core.simulate.model_form` reports what that costs
the best-fitting analysis model. Every mode carries its family (:attr:`ModalTruth.families`): the
in-plane family is the motion the analysis model describes. Every per-window
property change is a multiplicative factor on a parameter of the truth model's affine form
``K = K0 + sum theta_i K_i`` (parameters the truth spec declares for itself, e.g. one per span).

:class:`TruthModel` is what every kind's truth model offers the campaign; each simulated kind has its
own subclass in ``shm_ros/core/simulate/truths/`` (see :mod:`shm_ros.core.simulate.truth_kinds`).
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.simulate.effects import Conditions, Effect, EffectError
from shm_ros.core.simulate.linear import ModalSystem
from shm_ros.core.simulate.truth_kinds import simulated_kinds, truth_class
from shm_ros.core.structure import StructureSpec, structure_from_dict

# prior of the truth spec's own parameters: they only name model terms, nothing is inferred
FLAT_PRIOR = {"dist": "uniform", "low": 0.0, "high": 10.0}


@dataclass
class ModalTruth:
    """True modal properties of one window (lowest modes, ascending frequency)."""

    frequencies_hz: np.ndarray
    damping_ratios: np.ndarray
    shapes: np.ndarray  # (n_sensors, n_modes) real, largest |.| = +1 per mode (signal axes)
    sensor_ids: list[str]
    families: list[str] = field(default_factory=list)  # per mode, e.g. "vertical" / "lateral" / "torsion"
    in_plane_family: str = ""  # the family the analysis model describes ("vertical", "x", ...)

    def in_plane(self) -> np.ndarray:
        """Indices of the in-plane modes (all modes when no family is marked)."""
        if not self.families:
            return np.arange(self.frequencies_hz.size)
        return np.array([j for j, f in enumerate(self.families) if f == self.in_plane_family], dtype=int)

    def select(self, idx: np.ndarray) -> ModalTruth:
        fam = [self.families[j] for j in idx] if self.families else []
        return ModalTruth(self.frequencies_hz[idx], self.damping_ratios[idx], self.shapes[:, idx],
                          list(self.sensor_ids), fam, self.in_plane_family)


def report_modes(f: np.ndarray, families: list[str], in_plane: str, n_in_plane: int) -> np.ndarray:
    """Indices (ascending frequency) of the modes a truth reports: the lowest ``n_in_plane`` in-plane
    modes and every out-of-plane mode below the highest of them (the modes a record of that band
    holds; ``f`` ascending)."""
    inp = [j for j, fam in enumerate(families) if fam == in_plane][:n_in_plane]
    if not inp:
        return np.zeros(0, dtype=int)
    top = f[inp[-1]]
    return np.array([j for j, fam in enumerate(families) if j in inp or (fam != in_plane and f[j] <= top)],
                    dtype=int)


@dataclass
class TruthOptions:
    """How far the truth departs from the nominal file (the scenario's settings)."""

    refine: int = 4  # truth elements per nominal element (meshed kinds)
    scatter: float = 0.03  # relative scatter of stiffness and mass properties
    misplacement_std_m: float = 0.15  # sensor misplacement (kinds with continuous sensor positions)
    damping_range: tuple[float, float] = (0.012, 0.025)  # truth damping ratios
    n_truth_modes: int = 6  # in-plane modes reported; out-of-plane modes among them come in addition
    fs: float = 100.0
    model_form: bool = True  # richer than the analysis model (see module doc)
    # building: range of the mass centres' offset from the stiffness centre, fraction of the plan
    # (None: the plan form's default, 1-2 %)
    eccentricity: tuple[float, float] | None = None


@dataclass
class WindowRun:
    """What a truth model needs to compute one window's response."""

    factors: dict[str, float]  # effect group -> factor of this window
    amplitude_effects: list[Effect]  # effects that depend on the response amplitude
    system: ModalSystem  # the linear system under ``factors``
    modal: ModalTruth  # its true modal properties
    inputs: np.ndarray  # the window's inputs (from :meth:`TruthModel.loads`), warm-up included
    dt: float
    n_warm: int  # warm-up samples at the start of ``inputs``
    inputs_for: Callable[[ModalSystem], np.ndarray]  # the same loads for another system (same draws)


@dataclass
class TruthModel(ABC):
    """Truth structure of a scenario; :meth:`system` gives the simulation model of one window."""

    name: ClassVar[str]  # the structure kind, set by ``truth_kinds.register``
    supports_earthquakes: ClassVar[bool] = False  # whether a ground motion drives the model
    # effect key -> default parameters for this kind (an effect missing here is not available)
    effect_defaults: ClassVar[dict[str, dict[str, Any]]] = {}
    effect_forms: ClassVar[dict[str, str]] = {}  # effect key -> how it acts, where that depends on kind
    effect_where: ClassVar[dict[str, str]] = {}  # effect key ("*": any other) -> default where
    stiffness_wheres: ClassVar[dict[str, str]] = {}  # where value -> effect group, beyond EI / EI:k

    nominal: StructureSpec
    spec: StructureSpec
    model: AffineModel
    groups: dict[str, list[int]]  # effect group -> parameter indices of ``model``
    sensor_ids: list[str]  # output channels, in order
    input_names: list[str]
    info: dict[str, Any] = field(default_factory=dict)
    max_frequency_hz: float = 45.0
    in_plane_family: str = ""  # family of the modes the analysis model describes

    @property
    def kind(self) -> str:
        return self.name

    @classmethod
    @abstractmethod
    def build(cls, nominal: StructureSpec, structure: dict[str, Any], effects: list[Effect],
              rng: np.random.Generator, options: TruthOptions) -> TruthModel:
        """The truth model of the ``nominal`` structure (``structure``: its mapping, to modify)."""

    @abstractmethod
    def system(self, factors: dict[str, float], k_scale: np.ndarray | None = None,
               c_scale: np.ndarray | None = None, damping_scale: float = 1.0) -> tuple[ModalSystem, ModalTruth]:
        """Simulation model and true modal properties under the effect ``factors`` of a window.
        ``k_scale``/``c_scale``/``damping_scale``: equivalent-linear amplitude effects, where the
        kind has them."""

    @abstractmethod
    def loads(self, rng: np.random.Generator, n: int, cond: Conditions, scenario: Any, system: ModalSystem | None,
              event: dict[str, float] | None) -> tuple[np.ndarray, dict | None]:
        """Inputs of a window (n samples) and the earthquake it carries, if any."""

    @abstractmethod
    def respond(self, run: WindowRun) -> tuple[np.ndarray, ModalTruth, dict[str, Any]]:
        """True absolute accelerations (n, 3 n_sensors) along x, y, z of the structure at every
        sensor (column ``3 c + a``: sensors read a little of the axes they should not) incl.
        warm-up, the window's modal truth and extra entries of the window's truth record."""

    @abstractmethod
    def summary(self) -> dict[str, Any]:
        """Kind-specific entries of ``truth.json``'s ``truth_model``."""

    # -- per-window parameters ----------------------------------------------------------------
    def theta(self, factors: dict[str, float]) -> np.ndarray:
        th = np.ones(self.model.n_parameters)
        for group, f in factors.items():
            if group == "damper":
                continue
            if group not in self.groups:
                raise EffectError(f"effect group {group!r} does not exist in a {self.kind} truth model")
            th[self.groups[group]] *= f
        return th


def build_truth(structure: dict[str, Any], effects: list[Effect], rng: np.random.Generator, *,
                refine: int = 4, scatter: float = 0.03, misplacement_std_m: float = 0.15,
                damping_range: tuple[float, float] = (0.012, 0.025), n_truth_modes: int = 6,
                fs: float = 100.0, model_form: bool = True,
                eccentricity: tuple[float, float] | None = None) -> TruthModel:
    """Truth model of the nominal ``structure`` mapping (see module doc); ``rng`` draws the scatter."""
    nominal = structure_from_dict(copy.deepcopy(structure), source="<nominal>")
    try:
        cls = truth_class(nominal.kind)
    except KeyError:
        raise EffectError(f"cannot simulate a structure of kind {nominal.kind!r} "
                          f"({' or '.join(simulated_kinds())})") from None
    options = TruthOptions(refine=refine, scatter=scatter, misplacement_std_m=misplacement_std_m,
                           damping_range=damping_range, n_truth_modes=n_truth_modes, fs=fs,
                           model_form=model_form, eccentricity=eccentricity)
    return cls.build(nominal, structure, effects, rng, options)
