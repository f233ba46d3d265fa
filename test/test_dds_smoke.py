"""Two nodes in two processes exchange messages over real DDS on a clean set-up."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

HELPER = Path(__file__).resolve().parent / "ros_helpers" / "talker_listener.py"


def test_talker_and_listener_processes_exchange_every_message():
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert os.environ["ROS_DOMAIN_ID"]
    n = 500
    listener = subprocess.Popen([sys.executable, str(HELPER), "listen", str(n)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    talker = subprocess.Popen([sys.executable, str(HELPER), "talk", str(n)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = listener.communicate(timeout=90)
    talker.communicate(timeout=90)
    assert listener.returncode == 0, err
    assert talker.returncode == 0
    stamps = [int(s) for s in out.split()]
    assert stamps == [1_700_000_000 + k for k in range(n)]


def _start(args: list[str], env: dict[str, str] | None = None) -> subprocess.Popen:
    """A helper process, returned once it says it is ready (subscribed or publishing)."""
    proc = subprocess.Popen([sys.executable, str(HELPER), *args], env=env, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"
    return proc


def test_other_domains_see_nothing():
    """Isolation: two identical watchers join a talker's stream at the same moment; the one on
    this run's domain receives it (so the set-up delivers to a subscriber in exactly the other's
    position) and the one on another domain receives nothing in the same time."""
    # 4 s of stream after the first delivery: longer than the 3 s period at which DDS participants
    # announce themselves, so a subscriber on the talker's domain would have been found by then
    n = 200
    domain = int(os.environ["ROS_DOMAIN_ID"])
    other_domain = (domain + 37) % 200 + 1
    assert other_domain != domain
    talker = _start(["stream"])
    # (started in this order, so the watcher on the talker's domain is not the first to be seen)
    other = subprocess.Popen([sys.executable, str(HELPER), "watch", str(n)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=dict(os.environ, ROS_DOMAIN_ID=str(other_domain)))
    same = _start(["watch", str(n)])
    try:
        assert other.stdout is not None and other.stdout.readline().strip() == "ready"
        # the event that ends the exchange: the watcher on this domain has n messages
        same.wait(timeout=90)  # (not communicate: closing its stdin would end it at once)
        assert same.stdout is not None and same.stderr is not None
        same_out, same_err = same.stdout.read(), same.stderr.read()
        other_out, other_err = other.communicate(input="", timeout=60)  # stdin closed: report
        talker.communicate(input="", timeout=60)
    finally:
        for proc in (same, other, talker):
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert same.returncode == 0 and same_out.strip() == str(n), same_err  # positive control
    assert talker.returncode == 0
    assert other.returncode == 0, other_err
    assert other_out.strip() == "0"
