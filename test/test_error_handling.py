"""One way errors travel: the command line prints a ShmError as one line (its exit code) and lets
every other exception show its traceback; nothing in the package swallows exceptions broadly
(``except Exception``, ``except BaseException`` or a bare ``except``) except the guards listed here -
the nodes' callbacks, where one bad message must not take a node down, and a third-party reader
that raises plain ``Exception``. A handler that cleans up and re-raises is not swallowing."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BROAD = {"Exception", "BaseException"}

# (file, enclosing function) -> why the broad handler is right there
ALLOWED = {
    ("shm_ros/ros/identify_node.py", "IdentifyNode._on_window"): "node callback guard: one bad window",
    ("shm_ros/ros/ingest_node.py", "IngestNode._guard.handle"): "node callback guard: one bad message",
    ("shm_ros/ros/ingest_node.py", "IngestNode._feed_imu"): "node callback guard: one bad Imu batch",
    ("shm_ros/ros/explain_node.py", "ExplainNode._finish"): "node callback guard: a failed run or lost worker",
    ("shm_ros/ros/update_node.py", "UpdateNode._poll"): "node callback guard: a failed update",
    ("shm_ros/ros/update_node.py", "UpdateNode._collect_events"): "node callback guard: a failed "
                                                                  "time-domain step",
    ("shm_ros/ros/track_node.py", "TrackNode._on_estimate"): "node callback guard: one bad estimate",
    ("shm_ros/ros/predict_node.py", "PredictNode._poll"): "node callback guard: a failed prediction",
    ("shm_ros/ros/roving_node.py", "RovingNode._execute"): "action guard: a failed estimate ends the goal",
    ("shm_ros/io/importers.py", "read_miniseed"): "ObsPy raises plain Exception for unreadable records",
    ("shm_ros/io/opensees.py", "_parameter_term"): "OpenSeesPy raises its own untyped error for an unknown tag",
    ("shm_ros/ros/managed.py", "ManagedNode.on_configure"): "lifecycle guard: a failed configure is a failed "
                                                            "transition with the reason, not a dead node",
}


def _qualname(stack: list[ast.AST]) -> str:
    return ".".join(n.name for n in stack if isinstance(n, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)))


def _broad(handler: ast.ExceptHandler) -> bool:
    t = handler.type
    names = t.elts if isinstance(t, ast.Tuple) else [t] if t is not None else []
    return t is None or any(isinstance(n, ast.Name) and n.id in BROAD for n in names)


def broad_handlers(path: Path) -> list[tuple[str, int]]:
    """``(enclosing function, line)`` of every broad handler that does not end by re-raising."""
    found: list[tuple[str, int]] = []

    def visit(node: ast.AST, stack: list[ast.AST]) -> None:
        if isinstance(node, ast.ExceptHandler) and _broad(node):
            last = node.body[-1]
            reraises = isinstance(last, ast.Raise) and last.exc is None
            if not reraises:
                found.append((_qualname(stack), node.lineno))
        for child in ast.iter_child_nodes(node):
            visit(child, [*stack, node] if isinstance(node, (ast.ClassDef, ast.FunctionDef,
                                                             ast.AsyncFunctionDef)) else stack)

    visit(ast.parse(path.read_text(), str(path)), [])
    return found


def test_no_broad_exception_handler_outside_the_guards():
    offenders, used = [], set()
    for path in sorted((ROOT / "shm_ros").rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        for where, line in broad_handlers(path):
            key = (rel, where.split(".<")[0])
            if key in ALLOWED or (rel, where) in ALLOWED:
                used.add(key if key in ALLOWED else (rel, where))
                continue
            offenders.append(f"{rel}:{line} in {where or 'module'}")
    assert not offenders, "broad exception handlers outside the allow-list:\n" + "\n".join(offenders)
    stale = set(ALLOWED) - used
    assert not stale, f"allow-list entries that no longer match a handler: {sorted(stale)}"
    print(f"{len(used)} allowed guards; no other broad handler in shm_ros/")


def test_the_checker_finds_what_it_should(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("def f():\n    try:\n        g()\n    except Exception:\n        pass\n"
                 "def h():\n    try:\n        g()\n    except:\n        return 1\n"
                 "def k():\n    try:\n        g()\n    except (ValueError, BaseException) as e:\n        log(e)\n"
                 "def ok():\n    try:\n        g()\n    except BaseException:\n        undo()\n        raise\n"
                 "def narrow():\n    try:\n        g()\n    except ValueError:\n        pass\n")
    assert broad_handlers(p) == [("f", 4), ("h", 9), ("k", 14)]


def _cli(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)


def test_an_unexpected_exception_shows_its_traceback():
    """A bug inside a command (here an injected RuntimeError) is not turned into a one-line message:
    the traceback is printed and the exit code is not 0."""
    out = _cli("import sys\nimport shm_ros.commands.report as r\n"
               "def boom(args):\n    raise RuntimeError('injected bug')\n"
               "r.run = boom\nfrom shm_ros.cli import main\nsys.exit(main(['report', '--out', '/tmp/x-never']))")
    assert out.returncode == 1, out.stderr
    assert "Traceback (most recent call last)" in out.stderr and "RuntimeError: injected bug" in out.stderr


def test_a_project_error_is_one_line_with_its_exit_code():
    out = _cli("import sys\nimport shm_ros.commands.report as r\nfrom shm_ros.errors import NoWindowsError\n"
               "def none(args):\n    raise NoWindowsError('x.bag: no window found')\n"
               "r.run = none\nfrom shm_ros.cli import main\nsys.exit(main(['report', '--out', '/tmp/x-never']))")
    assert out.returncode == 3
    assert out.stderr == "shm-ros report: error: x.bag: no window found\n"
