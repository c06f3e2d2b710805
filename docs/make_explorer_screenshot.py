"""Regenerate ``docs/explorer.png``: the real explorer page in headless Debian Chromium.

Usage: ``python docs/make_explorer_screenshot.py [SEQUENCE_FILE] [--frame N] [--out PATH]``
(default: the bundled demo ``assets/demo_three_motions.mat`` at frame 15, 1280 px wide as on
a projector, every card open). Needs
``/usr/bin/chromium`` (``apt-get install -y chromium``) and the playwright package; no
request leaves 127.0.0.1. The PNG is quantised to 256 colours to stay under 500 KB.
"""

from __future__ import annotations

import argparse
import socket
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", help="sequence file (default: the bundled demo)")
    ap.add_argument("--frame", type=int, default=15)
    ap.add_argument("--width", type=int, default=1280, help="page width (default 1280: a projector)")
    ap.add_argument("--height", type=int, default=3700, help="tall enough for every card")
    ap.add_argument("--out", default=str(REPO / "docs" / "explorer.png"))
    args = ap.parse_args(argv)

    import panel as pn
    from PIL import Image
    from playwright.sync_api import sync_playwright

    import laav
    from explorer.cli import app_factory
    from explorer.demo import demo_sequence

    seq = laav.load_sequence(args.file) if args.file else demo_sequence()
    created: list = []
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = pn.serve({"/": app_factory(seq, None, created=created)}, port=port, address="127.0.0.1",
                      show=False, threaded=True, verbose=False)
    outside: list[str] = []
    raw = Path(args.out).with_suffix(".raw.png")
    try:
        for _ in range(300):
            try:
                socket.create_connection(("127.0.0.1", port), 0.2).close()
                break
            except OSError:
                time.sleep(0.1)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=ARGS)
            page = browser.new_page(viewport={"width": args.width, "height": 1000})

            def route(r):
                if r.request.url.startswith(("http://127.0.0.1", "ws://127.0.0.1", "data:", "blob:")):
                    r.continue_()
                else:
                    outside.append(r.request.url)
                    r.abort()

            page.route("**/*", route)
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=60000)
            while not created:
                time.sleep(0.1)
            ex = created[0]
            ex.wait(120, plain_rv=True)
            ex.w_frame.value = args.frame
            if ex.viser is not None:  # the 3-D client loads with the first result; let it draw
                deadline = time.monotonic() + 90
                while time.monotonic() < deadline:
                    frames = [fr for fr in page.frames if f":{ex.viser.port}" in fr.url]
                    if frames and frames[0].get_by_text("Connected").count():
                        break
                    time.sleep(0.5)
            # software WebGL (SwiftShader) is slow: give the scene time to fade in, and close
            # viser's "software WebGL" notice whenever it shows up (headless only)
            page.set_viewport_size({"width": args.width, "height": args.height})
            for _ in range(25):
                for fr in page.frames:
                    if fr != page.main_frame:
                        btn = fr.locator(".mantine-Notification-closeButton")
                        if btn.count():
                            btn.first.click()
                time.sleep(1)
            page.screenshot(path=str(raw))
            browser.close()
    finally:
        server.stop()
        for e in created:
            e.close()
    if outside:
        print(f"requests left 127.0.0.1: {outside}", file=sys.stderr)
        return 1
    im = Image.open(raw).convert("RGB")
    raw.unlink()
    # crop the empty space below the last card
    gray = im.convert("L").point(lambda v: 255 if v < 250 else 0)
    box = gray.crop((400, 0, im.width, im.height)).getbbox()
    if box:
        im = im.crop((0, 0, im.width, min(im.height, box[3] + 12)))
    im.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        args.out, optimize=True)
    print(f"{args.out}: {im.width}x{im.height}, {Path(args.out).stat().st_size // 1024} KB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
