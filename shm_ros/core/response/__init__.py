"""Exact time-domain response of a structural model to measured inputs.

``response(model, theta, records, dt, outputs)``: the model at ``theta`` (``AffineModel``, its
``inputs`` from the structure file: base, floor and force inputs, several at once; its dampers,
Kelvin-Voigt and Maxwell) from rest, outputs at every sample. The inputs are taken as linear
between samples, and for such inputs the result is exact (one matrix exponential per theta):

- :mod:`.supports`   which DOFs are driven, which are free, what the inputs leave unknown;
- :mod:`.statespace` continuous A, B, C, D (non-classical damping, Maxwell states);
- :mod:`.discretize` the exact first-order-hold step;
- :mod:`.simulate`   the recursion;
- :mod:`.outputs`    absolute accelerations at sensors, displacements, interstory drifts.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.structure import InputSpec

from .discretize import DiscreteSystem, discretize_foh
from .outputs import Output, Quantity, drift_outputs, node_row, sensor_outputs
from .simulate import simulate
from .statespace import StateSpace, build_state_space, build_state_spaces
from .supports import Supports, partition

__all__ = [
    "DiscreteSystem",
    "Output",
    "Quantity",
    "StateSpace",
    "Supports",
    "build_state_space",
    "build_state_spaces",
    "discretize_foh",
    "drift_outputs",
    "node_row",
    "partition",
    "response",
    "sensor_accelerations",
    "sensor_outputs",
    "simulate",
]


def response(model: AffineModel, theta: np.ndarray | None, records: np.ndarray, dt: float,
             outputs: Sequence[Output], inputs: Sequence[InputSpec] | None = None) -> np.ndarray:
    """Outputs (n_outputs, N) of ``model`` at ``theta`` (None: nominal) from rest.

    ``records`` (n_inputs, N) or (N,) for one input: the input sensors' samples, one row per input
    in the order of ``inputs`` (default ``model.inputs``); each input's gain is applied here.
    """
    ins = list(model.inputs if inputs is None else inputs)
    u = np.atleast_2d(np.asarray(records, dtype=float))
    if u.shape[0] != len(ins):
        raise ValueError(f"records must have one row per input ({len(ins)}: "
                         f"{[i.sensor for i in ins]}), got shape {u.shape}")
    ss = build_state_space(model, theta, outputs, ins)
    return simulate(discretize_foh(ss, dt), u)


def sensor_accelerations(model: AffineModel, theta: np.ndarray | None, records: np.ndarray, dt: float,
                         sensor_ids: Sequence[str], inputs: Sequence[InputSpec] | None = None) -> np.ndarray:
    """Absolute accelerations (N, n_sensors) at ``sensor_ids``: what accelerometers read."""
    return response(model, theta, records, dt, sensor_outputs(model, sensor_ids), inputs).T
