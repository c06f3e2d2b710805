"""Latency of the live explorer, measured server-side.

From setting a widget's value to every view's data being updated from the new result:
the widget callback, the request to the worker thread, ``Pipeline.update`` (only the
stages downstream of the change), building the view data and writing it into the bokeh
data sources and the viser scene. The explorer is built without a browser (no websocket
push; results are applied directly by the worker), with its viser server running (started
here as the 3-D card's first unfold starts it; the card stays folded, so its scene waits).

Targets (issue 5): lambda <= 150 ms, R1/R2 <= 500 ms, frame <= 50 ms, on a ~300-point
Hopkins155 sequence (cars1, 307 points; else 1R2RC_g12; else the bundled demo, noted on
stderr). Data: $HOPKINS155 or ../shared/data/hopkins155 relative to the repository.

Prints ONE JSON line on stdout, e.g.::

    {"lambda_ms_median": 140.2, "radius_ms_median": 310.5, "frame_ms_median": 6.1, ...}

Extra keys: the sequence, point count, repeats, and the share of each median spent inside
``Pipeline.update`` (``*_pipeline_ms_median``).

Also writes them, with date and machine, to ``--out`` (default ``docs/bench/explorer_latency.md``).

Usage: ``python benchmarks/explorer_latency.py [--repeats N] [--sequence NAME] [--no-viser] [--out F]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _machine import write_json_report  # noqa: E402 - this folder, on sys.path

import laav  # noqa: E402


def find_sequence(name: str | None) -> tuple[laav.Sequence, str]:
    env = os.environ.get("HOPKINS155")
    root = Path(env).expanduser() if env else REPO.parent / "shared" / "data" / "hopkins155"
    for cand in ([name] if name else ["cars1", "1R2RC_g12"]):
        p = root / cand
        if p.is_dir():
            return laav.load_sequence(p), ""
    from explorer.demo import demo_sequence

    seq = demo_sequence()
    return seq, f"note: Hopkins155 not found under {root}; measured on the demo sequence {seq.name}"


def measure(ex, set_value, values, repeats: int) -> tuple[list, list]:
    total, pipeline = [], []
    for i in range(repeats):
        v = values[i % len(values)]
        t0 = time.perf_counter()
        set_value(v)
        if not ex.wait(120):
            raise RuntimeError("timed out waiting for the views")
        total.append(1000 * (time.perf_counter() - t0))
        pipeline.append(1000 * ex.state.compute_seconds)
    return total, pipeline


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--sequence", help="Hopkins155 sequence folder name (default cars1)")
    ap.add_argument("--no-viser", action="store_true", help="leave the 3-D view out")
    ap.add_argument("--out", default=str(REPO / "docs" / "bench" / "explorer_latency.md"),
                    help="Markdown report to write (default docs/bench/explorer_latency.md)")
    args = ap.parse_args(argv)

    from explorer import Explorer

    seq, note = find_sequence(args.sequence)
    if note:
        print(note, file=sys.stderr)
    ex = Explorer(seq, viser=not args.no_viser)
    ex.view3d.start()  # (nothing with --no-viser)
    try:
        if not ex.wait(300):
            raise RuntimeError("first result did not arrive")
        lam0 = ex.result.params.lam
        r1_0 = ex.result.params.r1
        # warm up both paths once (imports, caches)
        measure(ex, lambda v: setattr(ex.w_params["lam"], "value", v), [lam0 * 1.5, lam0], 2)
        ex.wait(120, plain_rv=True)  # let the plain-RV comparison finish: it is not part of the timing

        lam_ms, lam_pipe = measure(ex, lambda v: setattr(ex.w_params["lam"], "value", v),
                                   [lam0 * 1.5, lam0], args.repeats)
        rad_ms, rad_pipe = measure(ex, lambda v: setattr(ex.w_params["r1"], "value", v),
                                   [r1_0 - 2.0, r1_0], args.repeats)
        frames = [(i * 7) % seq.n_frames for i in range(1, args.repeats + 1)]
        frame_ms = []
        for f in frames:
            if f == ex.w_frame.value:
                f = (f + 1) % seq.n_frames
            t0 = time.perf_counter()
            ex.w_frame.value = f  # synchronous: only moves data, no recomputation
            frame_ms.append(1000 * (time.perf_counter() - t0))
    finally:
        ex.close()

    med = statistics.median
    out = {
        "lambda_ms_median": round(med(lam_ms), 1),
        "radius_ms_median": round(med(rad_ms), 1),
        "frame_ms_median": round(med(frame_ms), 1),
        "lambda_pipeline_ms_median": round(med(lam_pipe), 1),
        "radius_pipeline_ms_median": round(med(rad_pipe), 1),
        "sequence": seq.name,
        "points": seq.n_points,
        "repeats": args.repeats,
        "viser": not args.no_viser,
    }
    write_json_report(args.out, "Explorer latency, server-side",
                      f"{seq.name} ({seq.n_points} points), median of {args.repeats} changes each; "
                      "targets: lambda <= 150 ms, R1/R2 <= 500 ms, frame <= 50 ms", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
