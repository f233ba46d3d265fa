"""When a node that reruns its analysis as windows arrive (update, explain) runs again.

The first run comes at ``first`` windows; the next each time the count of windows received
crosses the next of ``first + k * every`` (k = 1, 2, ...), on every window received by then.
Counted from the window counts, not from the size of the last run: a run that took long (windows
piled up meanwhile) or a restarted node that takes up its inputs' history in one burst still runs
when the count reaches the next step, so the last run of a replay covers every window whatever
happened on the way (counting ``every`` new windows from the last run would leave the ones after
it out until ``every`` more arrive).
"""

from __future__ import annotations


def _step(n: int, first: int, every: int) -> int:
    return (n - first) // max(every, 1) if n >= first else -1


def run_due(received: int, used: int, first: int, every: int) -> bool:
    """Whether a run is due with ``received`` windows when the last run had ``used`` (0: none yet)."""
    if received < max(first, 1) or received == used:
        return False
    return used == 0 or _step(received, first, every) > _step(used, first, every)


def next_run_at(used: int, first: int, every: int) -> int:
    """The window count at which the next run comes when the last run had ``used`` (0: none yet)."""
    if used == 0:
        return max(first, 1)
    return first + (_step(used, first, every) + 1) * max(every, 1)
