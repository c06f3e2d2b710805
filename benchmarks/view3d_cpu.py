"""What the explorer's 3-D view costs the browser per frame move: Chromium's CPU seconds
(all its processes) while the view's frame moves, and the scene's redraws.

Serves the 3-D view alone (``explorer.viser_view.ViserView``) with LAAV's result on a
sequence, opens it in Debian's Chromium (headless, software WebGL: no GPU) at the size of
the 3-D card, and measures:

- ``idle_cpu_s_per_s``: Chromium's CPU seconds per second with the page idle (viser still
  redraws once a second);
- ``cpu_s_per_move``: Chromium's CPU seconds per frame move, moves ``--gap`` seconds apart
  (as the frame slider moves: plane, current points, atoms and graph sent anew);
- ``redraws_per_move``: WebGL clears of the view's canvas per move (one per redraw).

``--scene plane`` sends nothing but the frame plane and the axes (no trails, points, atoms
nor graph): what a redraw costs whatever the scene holds. ``--dpr 0.5`` renders at half resolution
(viser's ``fixedDpr``); ``--trail-samples N`` changes the trails' budget
(``TRAIL_SAMPLES``).

    python benchmarks/view3d_cpu.py [FILE] [--scene full|plane] [--dpr X] [--out REPORT.md]

Prints one JSON line; writes it with date, machine and commit to ``--out`` (default
``bench-out/view3d_cpu.md``; docs/bench/view3d_cpu.md is the report of 2026-12-06). Compare runs
made one after the other only (a shared 2-core VM).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _machine import write_json_report  # noqa: E402  (this folder, on sys.path)

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
#: counts the page's WebGL clears (one per redraw of the scene)
JS_COUNT_CLEARS = """
for (const C of [window.WebGL2RenderingContext, window.WebGLRenderingContext]) {
  if (!C) continue;
  const clear = C.prototype.clear;
  C.prototype.clear = function (...a) {
    window.__clears = (window.__clears || 0) + 1;
    return clear.apply(this, a);
  };
}
"""


def _cpu(procs) -> float:
    import psutil

    total = 0.0
    for p in procs:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except psutil.Error:  # a process that has ended
            pass
    return total


def measure(file: str | None, scene: str = "full", dpr: float | None = None,
            trail_samples: int | None = None, moves: int = 20, gap: float = 0.3,
            size=(900, 440)) -> dict:
    import psutil
    from playwright import sync_api

    import laav
    from explorer import viser_view as VV
    from explorer.demo import demo_sequence
    from explorer.views import motion_color

    if trail_samples is not None:
        VV.TRAIL_SAMPLES = int(trail_samples)
    seq = laav.load_sequence(file) if file else demo_sequence()
    res = laav.segment(seq, seq.n_motions or 2)
    view = VV.ViserView()
    try:
        view.set_result(seq, res, np.array([motion_color(int(m)) for m in res.labels]), 0)
        if scene == "plane":  # nothing but the plane, moved per frame
            for name in ("/trajectories", "/points", "/atoms", "/graph_edges"):
                view._remove(name)
            view._draw_frame_items = lambda: setattr(
                view._plane, "position", (0.0, 0.0, float(view._frame) * view._map.dz))
        url = view.url("127.0.0.1") + ("" if dpr is None else f"?fixedDpr={dpr:g}")
        out = {"file": file or "bundled demo", "scene": scene, "points": int(seq.n_points),
               "frames": int(seq.n_frames), "viewport": f"{size[0]}x{size[1]}",
               **({"dpr": dpr} if dpr is not None else {}),
               "trail_samples": int(VV.trail_samples(seq.visible).sum()) if scene == "full" else 0}
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
            try:
                page = browser.new_page(viewport={"width": size[0], "height": size[1]})
                page.add_init_script(JS_COUNT_CLEARS)
                page.goto(url)
                page.locator("canvas").first.wait_for(timeout=120000)
                time.sleep(6)  # shaders compiled, the scene drawn, the notice gone
                procs = [c for c in psutil.Process().children(recursive=True)
                         if "chrom" in c.name().lower()]
                c0, t0 = _cpu(procs), time.monotonic()
                time.sleep(8)
                out["idle_cpu_s_per_s"] = round((_cpu(procs) - c0) / (time.monotonic() - t0), 3)
                clears0 = page.evaluate("window.__clears || 0")
                c0, t0 = _cpu(procs), time.monotonic()
                for i in range(moves):
                    view.set_frame(3 + i % 5)
                    time.sleep(gap)
                dt = time.monotonic() - t0
                used = _cpu(procs) - c0
                out["moves"], out["gap_s"] = moves, gap
                out["cpu_s_per_move"] = round(used / moves, 3)
                out["cpu_s_per_s_moving"] = round(used / dt, 3)
                out["redraws_per_move"] = round((page.evaluate("window.__clears || 0") - clears0) / moves, 1)
            finally:
                browser.close()
    finally:
        view.close()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", help="sequence file (default: the bundled demo)")
    ap.add_argument("--scene", choices=("full", "plane"), default="full")
    ap.add_argument("--dpr", type=float, default=None)
    ap.add_argument("--trail-samples", type=int, default=None)
    ap.add_argument("--moves", type=int, default=20)
    ap.add_argument("--gap", type=float, default=0.3)
    ap.add_argument("--out", default="bench-out/view3d_cpu.md")
    a = ap.parse_args(argv)
    out = measure(a.file, a.scene, a.dpr, a.trail_samples, a.moves, a.gap)
    write_json_report(a.out, "The 3-D view's cost to the browser per frame move",
                      f"{out['file']}, scene {a.scene}, {a.moves} moves {a.gap} s apart, "
                      "headless Chromium (software WebGL)", out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
