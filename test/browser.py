"""A real headless browser for the report tests: Debian's chromium, its console log checked.

Chromium is installed by the test set-up (`./dev test` as root: `apt-get install -y chromium`); a
missing browser fails the test with that instruction rather than skipping it.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"

# Chromium's own start-up noise on a headless machine without D-Bus, GPU or network: lines at
# ERROR level from these components say nothing about the page and are ignored. Anything else at
# ERROR level, and every console message (the report has no script, so any console line is a
# failed load, a blocked resource or a script error), fails the test.
IGNORED_ERRORS = [
    r":ERROR:dbus/",  # no system/session bus in a container
    r":ERROR:.*Failed to connect to the bus",
    r":ERROR:google_apis/gcm/",  # push-messaging registration (no network)
    r":ERROR:device/bluetooth/",  # no Bluetooth adapter
    r":ERROR:media/gpu/",  # VA-API probing (no GPU)
    r":ERROR:gpu/",  # GPU process with --disable-gpu
    r":ERROR:ui/gl/",  # GL bindings with --disable-gpu
    r":ERROR:components/viz/",  # compositor falling back to software
    r":ERROR:sandbox/",  # --no-sandbox as root
]
PAGE_PROBLEMS = [r":CONSOLE", r"net::ERR_", r"report\.html"]


def chromium_or_fail() -> str:
    if not Path(CHROMIUM).exists():
        pytest.fail("chromium is needed to test the report in a browser: install it with "
                    "`apt-get install -y chromium` (Debian's package; CI installs it as root)")
    return CHROMIUM


def run_chromium(page: Path, tmp: Path, *extra: str) -> subprocess.CompletedProcess:
    args = [chromium_or_fail(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
            "--no-first-run", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", f"--user-data-dir={tmp / 'chromium-profile'}", "--enable-logging=stderr",
            "--v=0", *extra, page.resolve().as_uri()]
    return subprocess.run(args, capture_output=True, text=True, timeout=180, cwd=tmp)


def page_errors(stderr: str) -> list[str]:
    bad = []
    for line in stderr.splitlines():
        if any(re.search(p, line) for p in PAGE_PROBLEMS):
            bad.append(line)
        elif ":ERROR:" in line and not any(re.search(p, line) for p in IGNORED_ERRORS):
            bad.append(line)
    return bad


class Images(HTMLParser):
    """The ids, image sources and external references of a rendered page."""

    def __init__(self) -> None:
        super().__init__()
        self.srcs: list[str] = []
        self.ids: list[str] = []
        self.external: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "img":
            self.srcs.append(a.get("src") or "")
        if a.get("id"):
            self.ids.append(str(a["id"]))
        for key in ("src", "href"):
            v = a.get(key) or ""
            if tag in ("script", "link", "iframe", "img") and v and not v.startswith("data:"):
                self.external.append(f"<{tag} {key}={v[:80]}>")


def artefact_dir() -> Path:
    d = Path(os.environ.get("SHM_TEST_ARTIFACTS") or ROOT / "out" / "test-artifacts")
    d.mkdir(parents=True, exist_ok=True)
    return d


