"""Structure kinds: what a ``kind:`` of a structure file means, one small class per kind.

A kind reads its own section of the structure file (``girder:``, ``shear_building:``, ...), checks
where its sensors may sit, says which of its numbers a parameter may scale, proposes a default
sensor layout and builds the :class:`~shm_ros.core.models.base.AffineModel` that updating uses.
Everything else (names, damping, sensors' sources, parameters and priors, paths) is shared and lives
in :mod:`shm_ros.core.structure`.

A new kind is one new file that subclasses :class:`ModelKind` and decorates it with
``@register("name")``: in ``shm_ros/core/models/kinds/`` for a built-in kind, or anywhere for a
user's kind (see :mod:`shm_ros.core.plugins` for how such a file is found). The simulator's truth
model of a kind, if it has one, registers separately (:mod:`shm_ros.core.simulate.truth_kinds`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

from shm_ros.core.plugins import KindRegistry

if TYPE_CHECKING:  # annotations only: the structure module imports this one
    import numpy as np

    from shm_ros.core.models.base import AffineModel
    from shm_ros.core.structure import FieldReader, Location, StructureSpec

__all__ = ["ModelKind", "MODEL_KINDS", "register", "model_kind", "kind_names"]


class ModelKind(ABC):
    """One structure kind. Stateless: the registry keeps one instance per kind."""

    name: ClassVar[str]  # set by ``register``: the ``kind:`` value and the key of the kind's section
    title: ClassVar[str] = ""  # plain-language name for messages and reports, e.g. "girder on bearings"
    # key of the kind's section that names an ``.npz`` file the structure-file loader reads (None: none)
    array_file_field: ClassVar[str | None] = None

    @abstractmethod
    def parse_section(self, r: FieldReader, value: Any, arrays: Mapping[str, np.ndarray] | None) -> Any:
        """The typed section from the mapping under ``<name>:``; errors via ``r.err(msg, field)``.
        ``arrays``: the contents of the ``array_file_field`` file, if the kind has one."""

    @abstractmethod
    def section_to_dict(self, section: Any) -> dict[str, Any]:
        """The section back in structure-file form (plain YAML types)."""

    @abstractmethod
    def sensor_location(self, r: FieldReader, section: Any, at: Mapping[str, Any], direction: str,
                        fld: str) -> dict[str, Any]:
        """The validated ``at`` mapping of a sensor (``fld`` is the sensor's field path)."""

    def n_dof(self, section: Any) -> int:
        """Degrees of freedom of the model the section describes (an upper estimate; 0: unknown), checked
        against the structure loader's limit before anything is built."""
        return 0

    @abstractmethod
    def updatable(self, loc: Location) -> bool:
        """Whether a location inside this kind's section is a number a parameter may scale."""

    def product_keys(self, section: Any, loc: Location) -> list[tuple]:
        """Model terms the location multiplies (two parameters on one term would not be affine)."""
        return [loc]

    @abstractmethod
    def default_sensors(self, section: Any) -> list[dict[str, Any]]:
        """A sensible sensor layout for the section, as ``sensors:`` entries of a structure file."""

    @abstractmethod
    def build(self, spec: StructureSpec, **overrides: Any) -> AffineModel:
        """The affine model of ``spec``; unknown ``overrides`` raise TypeError."""


MODEL_KINDS: KindRegistry[ModelKind] = KindRegistry("structure kind", "shm_ros.core.models.kinds")
register = MODEL_KINDS.register
_instances: dict[type[ModelKind], ModelKind] = {}


def model_kind(name: str) -> ModelKind:
    """The kind registered as ``name`` (KeyError listing the known kinds)."""
    cls = MODEL_KINDS.get(name)
    if cls not in _instances:
        _instances[cls] = cls()
    return _instances[cls]


def kind_names() -> list[str]:
    return MODEL_KINDS.names()
