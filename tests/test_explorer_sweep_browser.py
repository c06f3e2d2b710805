"""The seed sweep and the guided tour in headless Chromium (served with the shared
:func:`test_explorer_browser._served`): the sweep runs from its button with progress on the
page and a click on a row loads that seed; the tour steps forward and back with its buttons
and the arrow keys, its text changing."""

from __future__ import annotations

import os
import re
import threading
from pathlib import Path

import pytest

import laav

pytestmark = [pytest.mark.browser, pytest.mark.slow]

from test_explorer_browser import (  # noqa: E402
    JS_CARD_TITLES,
    JS_SET_SLIDER,
    JS_SOURCES,
    _sequence,
    _served,
    _wait_for,
)

from explorer.sweep import SEEDS  # noqa: E402
from explorer.tour import TOUR  # noqa: E402

#: Step 3's title, on the page before a key press moves to step 4.
TOUR_TITLE_3 = TOUR[2].title

# every value the page's Markdown texts take about the sweep's progress (each change, as the
# browser applies it)
JS_RECORD_PROGRESS = """() => {
  window._laavSeen = [];
  for (const m of Bokeh.documents[0].all_models) {
    if (typeof m.text !== 'string' || m.properties === undefined || m.properties.text === undefined)
      continue;
    m.properties.text.change.connect(() => {
      if (/of 10 seeds|seeds in/.test(m.text)) window._laavSeen.push(m.text);
    });
  }
}"""



#: Elements (shadow roots included) drawn with the tour's 4 px outline.
JS_OUTLINED = """() => { let n = 0; const walk = root => { for (const el of root.querySelectorAll('*')) {
  const cs = getComputedStyle(el);
  if (cs.outlineStyle !== 'none' && cs.outlineWidth === '4px') n++;
  if (el.shadowRoot) walk(el.shadowRoot); } }; walk(document); return n; }"""

#: The sidebar as the tour widens it (explorer.cards.tour.TOUR_SIDEBAR_WIDTH: 35 % of the
#: window less 60 px, 300-440 px) / as usual (300 px).
JS_SIDEBAR_WIDE = """() => { const w = document.getElementById('sidebar').offsetWidth;
  const want = Math.min(Math.max(0.35 * window.innerWidth - 60, 300), 440);
  return Math.abs(w - want) <= 1; }"""
JS_SIDEBAR_USUAL = "() => Math.abs(document.getElementById('sidebar').offsetWidth - 300) <= 1"

#: Where the tour's panel, the outlined card and the page's parts end: the boxes (left, top,
#: right, bottom; px in the window) of the panel and of the outlined card, the sidebar's and
#: main area's scroll offsets, and the widest content against the window.
JS_TOUR_BOXES = """() => {
  const box = el => { const r = el.getBoundingClientRect();
    return [Math.round(r.left), Math.round(r.top), Math.round(r.right), Math.round(r.bottom)]; };
  let panel = null, card = null;
  const walk = root => { for (const el of root.querySelectorAll('*')) {
    if (!panel && el.classList && el.classList.contains('laav-tour-panel')) panel = el;
    if (!card && getComputedStyle(el).outlineWidth === '4px' && getComputedStyle(el).outlineStyle !== 'none')
      card = el;
    if (el.shadowRoot) walk(el.shadowRoot); } };
  walk(document);
  const side = document.getElementById('sidebar'), main = document.getElementById('main');
  return {panel: panel && box(panel), card: card && box(card),
          sideScroll: side.scrollTop, mainScroll: main.scrollTop,
          mainWide: main.scrollWidth - main.clientWidth, pageWide: document.scrollingElement.scrollWidth};
}"""


#: The cards a tour step names (explorer.tour.TourStep.cards) by the start of their titles.
CARD_TITLES = {"frame": "1 · Atoms", "view3d": "3-D", "graph": "2 · Multicut", "coarse": "3 · Fine-to-coarse",
               "rv": "4 · Fine-tuning", "numbers": "5 · Final labels and numbers"}
#: What a step's text is about in each card, to be on screen whole at a projector's size:
#: its first n plots (the RV card's error and label-change charts: "it settles sooner"), or
#: the whole card (the numbers: a table).
SUBJECTS = {"frame": 1, "view3d": 0, "graph": 1, "coarse": 1, "rv": 2, "numbers": "card"}

#: The box (left, top, right, bottom; px in the window) of the shown card whose title starts
#: with the given text, and of its plots in page order (one box per plot: bokeh draws a plot
#: on several canvases of one size); null when no such card is shown.
JS_CARD_BOXES = """(title) => {
  const box = el => { const r = el.getBoundingClientRect();
    return [Math.round(r.left), Math.round(r.top), Math.round(r.right), Math.round(r.bottom)]; };
  let card = null;
  const walk = root => { for (const el of root.querySelectorAll('*')) {
    if (!card && el.classList && el.classList.contains('card-title')) {
      const h = (el.shadowRoot || el).querySelector('h3');
      if ((h ? h.textContent : el.textContent).trim().startsWith(title)) {
        let c = el;  // up to the card (through the shadow roots it sits in)
        while (c && !(c.classList && c.classList.contains('card')))
          c = c.parentNode instanceof ShadowRoot ? c.parentNode.host : c.parentNode;
        if (c && c.getBoundingClientRect().height > 0) card = c;
      }
    }
    if (el.shadowRoot) walk(el.shadowRoot); } };
  walk(document);
  if (!card) return null;
  const plots = [];
  const inCard = root => { for (const el of root.querySelectorAll('*')) {
    if (el.tagName === 'CANVAS' && el.getBoundingClientRect().width > 50) {
      const b = box(el);
      if (!plots.some(p => p.join() === b.join())) plots.push(b);
    }
    if (el.shadowRoot) inCard(el.shadowRoot); } };
  inCard(card); if (card.shadowRoot) inCard(card.shadowRoot);
  return {card: box(card), plots: plots};
}"""


def _shots(tmp_path) -> Path:
    d = Path(os.environ.get("LAAV_EXPLORER_SHOTS", tmp_path))
    d.mkdir(parents=True, exist_ok=True)
    return d


def _open(browser, port, created, i=0):
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
    page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
    ex = _wait_for(lambda: created[i] if len(created) > i else None, 30, "the explorer")
    assert ex.wait(60)
    page.wait_for_function("(" + JS_SOURCES + ")().points > 0", timeout=30000)
    return page, ex, errors


def test_seed_sweep_in_the_page(tmp_path, monkeypatch):
    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, ex, errors = _open(browser, port, created)
        run = page.locator("button", has_text="Run seeds 0-9")
        run.wait_for(timeout=30000)
        run.scroll_into_view_if_needed()
        page.evaluate(JS_RECORD_PROGRESS)
        run.click()
        # progress on the page while it runs, then the ten rows in the table
        page.get_by_text("10 seeds in").first.wait_for(timeout=120000)
        page.wait_for_function("window._laavSeen.some(t => t.includes('10 seeds in'))", timeout=10000)
        seen = page.evaluate("window._laavSeen")
        # the progress line counted the seeds as they finished
        done = [int(m.group(1)) for t in seen if (m := re.search(r"(\d+) of 10 seeds \(", t))]
        assert len(done) >= 3 and done == sorted(done) and min(done) < 10, seen
        rows = page.locator("button", has_text=re.compile(r"^\s*\d+\s+\d+\.\d %"))
        _wait_for(lambda: rows.count() == len(SEEDS), 30, "ten rows in the table", page=page)
        page.get_by_text(re.compile("Worst: seed|Every seed gives the same")).first.wait_for(timeout=10000)
        assert ex.sweep_view.data["seed"] == list(SEEDS)
        assert ex.result.seed == 0
        page.screenshot(path=str(_shots(tmp_path) / "sweep_done.png"))
        # a click on a row loads that seed (the seed slider in the page follows)
        page.locator("button", has_text=re.compile(r"^\s*4\s")).click()
        _wait_for(lambda: ex.result.seed == 4 and ex.wait(1), 60, "seed 4 shown", page=page)
        assert ex.w_seed.value == 4
        page.wait_for_function("""() => { for (const m of Bokeh.documents[0].all_models)
            if (m.type === 'Slider' && String(m.title).startsWith('seed')) return m.value === 4; }""",
                               timeout=20000)
        page.get_by_text("Showing browser_test").first.wait_for(timeout=20000)
        # shown from the sweep's own pipeline for seed 4, not computed again
        page.get_by_text("by the seed sweep").first.wait_for(timeout=20000)
        assert ex.state.computed_ahead(ex.result) == "by the seed sweep"
        assert rows.count() == len(SEEDS)  # the rows stay: only the seed changed
        # a parameter change in the page cancels a running sweep. The sweep's seeds wait at
        # a gate until the change has reached the server: on a fast machine ten small runs
        # could otherwise end before the page's change arrives (a race, not the behaviour)
        gate = threading.Event()
        import explorer.sweep as sweep_module

        pipeline = sweep_module.explorer_pipeline  # what the sweep computes each seed with

        def gated(*args, **kw):
            if threading.current_thread() is not threading.main_thread():
                gate.wait(60)
            return pipeline(*args, **kw)

        monkeypatch.setattr(sweep_module, "explorer_pipeline", gated)
        run.click()
        _wait_for(lambda: ex.sweep_view.sweep.running, 30, "a second sweep", page=page)
        # from the page, as a person does (a change made on the server from this test's
        # thread raced the document's own batches: bokeh "reference ... isn't known")
        assert page.evaluate(JS_SET_SLIDER, ["λ", 4.0]) is not None
        _wait_for(lambda: ex.w_params["lam"].value == 4.0, 30, "λ = 4 on the server", page=page)
        gate.set()
        page.get_by_text("Cancelled: the settings changed").first.wait_for(timeout=30000)
        assert not ex.sweep_view.sweep.running
    assert not errors, errors[:5]


def test_guided_tour_in_the_page(tmp_path):
    from explorer.tour import TOUR

    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, ex, errors = _open(browser, port, created)
        page.wait_for_function(f"({JS_CARD_TITLES})().length >= 7", timeout=30000)  # every card
        # the main area scrolled down to card 3 first: the tour gives it back at its end
        page.wait_for_function("document.getElementById('main').scrollHeight > 2500", timeout=30000)
        page.evaluate("document.getElementById('main').scrollTop = 1500")
        page.locator("button", has_text="Guided tour").first.click()
        title = page.get_by_text(TOUR[0].title)
        title.first.wait_for(timeout=20000)
        page.get_by_text(f"step 1 of {len(TOUR)}").first.wait_for(timeout=10000)
        # large type for a projector (the page's other text is 14 px)
        size = title.first.evaluate("el => parseFloat(getComputedStyle(el).fontSize)")
        assert size >= 26, size
        # only this stage's card: the multicut card is hidden at step 1
        graph = page.locator(".card-header", has_text="2 · Multicut graph")
        graph.first.wait_for(state="hidden", timeout=10000)
        # the panel is in the sidebar, widened beside the card; the sidebar cannot be folded
        # away meanwhile (its text would go while the keys still step)
        page.wait_for_function(JS_SIDEBAR_WIDE, timeout=10000)
        page.locator("#sidebar-toggle").wait_for(state="hidden", timeout=10000)
        page.wait_for_function(f"({JS_OUTLINED})() >= 1", timeout=10000)  # the stage's card
        page.screenshot(path=str(_shots(tmp_path) / "tour_step1.png"))

        # → (the keyboard), Next (the button), ← (the keyboard)
        page.keyboard.press("ArrowRight")
        page.get_by_text(TOUR[1].title).first.wait_for(timeout=20000)
        _wait_for(lambda: ex.tour.step == 1, 10, "step 2", page=page)
        graph.first.wait_for(state="visible", timeout=10000)
        page.get_by_text(TOUR[1].text_for(ex.result.params, 2)[:60]).first.wait_for(timeout=10000)
        page.locator("button", has_text="Next ▶").first.click()
        page.get_by_text(TOUR[2].title).first.wait_for(timeout=20000)
        page.get_by_text(f"step 3 of {len(TOUR)}").first.wait_for(timeout=10000)
        page.locator(".card-header", has_text="3 · Fine-to-coarse").first.wait_for(timeout=10000)
        page.screenshot(path=str(_shots(tmp_path) / "tour_step3.png"))
        page.keyboard.press("ArrowLeft")
        page.get_by_text(TOUR[1].title).first.wait_for(timeout=20000)
        assert ex.tour.step == 1
        page.locator("button", has_text="◀ Back").first.click()
        page.get_by_text(TOUR[0].title).first.wait_for(timeout=20000)
        _wait_for(lambda: ex.tour.step == 0, 10, "step 1 again", page=page)
        # two quick presses move two steps (the second was lost when both reached the server
        # as one change of the key box)
        page.keyboard.press("ArrowRight")
        page.keyboard.press("ArrowRight")
        _wait_for(lambda: ex.tour.step == 2, 10, "step 3 after two presses", page=page)
        page.get_by_text(TOUR[2].title).first.wait_for(timeout=20000)
        # Esc ends the tour: every card is back
        page.keyboard.press("Escape")
        _wait_for(lambda: not ex.tour.active, 10, "the tour to end", page=page)
        graph.first.wait_for(state="visible", timeout=10000)
        page.get_by_text(TOUR[0].title).first.wait_for(state="hidden", timeout=10000)
        page.locator("#sidebar").wait_for(state="visible", timeout=10000)
        page.wait_for_function(JS_SIDEBAR_USUAL, timeout=10000)  # its usual width
        page.locator("#sidebar-toggle").wait_for(state="visible", timeout=10000)
        # and no outline is left on any card in the page (the server's styles are not enough)
        page.wait_for_function(f"({JS_OUTLINED})() === 0", timeout=10000)
        # scrolled back where it was (the tour had put it at the top)
        page.wait_for_function("Math.abs(document.getElementById('main').scrollTop - 1500) <= 1",
                               timeout=10000)
    assert not errors, errors[:5]


def test_a_link_opens_the_tour_at_its_step(tmp_path):
    """``/?tour=3`` opens the page in the tour at step 3, as the server-side tour would show it
    (the sidebar folded, the keys armed: both run in the page once it is on screen), and
    the address follows the steps."""
    from explorer.tour import TOUR

    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"http://127.0.0.1:{port}/?tour=3", wait_until="domcontentloaded")
        ex = _wait_for(lambda: created[0] if created else None, 30, "the explorer")
        assert ex.wait(60)
        page.get_by_text(TOUR[2].title).first.wait_for(timeout=30000)
        page.get_by_text(f"step 3 of {len(TOUR)}").first.wait_for(timeout=10000)
        page.wait_for_function(JS_SIDEBAR_WIDE, timeout=10000)
        page.locator(".card-header", has_text="2 · Multicut graph").first.wait_for(
            state="hidden", timeout=10000)
        page.keyboard.press("ArrowRight")
        page.get_by_text(TOUR[3].title).first.wait_for(timeout=20000)
        page.wait_for_function("new URLSearchParams(location.search).get('tour') === '4'",
                               timeout=20000)
        page.keyboard.press("Escape")
        _wait_for(lambda: not ex.tour.active, 10, "the tour to end", page=page)
        page.wait_for_function("!new URLSearchParams(location.search).has('tour')", timeout=20000)
        page.locator("#sidebar").wait_for(state="visible", timeout=10000)
        page.wait_for_function(JS_SIDEBAR_USUAL, timeout=10000)
    assert not errors, errors[:5]


def test_the_tour_fits_a_projector(tmp_path):
    """On the bundled demo (three motions: the longest texts and tables), at 1280x800 and
    1024x768, every step shows its whole panel (title, text, Back / Next) beside its card,
    and what the step is about in each card it shows whole and inside its card (:data:`SUBJECTS`:
    the plots its text talks about, or the whole Numbers table), without scrolling either way
    (before, the panel sat above the card and took half the screen: the plots began at
    y = 440-490 px; and the result's step showed the Numbers card below the frame view, off
    screen)."""
    from explorer.demo import demo_sequence
    from explorer.tour import TOUR

    seq = demo_sequence()
    with _served(seq, viser=False) as (port, browser, created):
        for i, (w, h) in enumerate(((1280, 800), (1024, 768))):
            page = browser.new_page(viewport={"width": w, "height": h})
            errors: list[str] = []
            page.on("pageerror", lambda e, errors=errors: errors.append(str(e)))
            page.goto(f"http://127.0.0.1:{port}/?tour=1", wait_until="domcontentloaded")
            ex = _wait_for(lambda i=i: created[i] if len(created) > i else None, 30, "the explorer")
            assert ex.wait(90)
            page.wait_for_function("(" + JS_SOURCES + ")().points > 0", timeout=60000)
            for k, step in enumerate(TOUR):
                if k:
                    page.keyboard.press("ArrowRight")
                page.get_by_text(step.title).first.wait_for(timeout=20000)
                _wait_for(lambda k=k, ex=ex: ex.tour.step == k, 10, f"step {k + 1}", page=page)
                page.wait_for_function(JS_SIDEBAR_WIDE, timeout=10000)
                page.wait_for_timeout(400)  # (the page scrolls its areas to their tops at 150 ms)
                m = page.evaluate(JS_TOUR_BOXES)
                page.screenshot(path=str(_shots(tmp_path) / f"tour_{w}x{h}_step{k + 1}.png"))
                where = f"{w}x{h}, step {k + 1}: {m}"
                assert m["panel"] and m["card"], where
                assert m["sideScroll"] == 0 and m["mainScroll"] == 0, where
                assert m["mainWide"] <= 0 and m["pageWide"] <= w, where  # nothing sideways
                assert m["panel"][3] <= h, where  # the whole text and its buttons on screen
                # what the step is about, in each card it shows, on screen whole beside the
                # panel: the plots the text talks about, or the whole table (at 1024x768 the
                # result's Numbers card was below its frame view, off screen)
                for name in step.cards:
                    # (a step may rename its card: the frame view is card 1, the atoms', and
                    # at the result's step its header says 5a)
                    head = (step.card_title if name == step.cards[0] and step.card_title
                            else CARD_TITLES[name])
                    c = page.evaluate(JS_CARD_BOXES, head)
                    where = f"{w}x{h}, step {k + 1}, {name}: {c}"
                    assert c is not None, where
                    subject = SUBJECTS[name]
                    boxes = [c["card"]] if subject == "card" else c["plots"][:subject]
                    assert subject == "card" or len(boxes) == subject, where
                    for x0, y0, x1, y1 in boxes:
                        assert x0 >= m["panel"][2] and x1 <= w and y0 >= 0 and y1 <= h, where
                        assert x1 <= c["card"][2], where  # inside its card (a legend spilled out at 1024)
            page.keyboard.press("Escape")
            _wait_for(lambda ex=ex: not ex.tour.active, 10, "the tour to end", page=page)
            page.close()
            assert not errors, errors[:5]


@pytest.mark.hopkins
def test_step_4_of_a_failing_run_fits_a_projector(hopkins_root, tmp_path):
    """On Hopkins155 cars2B at seed 5 (38.5 % wrong: step 4's facts are a failing run's, its
    longest), step 4's whole panel is on screen at 1280x800 and 1024x768 without scrolling,
    reached from step 3 with the keys and opened by a link (?tour=4), plain RV's run in
    (the facts say it did better). Before, its facts ran past the screen's bottom: their
    smaller lines took the step's text's line height, and a link to step 4 also showed the
    keys' line under them."""
    seq = laav.load_sequence(hopkins_root / "cars2B" / "cars2B_truth.mat")
    with _served(seq, viser=False) as (port, browser, created):
        i = 0
        for w, h in ((1280, 800), (1024, 768)):
            for query in ("?seed=5&tour=3", "?seed=5&tour=4"):
                page = browser.new_page(viewport={"width": w, "height": h})
                errors: list[str] = []
                page.on("pageerror", lambda e, errors=errors: errors.append(str(e)))
                page.goto(f"http://127.0.0.1:{port}/{query}", wait_until="domcontentloaded")
                ex = _wait_for(lambda i=i: created[i] if len(created) > i else None, 30, "the explorer")
                i += 1
                assert ex.wait(120)
                page.wait_for_function("(" + JS_SOURCES + ")().points > 0", timeout=60000)
                if query.endswith("3"):
                    page.get_by_text(TOUR_TITLE_3).first.wait_for(timeout=20000)
                    page.keyboard.press("ArrowRight")
                _wait_for(lambda ex=ex: ex.tour.step == 3, 20, "step 4", page=page)
                page.get_by_text("Plain RV did better here").first.wait_for(timeout=60000)
                page.wait_for_function(JS_SIDEBAR_WIDE, timeout=10000)
                page.wait_for_timeout(400)  # (the page scrolls its areas to their tops at 150 ms)
                m = page.evaluate(JS_TOUR_BOXES)
                page.screenshot(path=str(_shots(tmp_path) / f"tour_cars2B_s5_{w}x{h}_{query[-1]}.png"))
                where = f"{w}x{h} {query}: {m}"
                assert m["panel"] and m["sideScroll"] == 0, where
                assert m["panel"][3] <= h, where  # the whole text and its buttons on screen
                assert not errors, errors[:5]
                page.close()
