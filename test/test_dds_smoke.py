"""Issue 2: two nodes in two processes exchange messages over real DDS on a clean set-up."""

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


def _watch(n: int, env: dict[str, str]) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, str(HELPER), "watch", str(n)], env=env, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"  # subscribed before anything is published
    return proc


def test_other_domains_see_nothing():
    """Isolation: of two identical watchers, the one on this run's domain receives the talker's
    messages (so the set-up can deliver them) and the one on another domain receives none, though
    it was subscribed for the whole exchange."""
    n = 5
    domain = int(os.environ["ROS_DOMAIN_ID"])
    other_domain = (domain + 37) % 200 + 1
    assert other_domain != domain
    other = _watch(n, dict(os.environ, ROS_DOMAIN_ID=str(other_domain)))
    same = _watch(n, dict(os.environ))
    talker = subprocess.Popen([sys.executable, str(HELPER), "talk", str(n)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    try:
        # the event that ends the exchange: the watcher on this domain has every message
        same.wait(timeout=90)  # (not communicate: closing its stdin would end it at once)
        assert same.stdout is not None and same.stderr is not None
        same_out, same_err = same.stdout.read(), same.stderr.read()
        talker.communicate(timeout=90)
        other_out, other_err = other.communicate(input="", timeout=60)  # stdin closed: report
    finally:
        for proc in (same, other, talker):
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert same.returncode == 0 and same_out.strip() == str(n), same_err  # positive control
    assert talker.returncode == 0
    assert other.returncode == 0, other_err
    assert other_out.strip() == "0"
