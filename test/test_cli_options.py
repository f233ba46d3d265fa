"""Every command's options, table-driven: each of 0, -1, inf, nan and text that an option's
documented type or range excludes, and for every path option a missing path, a directory where a
file is expected and the reverse, an unwritable place and a non-empty output folder, is refused with
one line on stderr, exit code 2 and no file created; the values an option's range includes are
accepted, and a few complete runs at the edges of the ranges succeed.

The table is built from the parsers themselves, so a new option is covered or the test says that
its type is not in the table of documented ranges below.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
from pathlib import Path

import pytest

from shm_ros.cli import build_parser, main
from shm_ros.commands import checks

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
VALUES = {"0": 0, "-1": -1, "inf": math.inf, "nan": math.nan, "text": "abc"}

# documented range of each option type: which of VALUES it includes
RANGES: dict[object, set[str]] = {
    checks.finite_float: {"0", "-1"},
    checks.positive_float: set(),
    checks.nonneg_float: {"0"},
    checks.positive_int: set(),
    checks.nonneg_int: {"0"},
    int: {"0", "-1"},
}

# path options: (command, option) -> kind; "-" means the positional argument
INPUT_FILE = "input file"
INPUT_PATH = "input file or folder"
OUT_DIR = "output folder"
OUT_FILE = "output file"
OUT_NEW = "output created whole"
PATHS: dict[str, dict[str, str]] = {
    "ingest": {"bag": INPUT_PATH, "--structure": INPUT_FILE, "--out": OUT_DIR},
    "identify": {"bag": INPUT_PATH, "--structure": INPUT_FILE, "--config": INPUT_FILE, "--out": OUT_FILE,
                 "--plots": OUT_DIR},
    "event": {"bag": INPUT_PATH, "--structure": INPUT_FILE, "--out": OUT_FILE, "--plots": OUT_DIR},
    "track": {"modes": INPUT_FILE, "--structure": INPUT_FILE, "--out": OUT_DIR},
    "update": {"--structure": INPUT_FILE, "--modes": INPUT_FILE, "--out": OUT_DIR},
    "predict": {"--structure": INPUT_FILE, "--posterior": INPUT_PATH, "--bag": INPUT_PATH, "--out": OUT_DIR},
    "explain": {"--structure": INPUT_FILE, "--modes": INPUT_FILE, "--out": OUT_DIR},
    "report": {"--modes": INPUT_PATH, "--out": OUT_DIR},
    "import": {"files": INPUT_FILE, "--out": OUT_NEW},
    "simulate": {"--scenario-file": INPUT_FILE, "--out": OUT_DIR},
    "batch": {"archive": INPUT_PATH, "--structure": INPUT_FILE, "--config": INPUT_FILE, "--out": OUT_DIR},
    "example": {"--config": INPUT_FILE, "--out": OUT_DIR},
    "replay": {"bag": INPUT_PATH},
    "run": {"config": INPUT_FILE},
}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("inputs")
    shutil.copy(EXAMPLES / "recording" / "structure.yaml", d / "structure.yaml")
    shutil.copy(EXAMPLES / "modes.json", d / "modes.json")
    shutil.copy(EXAMPLES / "tracked_modes.csv", d / "modes.csv")
    shutil.copy(EXAMPLES / "posterior.json", d / "posterior.json")
    shutil.copy(EXAMPLES / "simulate_scenario.yaml", d / "scenario.yaml")
    shutil.copy(EXAMPLES.parent / "shm_ros" / "examples_data" / "main_job.yaml", d / "main_job.yaml")
    shutil.copy(ROOT / "config" / "pipeline.yaml", d / "pipeline.yaml")
    (d / "cfg.yaml").write_text("{}\n")
    (d / "a.csv").write_text("s1,s2\n" + "0.1,0.2\n" * 300)
    shutil.copytree(EXAMPLES / "recording" / "bag", d / "bag")
    for p in d.rglob("*"):
        p.chmod(0o444 if p.is_file() else 0o555)
    d.chmod(0o555)
    return {"structure": d / "structure.yaml", "modes.json": d / "modes.json", "modes.csv": d / "modes.csv",
            "posterior": d / "posterior.json", "scenario": d / "scenario.yaml", "job": d / "main_job.yaml",
            "pipeline": d / "pipeline.yaml", "cfg": d / "cfg.yaml", "csv": d / "a.csv", "bag": d / "bag"}


def base_args(command: str, i: dict[str, Path], out: Path) -> dict[str, list[str]]:
    """Valid arguments of each command: option (or positional name) -> its values, in order."""
    s = str(i["structure"])
    table: dict[str, dict[str, list[str]]] = {
        "ingest": {"bag": [str(i["bag"])], "--structure": [s], "--out": [str(out / "o")]},
        "identify": {"bag": [str(i["bag"])], "--structure": [s], "--out": [str(out / "m.json")]},
        "event": {"bag": [str(i["bag"])], "--structure": [s], "--out": [str(out / "e.json")]},
        "track": {"modes": [str(i["modes.json"])], "--out": [str(out / "o")]},
        "update": {"--structure": [s], "--modes": [str(i["modes.csv"])], "--out": [str(out / "o")]},
        "predict": {"--structure": [s], "--bag": [str(i["bag"])], "--out": [str(out / "o")]},
        "explain": {"--structure": [s], "--modes": [str(i["modes.csv"])], "--out": [str(out / "o")]},
        "report": {"--out": [str(out / "o")]},
        "import": {"files": [str(i["csv"])], "--rate": ["100"], "--out": [str(out / "bag")]},
        "simulate": {"--out": [str(out / "o")]},
        "batch": {"archive": [str(i["bag"])], "--out": [str(out / "o")]},
        "example": {"--config": [str(i["job"])], "--out": [str(out / "o")]},
        "replay": {"bag": [str(i["bag"])]},
        "run": {"config": [str(i["pipeline"])]},
        "lifecycle": {"action": ["state"], "nodes": ["ingest"]},
    }
    return table[command]


def argv(command: str, args: dict[str, list[str]]) -> list[str]:
    out = [command]
    for k, v in args.items():
        out += v if not k.startswith("-") else [k, *v]
    return out


def subparsers() -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def numeric_options() -> list[tuple[str, str, object]]:
    out = []
    for name, p in subparsers().items():
        for a in p._actions:
            text_list = getattr(a.type, "__name__", "") == "_comma_list"  # names, not numbers
            if a.option_strings and a.type not in (None, str) and not text_list and a.choices is None:
                out.append((name, a.option_strings[0], a.type))
    return out


NUMERIC = numeric_options()


def _range(kind: object) -> set[str]:
    if kind in RANGES:
        return RANGES[kind]
    name = getattr(kind, "__name__", "")
    if name.startswith("number>="):  # checks.min_float(low): every low used is >= 1
        assert float(name.split(">=")[1]) >= 1
        return set()
    return {"undocumented"}


def test_every_numeric_option_has_a_documented_range():
    assert len(NUMERIC) > 100
    undocumented = [(c, o, getattr(t, "__name__", t)) for c, o, t in NUMERIC if "undocumented" in _range(t)]
    assert not undocumented, f"option types without a documented range (plain float accepts nan/inf): {undocumented}"


def _tree(p: Path) -> set[str]:
    return {str(x.relative_to(p)) for x in p.rglob("*")}


def _refused(argv_: list[str], tmp: Path, capsys) -> str:
    before = _tree(tmp)
    rc = main(argv_)
    err = capsys.readouterr().err
    assert rc == 2, (argv_, rc, err)
    assert err.count("\n") == 1 and err.startswith("shm-ros") and "Traceback" not in err, (argv_, err)
    assert _tree(tmp) == before, (argv_, _tree(tmp) - before)
    return err


def _main_refusing(argv_: list[str]) -> tuple[int, str]:
    """``main`` when argparse refuses (SystemExit) or the command returns an exit code."""
    try:
        return main(argv_), ""
    except SystemExit as exc:
        return int(exc.code or 0), ""


def test_numeric_values_outside_the_range_are_refused_and_inside_accepted(inputs, tmp_path, capsys):
    n_refused = n_accepted = 0
    parsers = subparsers()
    for command, option, kind in NUMERIC:
        valid = _range(kind)
        base = base_args(command, inputs, tmp_path)
        for label, value in VALUES.items():
            args = dict(base) | {option: [str(value) if label != "text" else "abc"]}
            if label in valid:
                ns = parsers[command].parse_args(argv(command, args)[1:])
                got = getattr(ns, parsers[command]._option_string_actions[option].dest)
                assert got == value, (command, option, label, got)
                n_accepted += 1
                continue
            before = _tree(tmp_path)
            with pytest.raises(SystemExit) as exit_:
                main(argv(command, args))
            err = capsys.readouterr().err
            assert exit_.value.code == 2, (command, option, label)
            assert err.count("\n") == 1 and option in err and "Traceback" not in err, (command, option, err)
            assert _tree(tmp_path) == before
            n_refused += 1
    print(f"{len(NUMERIC)} numeric options: {n_refused} values refused, {n_accepted} accepted")
    assert n_refused > 400


def _path_cases(kind: str, tmp: Path, inputs: dict[str, Path]) -> dict[str, str]:
    a_file, a_dir = str(inputs["cfg"]), str(inputs["bag"])
    unwritable = "/proc/1/shm-ros-out"
    full = tmp / "full"
    if kind == INPUT_FILE:
        return {"missing": str(tmp / "nope.yaml"), "a directory": a_dir}
    if kind == INPUT_PATH:
        return {"missing": str(tmp / "nope")}
    cases = {"unwritable": unwritable, "under a file": f"{a_file}/x", "non-empty": str(full)}
    if kind in (OUT_DIR,):
        cases["a file"] = a_file
    if kind == OUT_FILE:
        cases["a directory"] = str(tmp)
        cases.pop("non-empty")
        cases["existing"] = str(full / "f.json")
    if kind == OUT_NEW:
        cases.pop("non-empty")
        cases["existing"] = str(full)
    return cases


def test_path_options_refuse_missing_wrong_kind_unwritable_and_non_empty(inputs, tmp_path, capsys):
    work = tmp_path / "work"
    work.mkdir()
    (work / "full").mkdir()
    (work / "full" / "f.json").write_text("{}")
    n = 0
    for command, options in PATHS.items():
        for option, kind in options.items():
            for label, value in _path_cases(kind, work, inputs).items():
                args = dict(base_args(command, inputs, work)) | {option: [value]}
                err = _refused(argv(command, args), work, capsys)
                assert value in err, (command, option, label, err)  # the message names the path given
                assert ("--overwrite" in err) == (label in ("non-empty", "existing")), (command, option, err)
                n += 1
    print(f"{n} path cases refused")
    assert n > 80


def test_valid_runs_at_the_edges_of_the_ranges(inputs, tmp_path, capsys):
    """Runs that must succeed: an import, ingest at the shortest window, a rerun into a non-empty
    folder with --overwrite (stale files of a sub-folder replaced), identify and track."""
    bag = tmp_path / "bag"
    assert main(["import", str(inputs["csv"]), "--rate", "100", "--start", "0", "--out", str(bag)]) == 0
    assert main(["import", str(inputs["csv"]), "--rate", "50", "--out", str(bag), "--overwrite"]) == 0
    out = tmp_path / "w"
    rc = main(["ingest", str(inputs["bag"]), "--structure", str(inputs["structure"]), "--out", str(out),
               "--window", "60", "--quiet"])
    assert rc == 0, capsys.readouterr().err
    first = sorted(p.name for p in (out / "windows").iterdir())
    (out / "windows" / "stale.npz").write_text("old")
    rc = main(["ingest", str(inputs["bag"]), "--structure", str(inputs["structure"]), "--out", str(out),
               "--window", "120", "--overwrite", "--quiet"])
    assert rc == 0
    second = sorted(p.name for p in (out / "windows").iterdir())
    assert "stale.npz" not in second and len(second) < len(first)
    assert not [p for p in tmp_path.iterdir() if ".partial-" in p.name]
    assert main(["identify", str(inputs["bag"]), "--structure", str(inputs["structure"]), "--window", "120",
                 "--out", str(tmp_path / "m.json")]) == 0
    assert main(["track", str(tmp_path / "m.json"), "--out", str(tmp_path / "t"), "--no-plot",
                 "--reference-windows", "3"]) == 0


def test_nothing_matched_exits_3_with_one_line(inputs, tmp_path, capsys):
    other = tmp_path / "other.yaml"
    text = Path(inputs["structure"]).read_text()
    import re

    other.write_text(re.sub(r"\bs(\d+)\b", r"zz\1", text))  # sensors the recording does not have
    capsys.readouterr()
    for command in ("ingest", "identify"):
        out = tmp_path / ("o" if command == "ingest" else "m.json")
        rc = main([command, str(inputs["bag"]), "--structure", str(other), "--out", str(out), "--quiet"]
                  if command == "ingest" else [command, str(inputs["bag"]), "--structure", str(other),
                                               "--out", str(out)])
        err = capsys.readouterr().err
        last = err.strip().splitlines()[-1]
        assert rc == 3 and "no window" in last and last.startswith(f"shm-ros {command}: error:"), err


def test_quiet_keeps_errors(inputs, tmp_path, capsys):
    assert os.environ.get("SHM_FULL") in (None, "", "0", "1")
    other = tmp_path / "other.yaml"
    import re

    other.write_text(re.sub(r"\bs(\d+)\b", r"zz\1", Path(inputs["structure"]).read_text()))
    main(["ingest", str(inputs["bag"]), "--structure", str(other), "--out", str(tmp_path / "o"), "--quiet",
          "--window", "600"])
    captured = capsys.readouterr()
    assert "zz1" in captured.err  # the misspelt sensor is named even with --quiet


def test_report_markdown_escapes_input_text(tmp_path, capsys):
    """Text from the inputs (here the title) cannot put HTML or links into report.md."""
    title = "<svg onload=alert(1)> [x](javascript:alert(1)) | a"
    assert main(["report", "--out", str(tmp_path / "r"), "--title", title]) == 0
    md = (tmp_path / "r" / "report.md").read_text()
    import re

    assert "<svg" not in md and "&lt;svg onload=alert(1)&gt;" in md
    assert not re.search(r"(?<!\\)\]\(javascript", md) and "\\[x\\](javascript" in md  # no link
    html = (tmp_path / "r" / "report.html").read_text()
    assert "<svg onload" not in html
