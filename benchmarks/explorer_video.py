"""The video behind the points (``laav-explore VIDEO``): memory, and what a frame scrub costs.

Measures, in one process, without a browser:

- ``cache_*``: :class:`explorer.video.FrameCache` fed ``--long-frames`` frames of 1280 x 720
  (a long HD video): bytes kept, frames kept, the decimation step, ms per frame added, and
  the process's resident memory growth while it fills (``/proc/self/status`` VmRSS);
- ``track_*``: :func:`explorer.video.open_video` on ``--video`` (default: the synthetic clip,
  ``--upscale K`` makes its frames K times larger first, written as PNGs to a temp folder):
  tracking and estimating C, and the frames kept;
- ``frame_*``: a frame scrub server-side, with the explorer's figures in a bokeh Document so
  that the change is serialised as the server would send it: ms from setting the frame
  widget to every view updated **plus** building the PATCH-DOC message, and its size in
  bytes (with its binary buffers), median (and 90th percentile) of ``--rounds`` x
  ``--repeats`` scrubs; for the same sequence with the video's frame behind the points
  (``on``), the toggle off (``off``), and the sequence without any video (``plain``),
  interleaved round by round (after a warm-up round) so that the machine's load hits all
  three alike.

- ``browser_*`` (``--browser``): in headless Chromium (1280 x 800, one page), ms from a frame
  move in the page (the player's value set, as ``explorer_browser_latency.py`` does) to the
  frame view's new title drawn, median of ``--rounds`` x ``--repeats`` moves, with the frames
  kept at several widths (``--widths``, ``0``: the background toggled off), interleaved move by
  move so that the machine's load hits every width alike.

Prints ONE JSON line and writes it to ``--out`` (default ``docs/bench/explorer_video.md``).
Usage: ``python benchmarks/explorer_video.py [--video PATH] [--upscale K] [--repeats N] [--browser]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402
from _machine import write_json_report  # noqa: E402 - this folder, on sys.path


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def cache_memory(n_frames: int) -> dict:
    from explorer.video import FrameCache

    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (720, 1280), dtype=np.uint8)
    fc = FrameCache()
    before = rss_mb()
    t0 = time.perf_counter()
    for t in range(n_frames):
        fc.add(t, frame)
    ms = 1000 * (time.perf_counter() - t0) / n_frames
    return {"cache_frames_fed": n_frames, "cache_frames_kept": fc.n_kept, "cache_step": fc.step,
            "cache_mb": round(fc.nbytes / 1e6, 1), "cache_rss_growth_mb": round(rss_mb() - before, 1),
            "cache_add_ms": round(ms, 2), "cache_shape": list(fc.shape)}


def scrub(ex, repeats: int) -> tuple[list, list]:
    """ms and bytes of ``repeats`` frame scrubs, the PATCH-DOC message included."""
    from bokeh.document import Document
    from bokeh.protocol import Protocol

    doc = Document()
    for fig in (ex.frame_view.fig, ex.graph_view.fig):
        doc.add_root(fig)
    events: list = []
    doc.callbacks.on_change(lambda ev: events.append(ev))
    proto = Protocol()
    n = ex.sequence.n_frames
    ms, size = [], []
    for _ in range(repeats):
        f = (ex.frame + 7) % n
        events.clear()
        t0 = time.perf_counter()
        ex.w_frame.value = f
        msg = proto.create("PATCH-DOC", list(events))
        dt = 1000 * (time.perf_counter() - t0)
        nbytes = len(msg.header_json) + len(msg.metadata_json) + len(msg.content_json) + sum(
            len(b.to_bytes()) for b in msg.buffers)
        ms.append(dt)
        size.append(nbytes)
    for fig in (ex.frame_view.fig, ex.graph_view.fig):
        doc.remove_root(fig)
    return ms, size


def width_caches(src, video, widths: list[int]) -> dict:
    """The video's frames kept at each width (from the source's full-size frames, read by the
    tracker in its order), as Videos of the same sequence."""
    import dataclasses

    from explorer.video import FrameCache
    from laav.track import track

    caches = {w: FrameCache(max_width=w) for w in widths if w}
    track(src, max_points=20, on_frame=lambda t, img: [c.add(t, img) for c in caches.values()])
    return {w: dataclasses.replace(video, frames=c) for w, c in caches.items()}


def browser(video, caches: dict, widths: list[int], moves: int) -> dict:
    """Frame-move latency in Chromium with the video's frames kept at each width (0: toggle off)."""
    import socket

    import panel as pn
    from explorer_browser_latency import ARGS, CHROMIUM, JS_MOVE
    from playwright.sync_api import sync_playwright

    from explorer.cli import app_factory

    created: list = []
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = pn.serve({"/": app_factory(video.sequence, video.n_motions, created=created, viser=False,
                                        video=video)}, port=port, address="127.0.0.1", show=False,
                      threaded=True, verbose=False)
    runs: dict = {w: [] for w in widths}
    try:
        with sync_playwright() as p:
            b = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=ARGS)
            page = b.new_page(viewport={"width": 1280, "height": 800})
            for _ in range(600):
                try:
                    page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
                    break
                except Exception:  # noqa: BLE001 - not listening yet
                    time.sleep(0.1)
            page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=120000)
            while not created:
                time.sleep(0.1)
            ex = created[0]
            ex.wait(300, plain_rv=True)
            page.wait_for_timeout(2000)
            n = video.sequence.n_frames
            for i in range(moves + 1):
                for w in widths:
                    def use(w=w):
                        ex.frame_view.set_video(caches[w] if w else video)
                        ex.frame_view.w_background.value = bool(w)

                    ex.schedule(use)
                    page.wait_for_timeout(300)
                    f = (ex.frame + 5) % n
                    ms = page.evaluate(JS_MOVE, ["frame", f, "frame", f"frame {f} of"])
                    if i:  # the first round warms up
                        runs[w].append(ms)
            b.close()
    finally:
        server.stop()
        for e in created:
            e.close()
    out = {}
    for w, ms in runs.items():
        key = f"browser_{w}px" if w else "browser_off"
        out[key + "_ms"] = round(statistics.median(ms), 1)
        if w:
            h, ww = caches[w].frames.shape
            out[key + "_image"] = f"{ww}x{h}"
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--video", default=str(REPO / "assets" / "two_objects"))
    ap.add_argument("--upscale", type=int, default=1, help="make the frames K times larger first")
    ap.add_argument("--repeats", type=int, default=20, help="scrubs per round")
    ap.add_argument("--rounds", type=int, default=3, help="rounds, on/off/plain interleaved")
    ap.add_argument("--long-frames", type=int, default=300)
    ap.add_argument("--out", default=str(REPO / "docs" / "bench" / "explorer_video.md"))
    ap.add_argument("--browser", action="store_true", help="also measure frame moves in Chromium")
    ap.add_argument("--widths", default="0,320,410,640",
                    help="frame widths compared in the browser (0: the background off)")
    args = ap.parse_args(argv)

    import cv2

    import laav
    from explorer import Explorer
    from explorer.video import open_video
    from laav.track import IMAGE_EXTENSIONS

    out = cache_memory(args.long_frames)
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(args.video)
        if args.upscale > 1:
            for f in sorted(p for p in src.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS):
                img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
                big = cv2.resize(img, None, fx=args.upscale, fy=args.upscale, interpolation=cv2.INTER_CUBIC)
                cv2.imwrite(str(Path(tmp) / f.name), big)
            src = Path(tmp)
        laav.preload()  # the pipeline's imports are not the video's memory
        before = rss_mb()
        t0 = time.perf_counter()
        video = open_video(src, progress=False)
        out.update(track_s=round(time.perf_counter() - t0, 2),
                   track_rss_growth_mb=round(rss_mb() - before, 1),
                   track_frames=video.frames.describe(), points=video.sequence.n_points,
                   image_size=list(video.sequence.image_size), n_motions=video.n_motions)
        widths = [int(w) for w in args.widths.split(",")]
        caches = width_caches(src, video, widths) if args.browser else {}
    seq = video.sequence
    ex = Explorer(seq, video.n_motions, viser=False, video=video)
    plain = Explorer(laav.Sequence(seq.points, name=seq.name, image_size=seq.image_size), video.n_motions,
                     viser=False)
    try:
        if not (ex.wait(300) and plain.wait(300)):
            raise RuntimeError("first result did not arrive")
        runs: dict = {}
        for r in range(args.rounds + 1):  # interleaved; round 0 warms every path up
            for name, e, on in (("on", ex, True), ("off", ex, False), ("plain", plain, True)):
                e.frame_view.w_background.value = on
                ms, size = scrub(e, args.repeats)
                if r:
                    runs.setdefault(name, ([], []))
                    runs[name][0].extend(ms)
                    runs[name][1].extend(size)
        for name, (ms, size) in runs.items():
            out[f"frame_{name}_ms"] = round(statistics.median(ms), 2)
            out[f"frame_{name}_ms_p90"] = round(float(np.percentile(ms, 90)), 2)
            out[f"frame_{name}_bytes"] = int(statistics.median(size))
    finally:
        ex.close()
        plain.close()
    out["repeats"] = args.repeats * args.rounds
    if args.browser:
        out.update(browser(video, caches, widths, args.rounds * 4))
    write_json_report(args.out, "Explorer with a video behind the points: memory and frame scrub",
                      f"{args.video} (upscaled {args.upscale}x), {out['points']} complete tracks; frame "
                      "scrubs server-side with the PATCH-DOC message built, median of "
                      f"{args.repeats * args.rounds} "
                      "(on / off / plain interleaved); "
                      f"a frame cache fed {args.long_frames} frames of 1280x720", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
