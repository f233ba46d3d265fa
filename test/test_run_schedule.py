"""The update and explain nodes run again at fixed window counts (``min_windows``, then every
``min_new_windows``), so that their last run covers every window whatever happened on the way: a
slow run while windows piled up, or a restart after which the node took up its inputs' history in
one burst. (Counting ``min_new_windows`` from the size of the last run left the windows after a
late run out of the last one: a restarted update ended a replay on 25 of 30 windows.)"""

from __future__ import annotations

from shm_ros.ros.run_schedule import next_run_at, run_due

FIRST, EVERY, N = 10, 10, 30


def _runs(arrivals: list[int], busy: int, used: int = 0) -> list[int]:
    """The run sizes of a node fed windows in ``arrivals`` (how many arrive at each tick), one run
    at a time, each lasting ``busy`` ticks (the node's timer collects a finished run and starts the
    next, as in update_node._poll; a window's callback starts one when the node is idle)."""
    runs, n, free_at = [], 0, 0
    for tick, count in enumerate([*arrivals, *[0] * (busy * 4 + 4)]):
        for _ in range(count):
            n += 1
            if tick >= free_at and run_due(n, used, FIRST, EVERY):
                used, free_at = n, tick + busy
                runs.append(n)
        if tick >= free_at and run_due(n, used, FIRST, EVERY):  # a run finished: the next at once
            used, free_at = n, tick + busy
            runs.append(n)
    return runs


def test_the_last_run_covers_every_window_however_the_windows_came():
    assert _runs([1] * N, busy=0) == [10, 20, 30]
    # a run that takes 13 windows' time: windows pile up; the last run still has all 30
    slow = _runs([1] * N, busy=13)
    assert slow[-1] == N and slow[0] == FIRST, slow
    # restarted after 25 windows: they come back in one burst, then the rest one by one
    restarted = _runs([25] + [1] * (N - 25), busy=2)
    assert restarted[0] == FIRST and restarted[-1] == N, restarted
    assert _runs([25] + [1] * (N - 25), busy=0) == [10, 20, 30]  # instant runs: the same counts


def test_the_schedule_steps():
    assert not run_due(9, 0, FIRST, EVERY) and run_due(10, 0, FIRST, EVERY) and run_due(14, 0, FIRST, EVERY)
    assert not run_due(19, 10, FIRST, EVERY) and run_due(20, 10, FIRST, EVERY)
    assert not run_due(29, 23, FIRST, EVERY) and run_due(30, 23, FIRST, EVERY)  # not 33
    assert not run_due(30, 30, FIRST, EVERY)
    assert run_due(11, 10, FIRST, 1) and run_due(4, 0, 4, 4) and not run_due(7, 4, 4, 4)
    assert [next_run_at(u, FIRST, EVERY) for u in (0, 10, 15, 20, 23)] == [10, 20, 20, 30, 30]
