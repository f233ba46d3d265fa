"""The accepted effects refined together (``core/explain/joint.py``): from a point on the ridge the
two effects trade along (one too large, the other at its best given it), the joint search climbs
to the ridge's top; from the top it returns nothing; the combined modification is the one a fit
on top uses.

The effects are two small candidates acting on one group: a knee (stiffer by ``slope`` per degree
below 0 degC) and a step (``size`` from window 60 on), with the cold spells mostly after the step,
so that a steeper knee and a deeper step fit the later windows almost as well as the truth. The
model's log-frequency change is the log of the group's factor; the likelihood is Gaussian with a
0.3 % scatter.
"""

from __future__ import annotations

import numpy as np

from shm_ros.core.explain.candidates.base import Modification, ParamSpec
from shm_ros.core.explain.jobs import OnTop
from shm_ros.core.explain.joint import joint_modification, joint_refine

W = 100
rng = np.random.default_rng(3)
TEMP = np.where(np.arange(W) < 60, rng.uniform(-1.0, 10.0, W), rng.uniform(-6.0, 4.0, W))
AFTER = (np.arange(W) >= 60).astype(float)
TRUTH = {"slope": 0.02, "size": -0.06}


class Knee:
    group, context = "EI:2", None
    vocabulary = name = explanation = label = "knee"

    def params(self):
        return [ParamSpec("slope", 0.0, 0.1, null=0.0)]

    def modify(self, theta):
        return Modification({"EI:2": 1.0 + np.atleast_2d(theta)[:, :1] * np.maximum(-TEMP, 0.0)[None]})


class Step(Knee):
    vocabulary = name = explanation = label = "step"

    def params(self):
        return [ParamSpec("size", -0.3, 0.0, null=0.0)]

    def modify(self, theta):
        return Modification({"EI:2": 1.0 + np.atleast_2d(theta)[:, :1] * AFTER[None]})


TARGET = np.log((1 + TRUTH["slope"] * np.maximum(-TEMP, 0)) * (1 + TRUTH["size"] * AFTER))
NOISY = TARGET + 0.003 * rng.standard_normal(W)


class Sur:
    def delta(self, mod):
        return np.log(mod.groups["EI:2"])[..., None]  # (B, W, 1)


class Lik:
    def gain(self, d, dd=None):
        return -0.5 * np.sum((NOISY[None] - d[..., 0]) ** 2, axis=1) / 0.003 ** 2


def _best_step_given(slope: float) -> float:
    sizes = np.linspace(-0.3, 0.0, 3001)
    g = Lik().gain(Sur().delta(joint_modification([(Knee(), np.array([[slope]])),
                                                   (Step(), sizes[:, None])])))
    return float(sizes[np.argmax(g)])


def test_joint_search_climbs_the_ridge_backfitting_stops_on():
    slope = 0.035  # 75 % too steep, and the step at its best given it
    size = _best_step_given(slope)
    assert size < 1.2 * TRUTH["size"], size  # the premise: the step deeper to make up for the knee
    out = joint_refine([(Knee(), np.array([slope])), (Step(), np.array([size]))], Sur(), Lik(), seed=1)
    assert out is not None
    (s,), (z,) = out
    assert abs(s / TRUTH["slope"] - 1) < 0.1 and abs(z / TRUTH["size"] - 1) < 0.1, (s, z)


def test_nothing_returned_at_the_top():
    out = joint_refine([(Knee(), np.array([TRUTH["slope"]])), (Step(), np.array([TRUTH["size"]]))], Sur(), Lik(),
                       seed=1)
    assert out is None or all(abs(v[0] / TRUTH[k] - 1) < 0.05 for v, k in zip(out, TRUTH, strict=True)), out


def test_a_fit_on_top_combines_the_effects_as_the_joint_search_does():
    sizes = np.array([[-0.02], [-0.05], [-0.1]])
    on_top = OnTop(Step(), [(Knee(), np.array([0.03]))]).modify(sizes)
    joint = joint_modification([(Step(), sizes), (Knee(), np.array([[0.03]]))])
    assert on_top.groups.keys() == joint.groups.keys()
    assert np.array_equal(on_top.groups["EI:2"], joint.groups["EI:2"])
    assert on_top.groups["EI:2"].shape == (3, W)
