"""Time from the ``laav-explore`` command to a usable page in headless Chromium.

Issue 5's target: the page is ready within 5 s of the command. Each repeat starts the real
command (``python -m explorer.cli [FILE] --no-browser --port N``) as a fresh process, polls
the port, and loads the page in Debian's Chromium (``/usr/bin/chromium``, via Playwright)
as soon as something listens. Times, from the moment the process is started:

- ``listen_s``: the port accepts connections;
- ``html_s``: the page's HTML has arrived (bokeh document built for the session);
- ``ready_s``: the page is drawn and usable: bokeh has rendered the document and the
  parameter sliders are on screen (the page-ready time of the target);
- ``result_s``: the first segmentation is drawn (the frame view shows the points).

Prints ONE JSON line with the medians (and every repeat) and exits 0. Chromium is launched
once, before the first repeat, so its own start-up is not counted (a user's browser is
already running). Usage::

    python benchmarks/explorer_startup.py [--repeats 5] [--out REPORT.md] [FILE]

It also writes them, with date and machine, to ``--out`` (default
``docs/bench/explorer_startup.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _machine import write_json_report  # this folder, on sys.path

from explorer.cli import _free_port  # the CLI's own free-port helper

REPO = Path(__file__).resolve().parents[1]
CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"]

JS_READY = """() => {
  if (!(window.Bokeh && Bokeh.documents.length > 0)) return false;
  // panel renders widgets inside shadow roots: look for a drawn noUi slider handle
  const seen = (root) => {
    if (root.querySelector && root.querySelector('.noUi-handle')) return true;
    for (const el of root.querySelectorAll ? root.querySelectorAll('*') : []) {
      if (el.shadowRoot && seen(el.shadowRoot)) return true;
    }
    return false;
  };
  return seen(document);
}"""

JS_RESULT = """() => {
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type === 'ColumnDataSource' && m.data.index !== undefined && m.data.index.length > 0) return true;
  }
  return false;
}"""


def one_run(browser, file: str | None, timeout: float = 60.0) -> dict:
    port = _free_port("127.0.0.1")
    cmd = [sys.executable, "-m", "explorer.cli", "--no-browser", "--port", str(port)]
    if file:
        cmd.append(file)
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    out: dict = {}
    try:
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"laav-explore exited: {proc.stderr.read().decode()[-2000:]}")
            try:
                socket.create_connection(("127.0.0.1", port), 0.2).close()
                break
            except OSError:
                time.sleep(0.02)
            if time.monotonic() - t0 > timeout:
                raise TimeoutError("the server never listened")
        out["listen_s"] = time.monotonic() - t0
        page = browser.new_page(viewport={"width": 1600, "height": 1000})
        html_at: list[float] = []
        page.on("response", lambda r: html_at.append(time.monotonic() - t0)
                if r.url.rstrip("/") == f"http://127.0.0.1:{port}" else None)
        page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded", timeout=timeout * 1000)
        out["html_s"] = html_at[0] if html_at else time.monotonic() - t0
        page.wait_for_function(JS_READY, timeout=timeout * 1000, polling=20)
        out["ready_s"] = time.monotonic() - t0
        page.wait_for_function(JS_RESULT, timeout=timeout * 1000, polling=50)
        out["result_s"] = time.monotonic() - t0
        page.close()
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("file", nargs="?", help="sequence to open (default: the bundled demo)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=str(REPO / "docs" / "bench" / "explorer_startup.md"),
                    help="Markdown report to write (default docs/bench/explorer_startup.md)")
    args = ap.parse_args(argv)
    if not CHROMIUM.exists():
        print("needs Debian's chromium at /usr/bin/chromium", file=sys.stderr)
        return 2
    from playwright.sync_api import sync_playwright

    # warm the OS file cache (a first-ever start after install reads every module from disk)
    subprocess.run([sys.executable, "-c", "import panel, laav, explorer.app"], cwd=REPO, check=True)
    runs = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=ARGS)
        try:
            for _ in range(args.repeats):
                runs.append(one_run(browser, args.file))
                print(json.dumps({k: round(v, 2) for k, v in runs[-1].items()}), file=sys.stderr)
        finally:
            browser.close()
    summary = {f"{k}_median": round(statistics.median(r[k] for r in runs), 2) for k in runs[0]}
    summary.update(repeats=len(runs), cpus=os.cpu_count(), file=args.file or "bundled demo",
                   runs=[{k: round(v, 2) for k, v in r.items()} for r in runs])
    write_json_report(args.out, "Explorer start-up, command to usable page in headless Chromium",
                      f"{summary['file']}, median of {len(runs)} fresh starts; target: page ready "
                      "(ready_s) within 5 s of the command", summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
