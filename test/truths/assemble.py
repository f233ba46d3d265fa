"""Build the OpenSees model of a :class:`Building` in a :class:`StoryState` (3-D, 6 DOF per node).

Node numbers: column line j of floor f is ``1000 f + j + 1``, floor f's centre of mass ``1000 f + 99``,
the fixed soil anchor under footing node ``nd`` is ``90000 + nd``. Damping: Rayleigh on the initial
stiffness (ratios ``Building.zeta`` met at the first and the fourth mode, the first translational
and a higher one) plus discrete dashpots, which makes it non-proportional.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .building import Building
from .opensees import eigen_hz, fresh, ops
from .story_state import Soil, Spring, StoryState


@dataclass
class Handles:
    masters: list[int]                            # floor 1..n centres of mass
    story_elements: dict[int, list[int]] = field(default_factory=dict)  # story -> spring elements
    foundation: int | None = None                 # a footing node (x displacement = foundation sway)
    anchors: list[int] = field(default_factory=list)


class _Tags:
    def __init__(self) -> None:
        self.mat = 0
        self.ele = 0

    def m(self) -> int:
        self.mat += 1
        return self.mat

    def e(self) -> int:
        self.ele += 1
        return self.ele


def _line_material(t: _Tags, state: StoryState, story: int, k: float) -> int:
    tag = t.m()
    nonlinear = story in state.nonlinear_stories and state.yield_drift is not None
    if state.spring is Spring.STEEL02 and nonlinear:
        dy = float(state.yield_drift[story])  # type: ignore[index]
        r = state.nonlinear_share
        ops.uniaxialMaterial("Elastic", tag + 1000, k * (1 - r))
        ops.uniaxialMaterial("Steel02", tag + 2000, r * k * dy, r * k, 0.02, 10.0, 0.0, 0.15)  # R fixed
        ops.uniaxialMaterial("Parallel", tag, tag + 1000, tag + 2000)
    elif state.spring is Spring.CRACK and nonlinear:
        d0 = float(state.yield_drift[story])  # type: ignore[index]
        k_open, big = k * (1 - state.nonlinear_share), 10.0
        ops.uniaxialMaterial("ElasticMultiLinear", tag, 0.0, "-strain", -big, 0.0, d0, big,
                             "-stress", -k * big, 0.0, k * d0, k * d0 + k_open * (big - d0))
    else:
        ops.uniaxialMaterial("Elastic", tag, k)
    return tag


def _extra_devices(t: _Tags, b: Building, state: StoryState, s: int) -> list[int]:
    """Dashpots, braces and orifice dampers of story s (one material per direction, shared by lines)."""
    mats = []
    c = b.damper_c[s] * (1.0 if state.damper_factor is None else state.damper_factor[s])
    if c > 0:
        mats.append(t.m())
        ops.uniaxialMaterial("Viscous", mats[-1], c, 1.0)
    if state.brace_k is not None and state.brace_k[s] > 0:
        mats.append(t.m())
        ops.uniaxialMaterial("Elastic", mats[-1], float(state.brace_k[s]))
        mats.append(t.m())
        ops.uniaxialMaterial("Viscous", mats[-1], float(state.brace_c[s]), 1.0)  # type: ignore[index]
    if state.quad_c is not None and state.quad_c[s] > 0:
        mats.append(t.m())
        ops.uniaxialMaterial("Viscous", mats[-1], float(state.quad_c[s]), 2.0)
    return mats


def _footing(t: _Tags, soil: Soil, node: int, share: float) -> int:
    """A footing under one column line: its own fixed anchor and softening soil springs in x and y
    (Hysteretic backbone: k to the knee, 0.35 k to 4 knees, 0.08 k to 20 knees), mass ``share``."""
    anchor = 90000 + node
    ops.node(anchor, *ops.nodeCoord(node))
    ops.fix(anchor, 1, 1, 1, 1, 1, 1)
    k, e1 = soil.k_sway * share, soil.yield_sway
    tag = t.m()
    s1, s2 = k * e1, k * e1 + 0.35 * k * 3 * e1
    s3 = s2 + 0.08 * k * 16 * e1
    ops.uniaxialMaterial("Hysteretic", tag, s1, e1, s2, 4 * e1, s3, 20 * e1,
                         -s1, -e1, -s2, -4 * e1, -s3, -20 * e1, 1.0, 1.0, 0.0, 0.0, 0.0)
    ops.element("zeroLength", t.e(), anchor, node, "-mat", tag, tag, "-dir", 1, 2)
    ops.mass(node, soil.mass * share, soil.mass * share, 0.0, 0.0, 0.0, 0.0)
    return anchor


def build(b: Building, state: StoryState) -> Handles:
    """Assemble the model in the global OpenSees domain (wiped first)
    returns the node/element tags."""
    fresh(3, 6)
    t = _Tags()
    lines = b.lines_xy()
    cm = b.cm_xy()
    z = np.concatenate([[0.0], b.heights_above_base()])
    soil = state.soil
    h = Handles(masters=[])
    for f in range(b.n + 1):
        for j, (x, y) in enumerate(lines):
            nd = 1000 * f + j + 1
            ops.node(nd, x, y, float(z[f]))
            if f == 0 and soil is None:
                ops.fix(nd, 1, 1, 1, 1, 1, 1)
            elif f == 0:
                ops.fix(nd, 0, 0, 1, 1, 1, 1)
            else:
                ops.fix(nd, 0, 0, 1, 1, 1, 0)
            if f == 0 and soil is not None:
                h.anchors.append(_footing(t, soil, nd, 1.0 / len(lines)))
                h.foundation = nd
        if f == 0:
            continue
        master = 1000 * f + 99
        ops.node(master, *cm, float(z[f]))
        ops.fix(master, 0, 0, 1, 1, 1, 0)
        m = float(b.masses[f - 1])
        ops.mass(master, m, m, 0.0, 0.0, 0.0, b.polar_inertia(m))
        ops.rigidDiaphragm(3, master, *[1000 * f + j + 1 for j in range(len(lines))])
        h.masters.append(master)
        s = f - 1
        devices = _extra_devices(t, b, state, s)
        h.story_elements[s] = []
        for j in range(len(lines)):
            mx = _line_material(t, state, s, float(b.k_x[s] * b.share_x[j] * state.k_factor[s]))
            my = _line_material(t, state, s, float(b.k_y[s] * b.share_y[j] * state.k_factor[s]))
            ni, nj = 1000 * (f - 1) + j + 1, 1000 * f + j + 1
            e = t.e()
            ops.element("zeroLength", e, ni, nj, "-mat", mx, my, "-dir", 1, 2, "-doRayleigh", 1)
            h.story_elements[s].append(e)
            share = 1.0 / len(lines)
            for mat in devices:  # devices spread evenly over the lines, x and y
                _device(t, mat, ni, nj, share)
    return h


def _device(t: _Tags, mat: int, ni: int, nj: int, share: float) -> None:
    """One share of a story device between two column-line nodes (scaled copy of its material)."""
    tag = t.m()
    ops.uniaxialMaterial("Parallel", tag, mat, "-factors", share)
    ops.element("zeroLength", t.e(), ni, nj, "-mat", tag, tag, "-dir", 1, 2, "-doRayleigh", 0)


def add_rayleigh(b: Building) -> np.ndarray:
    """Rayleigh damping on the initial stiffness meeting ``b.zeta`` at modes 1 and 4
    returns the
    first six undamped frequencies (Hz)."""
    n_modes = min(6, 3 * b.n)
    f = eigen_hz(n_modes)
    w1, w2 = 2 * np.pi * f[0], 2 * np.pi * f[min(3, n_modes - 1)]
    z1, z2 = b.zeta
    a1 = 2 * (z2 * w2 - z1 * w1) / (w2**2 - w1**2)
    a0 = 2 * z1 * w1 - a1 * w1**2
    ops.rayleigh(max(a0, 0.0), 0.0, max(a1, 0.0), 0.0)
    return f
