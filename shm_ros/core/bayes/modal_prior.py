"""The modal posterior carried forward as a prior: per parameter a normal of its mean and standard
deviation (the ambient windows' information, for a later update on other data, e.g. earthquakes'
records in the time domain)."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from shm_ros.core.structure import ParameterSpec, PriorSpec, StructureSpec


def modal_priors(spec: StructureSpec, modal: Mapping[str, Mapping[str, Any]]) -> list[ParameterSpec]:
    """The structure's parameters with, for each ``modal`` summarises (``{"mean", "std"}``, as in
    ``posterior.json``), the prior normal(mean, std); the others keep the structure's prior."""
    params = copy.deepcopy(spec.parameters)
    for p in params:
        s = modal.get(p.name)
        if s is not None and float(s["std"]) > 0:
            p.prior = PriorSpec("normal", {"mean": float(s["mean"]), "std": float(s["std"])})
    return params
