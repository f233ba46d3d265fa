"""The two-A check on stable candidates picks what the all-orders check picks.

``same_picks`` compares two lists of picked modes: same count, frequencies within 0.1 %, MAC of
the complex shapes >= 0.999. ``ScopeCheck`` wraps ``shm_ros.core.identify.diagram_picks`` so that
every identification of a test (every window the identify tests identify) that runs the default
``two_a_scope: columns`` (or ``stable``) is redone with ``all`` on the same subspace model and
compared (picks, every column's verdict, each checked candidate's verdict); conftest.py
installs it for the ``test_identify_*`` modules.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from shm_ros.core import identify
from shm_ros.core.modal import mac_matrix
from shm_ros.core.stabilization import PickedMode, TwoAScope

FREQ_TOL = 0.001
MAC_MIN = 0.999


def same_picks(a: list[PickedMode], b: list[PickedMode]) -> list[str]:
    """What differs between two pick lists (empty: the same modes)."""
    if len(a) != len(b):
        return [f"{len(a)} modes ({[round(p.frequency_hz, 4) for p in a]} Hz) against {len(b)} "
                f"({[round(p.frequency_hz, 4) for p in b]} Hz)"]
    out = []
    for p, q in zip(a, b, strict=True):
        rel = abs(p.frequency_hz / q.frequency_hz - 1)
        mac = float(mac_matrix(p.mode_shape_complex[None], q.mode_shape_complex[None])[0, 0])
        if rel > FREQ_TOL or not mac >= MAC_MIN:
            out.append(f"{p.frequency_hz:.4f} Hz against {q.frequency_hz:.4f} Hz "
                       f"({100 * rel:.3f} %), MAC {mac:.5f}")
    return out


@dataclass
class ScopeCheck:
    """Counts the identifications compared and keeps every difference found."""

    compared: int = 0
    poles: int = 0
    checked: int = 0  # candidates whose two-A verdict the ``columns`` scope computed
    candidates: int = 0  # of these candidates
    cpu_s: float = 0.0  # CPU seconds of the comparisons (the all-orders diagrams redone)
    differences: list[str] = field(default_factory=list)

    def wrap(self, original):
        def diagram_picks(model, orders, cfg, duration_s):
            out = original(model, orders, cfg, duration_s)
            st = cfg.stability
            if st.two_a and st.two_a_scope != TwoAScope.ALL:
                every = replace(cfg, stability=replace(st, two_a_scope=TwoAScope.ALL.value))
                c0 = time.process_time()
                ref = original(model, orders, every, duration_s)
                self.cpu_s += time.process_time() - c0
                self.compared += 1
                self.poles += len(out[0])
                self.differences += [f"{model.method}, {model.block_rows} block rows: {d}"
                                     for d in same_picks(out[2], ref[2])]
                # the poles that entered picking carry the same two-A verdict (under ``columns``
                # those checked: each column's until its verdict was settled)
                cand = out[1].stable & out[1].physical_ok
                if out[1].two_a_checked is not None:
                    cand &= out[1].two_a_checked
                    self.checked += int(cand.sum())
                    self.candidates += int(np.count_nonzero(out[1].stable & out[1].physical_ok))
                if not np.array_equal(out[1].two_a_ok[cand], ref[1].two_a_ok[cand]):
                    self.differences.append(f"{model.method}: a candidate's two-A verdict differs")
                # every column judged carries the same verdict
                verdicts = [(round(c["frequency_hz"], 6), c["check"]) for c in out[3].columns]
                if verdicts != [(round(c["frequency_hz"], 6), c["check"]) for c in ref[3].columns] \
                        or out[3].removed != ref[3].removed:
                    self.differences.append(f"{model.method}: a column's verdict differs")
            return out

        return diagram_picks


TOTAL = ScopeCheck()  # over the test session (printed at its end by conftest.py)


def install(monkeypatch) -> ScopeCheck:
    check = ScopeCheck()
    monkeypatch.setattr(identify, "diagram_picks", check.wrap(identify.diagram_picks))
    return check


def add_to_total(check: ScopeCheck) -> None:
    TOTAL.compared += check.compared
    TOTAL.poles += check.poles
    TOTAL.cpu_s += check.cpu_s
    TOTAL.checked += check.checked
    TOTAL.candidates += check.candidates
    TOTAL.differences += check.differences
