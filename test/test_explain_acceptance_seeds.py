"""No seed shopping: the seeds recorded in docs/explain.md's acceptance log are the ones the recorded
core tree gives (bench/explain_acceptance.py, test/acceptance_seeds.py), and development runs stay in
the development range."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from acceptance_seeds import DEV_SEEDS, explain_seeds

DOC = Path(__file__).resolve().parents[1] / "docs" / "explain.md"


def log_entries(text: str) -> list[dict]:
    """Each log entry's tree, seed kind and seeds per row."""
    if "## Acceptance log" not in text:
        return []
    log = text.split("## Acceptance log", 1)[1]
    out = []
    for block in re.split(r"\n### ", log)[1:]:
        tree = re.search(r"core tree `([0-9a-f]*)`", block)
        seeds = re.search(r"^- seeds: ([^:]+): (.*)$", block, re.M)
        assert tree and seeds, f"log entry without its tree or seeds: {block[:80]!r}"
        rows = {}
        for part in seeds.group(2).split(";"):
            name, _, values = part.strip().partition(" ")
            rows[name] = [int(x) for x in values.split(",") if x]
        out.append({"tree": tree.group(1), "kind": seeds.group(1), "rows": rows, "head": block.splitlines()[0]})
    return out


def test_recorded_acceptance_seeds_are_the_trees():
    entries = log_entries(DOC.read_text())
    assert entries, "docs/explain.md has no acceptance log entry"
    for e in entries:
        for row, seeds in e["rows"].items():
            if e["kind"].startswith("acceptance"):
                assert seeds == explain_seeds(len(seeds), e["tree"], row), f"{e['head']}: {row}"
            else:
                assert all(0 <= s < DEV_SEEDS for s in seeds), f"{e['head']}: {row}"


def test_seeds_are_disjoint_from_development_and_follow_the_tree():
    a = explain_seeds(30, "4b825dc642cb6eb9a060af63bec9d2f0b7a9fd2e", "nulls")
    b = explain_seeds(30, "4b825dc642cb6eb9a060af63bec9d2f0b7a9fd2f", "nulls")
    assert min(a + b) >= DEV_SEEDS and a != b and len(set(a)) == 30
    assert explain_seeds(30, "4b825dc642cb6eb9a060af63bec9d2f0b7a9fd2e", "nulls") == a


def test_a_shopped_seed_is_caught():
    tree = "4b825dc642cb6eb9a060af63bec9d2f0b7a9fd2e"
    good = explain_seeds(3, tree, "soil")
    text = (f"## Acceptance log\n\n### x\n\n- commit `abc`, core tree `{tree}`\n"
            f"- seeds: acceptance (x): soil {good[0]},{good[1]},{good[2] + 1}\n")
    entry = log_entries(text)[0]
    with pytest.raises(AssertionError):
        assert entry["rows"]["soil"] == explain_seeds(3, entry["tree"], "soil")
