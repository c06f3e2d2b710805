"""The page's work after a result arrives, with and without the glyph data of plots off
screen kept for when they are seen (``explorer/cards/onscreen.py``), A/B in one page.

Starts the real command (``python -m explorer.cli [FILE] --no-browser``), loads it in Debian's
Chromium at 1280x800 and moves one slider (``--control``, default R1) between two values,
``--pairs`` times with the deferral off (``window.__laavNoDefer = true``, the page computing
every changed renderer's data at once, as before) and on, alternating which comes first. Each
move is timed as ``benchmarks/explorer_browser_latency.py`` times it (release to the status
line naming the value, then two animation frames), and split at the arrival of the document
patch that carries the result: what comes after it is the page's own work. One page, one
server, interleaved: the machine's drift between two processes (tens of ms on the 2-core VM)
does not enter the difference. Prints ONE JSON line and writes it, with date, machine and
commit, to ``--out`` (default ``bench-out/explorer_offscreen_ab.md``). Usage::

    python benchmarks/explorer_offscreen_ab.py [--control R1] [--pairs 10] [FILE]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import explorer_browser_latency as B  # noqa: E402
from _machine import REPO, write_json_report  # noqa: E402

#: control name -> (slider title prefix, two values, status marker)
CONTROLS = {
    "R1": ("R1", (22.0, 18.0), lambda v: f"R1 = {v:g}"),
    "R2": ("R2", (44.0, 36.0), lambda v: f"R2 = {v:g}"),
    "lambda": ("λ", (3.0, 2.5), lambda v: f"λ = {v:g}"),
}


def measure(file: str | None, control: str, pairs: int, settle: float) -> dict:
    from playwright import sync_api

    prefix, values, marker = CONTROLS[control]
    port = B._free_port("127.0.0.1")
    cmd = [sys.executable, "-m", "explorer.cli", *([file] if file else []), "--no-browser",
           "--port", str(port)]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out: dict[bool, list] = {False: [], True: []}
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(B.CHROMIUM), headless=True, args=B.ARGS)
        proc = subprocess.Popen(cmd, cwd=str(REPO), env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        try:
            B.wait_listening(port, proc, time.monotonic() + 120)
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.add_init_script(B.JS_RECORD_PATCHES)
            page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded", timeout=120000)
            page.wait_for_function("() => (" + B.JS_STATE + ")().status.length > 0", timeout=120000,
                                   polling=20)
            page.wait_for_timeout(3000)
            for k in range(pairs):
                for off in ((True, False) if k % 2 == 0 else (False, True)):
                    page.evaluate(f"() => {{ window.__laavNoDefer = {str(off).lower()}; }}")
                    for v in values:
                        r = page.evaluate(B.JS_MOVE, [prefix, v, "status", marker(v), None])
                        if not isinstance(r, list) or r[2] < 0:
                            raise RuntimeError(f"{control} = {v}: no result on screen ({r!r})")
                        out[off].append((r[0], r[0] - r[2]))
                        page.wait_for_timeout(int(settle * 1000))
            if errors:  # a figure that failed to draw would time nothing worth comparing
                raise RuntimeError(f"errors in the page: {errors[:3]}")
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
            browser.close()

    def med(xs):
        return round(statistics.median(xs), 1)

    res = {"file": file or "bundled demo", "control": control, "moves_each": len(out[False])}
    for off, name in ((True, "at_once"), (False, "deferred")):
        res[f"{name}_ms_median"] = med(t for t, _ in out[off])
        res[f"{name}_after_patch_ms_median"] = med(a for _, a in out[off])
        res[f"{name}_after_patch_ms"] = [round(a, 1) for _, a in out[off]]
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("file", nargs="?", default=None)
    ap.add_argument("--control", choices=sorted(CONTROLS), default="R1")
    ap.add_argument("--pairs", type=int, default=10, help="A/B pairs (each: two moves a side)")
    ap.add_argument("--settle", type=float, default=0.4, help="seconds after each redraw")
    ap.add_argument("--out", default="bench-out/explorer_offscreen_ab.md")
    args = ap.parse_args()
    res = measure(args.file, args.control, args.pairs, args.settle)
    write_json_report(args.out, "Glyph data of plots off screen: computed at once or when seen",
                      f"{res['file']}, {args.control} moves, {args.pairs} interleaved pairs in one page, "
                      "headless Chromium 1280x800", res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
