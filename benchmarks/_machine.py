"""Machine and version facts printed into every benchmark report (shared by the scripts here)."""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (else what ``platform`` knows)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def git_commit() -> str:
    """Short commit of this checkout, ``-dirty`` when its code differs (:mod:`laav._provenance`)."""
    from laav._provenance import commit_of

    return commit_of(REPO)


def laav_version() -> str:
    import laav

    return laav.__version__


def write_json_report(path: str | Path, title: str, what: str, result: dict) -> Path:
    """Print ``result`` as one JSON line on stdout and write it to a short Markdown report
    (date, machine, software, the result as JSON) at ``path``."""
    import json

    print(json.dumps(result), flush=True)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [
        f"# {title} ({time.strftime('%Y-%m-%d %H:%M %Z')})",
        "",
        f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores, "
        f"{platform.system()} {platform.release()} {platform.machine()}",
        f"- Software: Python {platform.python_version()}, laav {laav_version()} (git {git_commit()})",
        f"- Measured: {what}",
        "",
        "```json",
        json.dumps(result, indent=1),
        "```",
        "",
    ]
    path.write_text("\n".join(lines))
    return path
