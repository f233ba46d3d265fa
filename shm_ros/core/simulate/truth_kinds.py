"""Which structure kinds the simulator can play "reality" for: one truth-model class per kind.

A truth model (:class:`~shm_ros.core.simulate.truth.TruthModel`) registers with ``@register("kind")``
in its own file under ``shm_ros/core/simulate/truths/`` (or in a user's kind file, see
:mod:`shm_ros.core.plugins`); the kind name is the structure kind it simulates.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from shm_ros.core.plugins import KindRegistry

if TYPE_CHECKING:  # annotation only: truth models import this module to register
    from shm_ros.core.simulate.truth import TruthModel

__all__ = ["TRUTH_KINDS", "register", "truth_class", "simulated_kinds"]

TRUTH_KINDS: KindRegistry[TruthModel] = KindRegistry("simulated structure kind", "shm_ros.core.simulate.truths")
register = TRUTH_KINDS.register


def truth_class(kind: str) -> type[TruthModel]:
    """The truth-model class of structure ``kind`` (KeyError naming the kinds that can be simulated)."""
    return TRUTH_KINDS.get(kind)


def simulated_kinds() -> list[str]:
    return TRUTH_KINDS.names()
