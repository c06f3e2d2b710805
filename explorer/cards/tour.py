"""The guided tour: stages 1-5 one at a time (stage 5 in two steps), for a class (the texts:
:mod:`explorer.tour`).

A button in the sidebar starts it. The tour's panel heads the sidebar, which widens for it
(about a third of the screen) while the main area shows only the step's card, outlined, at
its top: the step's title and text in large type beside the figures they explain, as a
slide puts them, so that a projector's 1280x800 or 1024x768 shows both without scrolling.
Back / Next (and the keyboard: ← → or a presenter's Page Up / Page Down; Esc ends the
tour); the controls stay in the sidebar below the panel. Ending the tour brings every card,
the sidebar's width (and its fold) and the colour-by choice back as they were.
"""

from __future__ import annotations

import secrets

import panel as pn

from .. import views as V
from ..tour import TOUR, fine_tuning_facts
from .base import Host, Markdown, page_box

#: Outline of the card a step is about (the header's navy: a page colour, not a motion's).
HIGHLIGHT = {"outline": "4px solid #2c4a66", "outline-offset": "2px"}
#: Not highlighted, said explicitly: styles set back to {} leave the page's outline in
#: place (the browser keeps a CSS property that is no longer sent).
NO_HIGHLIGHT = {"outline": "none", "outline-offset": "0px"}

_BIG_BUTTON = [":host .bk-btn { font-size: 20px; padding: 4px 12px; }"]
#: The panel's text without the paragraphs' own margins (about a line of its type each,
#: above and below): the step's text keeps to the screen's height, a projector's 768-800 px.
_TIGHT = [":host p, :host h1, :host h2 { margin: 0.15em 0; }"]
#: The sidebar's width during the tour (the page's ``--sidebar-width``; 300 px otherwise):
#: about a third of a wide screen, 388 px at 1280, and the usual 300 px at 1024 and below,
#: where the cards are fitted to the main area beside it.
TOUR_SIDEBAR_WIDTH = "clamp(300px, 35vw - 60px, 440px)"
#: Type sizes that follow the screen's width (27 / 19 px at 1280, 22 / 16 px at 1024; the
#: page's other text is 14 px).
TITLE_SIZE = "clamp(22px, 2.1vw, 30px)"
TEXT_SIZE = "clamp(16px, 1.5vw, 22px)"
#: What this run did (step 4's facts), under the step's text and smaller than it, in lines of
#: its own size: a block (inline in its paragraph, its lines took the paragraph's line height,
#: the step's text's, and its line height did nothing: a failing run's facts ran 42 px longer
#: at 1280x800, past the screen's bottom).
_FACTS_CSS = ":host .facts { display: block; font-size: 0.85em; line-height: 1.3; color: #333; }"

# Runs in the browser when the server writes a command into the hidden ``w_js`` box:
# ``on:RUN:N`` / ``off:N`` (arrow keys step the tour or not; the sidebar shown and widened for
# it, and back as it was, and the sidebar and main area scrolled back to where they were),
# ``scroll:N`` (the sidebar and the main area to their tops).
# Keys go back through the hidden ``w_key`` box as ``RUN.N:k1,k2,...``: the tour's token
# (sent with ``on:RUN``, new for every tour, so that another tour's or another explorer's
# presses in the same window are not replayed), the count of presses and the last 32 of them
# (``next``, ``back``, ``end``), so that none is lost when two arrive as one change; keys
# typed into a box or on a slider stay there.
_TOUR_JS = """
const cmd = String(cb_obj.value);
if (!window._laavTour) {
  window._laavTour = {on: false, out: out};
  document.addEventListener('keydown', (e) => {
    const t = window._laavTour;
    if (!t.on || e.altKey || e.ctrlKey || e.metaKey) return;
    let a = document.activeElement;
    while (a && a.shadowRoot && a.shadowRoot.activeElement) a = a.shadowRoot.activeElement;
    if (a && (['INPUT', 'TEXTAREA', 'SELECT'].includes(a.tagName) || a.isContentEditable ||
              (a.getAttribute && a.getAttribute('role') === 'slider'))) return;
    const k = {ArrowRight: 'next', PageDown: 'next', ArrowLeft: 'back', PageUp: 'back',
               Escape: 'end'}[e.key];
    if (!k) return;
    e.preventDefault();
    // every press of this tour (the last 32) in one value: two presses faster than the server
    // answers reach it as one change of the box, and the second one was lost
    t.n = (t.n || 0) + 1;
    t.keys = (t.keys || []).concat([k]).slice(-32);
    t.out.value = t.run + '.' + t.n + ':' + t.keys.join(',');
  });
}
const t = window._laavTour;
t.out = out;
const side = document.getElementById('sidebar');
const toggle = document.getElementById('sidebar-toggle');
const shown = () => side != null && side.offsetWidth > 0;
const root = document.documentElement.style;
if (cmd.startsWith('on:')) {
  // a new tour (its token from the server): its presses are counted from 1
  t.run = cmd.split(':')[1]; t.n = 0; t.keys = [];
  if (!t.on) {
    t.on = true;
    // where the sidebar and the main area were scrolled: back there when the tour ends
    t.scroll = {};
    for (const id of ['sidebar', 'main']) {
      const el = document.getElementById(id);
      if (el) t.scroll[id] = el.scrollTop;
    }
    // the panel is in the sidebar: shown (unfolded if folded) and widened, back afterwards
    // (a notebook has no such sidebar: nothing to widen there)
    if (toggle && !shown()) { toggle.click(); t.unfolded = true; }
    // folded during the tour, the sidebar hid the step's text while the keys still stepped:
    // its button is hidden until the tour ends (End tour, Esc)
    if (toggle) toggle.style.visibility = 'hidden';
    if (side) {
      t.width = root.getPropertyValue('--sidebar-width');
      root.setProperty('--sidebar-width', '__WIDTH__');
    }
  }
}
if (cmd.startsWith('off:')) {
  t.on = false;
  if (side) {
    if (t.width) root.setProperty('--sidebar-width', t.width); else root.removeProperty('--sidebar-width');
  }
  t.width = '';
  if (toggle) toggle.style.visibility = '';
  if (toggle && t.unfolded && shown()) toggle.click();
  t.unfolded = false;
  // back where the page was scrolled before the tour (it ended at the top), once the cards
  // the tour hid are laid out again (the later try: the page may still be growing)
  const back = t.scroll || {};
  t.scroll = {};
  const restore = () => {
    if (t.on) return;  // a new tour started meanwhile: its own scroll stands
    for (const [id, top] of Object.entries(back)) {
      const el = document.getElementById(id);
      if (el && Math.abs(el.scrollTop - top) > 1) el.scrollTop = top;
    }
  };
  setTimeout(restore, 200);
  setTimeout(restore, 700);
}
if (cmd.startsWith('scroll:')) {
  // the step's text and card from their tops (after the server's layout changes are in)
  setTimeout(() => {
    for (const id of ['sidebar', 'main']) {
      const el = document.getElementById(id);
      if (el) el.scrollTop = 0;
    }
    if (!side) {  // a notebook: the panel into view
      const find = (root) => {
        for (const el of root.querySelectorAll('*')) {
          if (el.classList && el.classList.contains('laav-tour-panel')) return el;
          if (el.shadowRoot) { const f = find(el.shadowRoot); if (f) return f; }
        }
        return null;
      };
      const el = find(document);
      if (el) el.scrollIntoView({block: 'start'});
    }
  }, 150);
}
""".replace("__WIDTH__", TOUR_SIDEBAR_WIDTH)


class TourView:
    """The tour's panel and its sidebar button. ``cards`` maps the names of
    :attr:`explorer.tour.TourStep.cards` to the page's cards."""

    def __init__(self, host: Host, controls, cards: dict) -> None:
        self.host, self.controls, self.cards = host, controls, cards
        self.step = 0
        self.active = False
        self._saved: dict = {}  # card name -> (visible, styles), colour mode, before the tour
        self._renamed = None  # (card name, its own title, the step's) while a step renames it
        self._n_js = 0
        self._keys_done = 0  # the page's key presses applied (the w_key box's count)
        self._run = ""  # the running tour's token (the page names its presses by it)
        self._errors_before = None  # the misclassified rings before the tour (None: no frame view)
        self._hint_step: int | None = None  # the step the keys are said at (None: not yet)
        self.w_start = pn.widgets.Button(label="▶ Guided tour (for a class)", color="success",
                                         width=265, margin=(8, 10))
        self.w_start.on_click(lambda e: self.start())
        self.w_back = pn.widgets.Button(label="◀ Back", width=120, height=44, margin=(2, 4, 2, 10),
                                        stylesheets=_BIG_BUTTON)
        self.w_next = pn.widgets.Button(label="Next ▶", color="primary", width=120, height=44,
                                        margin=(2, 4), stylesheets=_BIG_BUTTON)
        self.w_end = pn.widgets.Button(label="End tour", width=80, margin=(2, 10, 2, 4))
        self.w_back.on_click(lambda e: self.go(self.step - 1))
        self.w_next.on_click(lambda e: self.next())
        self.w_end.on_click(lambda e: self.end())
        self.step_md = Markdown("", margin=(2, 10), styles={"font-size": "15px", "color": "#444"},
                                stylesheets=_TIGHT)
        self.title_md = Markdown("", margin=(6, 10, 0, 10), sizing_mode="stretch_width", stylesheets=_TIGHT,
                                 styles={"font-size": TITLE_SIZE, "font-weight": "bold",
                                         "line-height": "1.2", "color": "#2c4a66"})
        self.text_md = Markdown("", margin=(4, 10), sizing_mode="stretch_width",
                                stylesheets=[*_TIGHT, _FACTS_CSS],
                                styles={"font-size": TEXT_SIZE, "line-height": "1.35"})
        self.hint_md = Markdown("Keyboard: ← →  (Esc ends the tour)", margin=(6, 10),
                                styles={"font-size": "14px", "color": "#555"}, stylesheets=_TIGHT)
        # commands to the page (scroll, keys on/off) and the keys it sends back
        self.w_key = pn.widgets.TextInput(value="", visible=False, margin=0, width=0)
        self.w_js = page_box(_TOUR_JS, args={"out": self.w_key})
        self.w_key.param.watch(self._on_key, "value")
        # Back / Next first, where they stay in place from step to step whatever the text's length
        self.panel = pn.Column(
            pn.Row(self.step_md, pn.layout.HSpacer(), self.w_end, sizing_mode="stretch_width"),
            pn.Row(self.w_back, self.w_next),
            self.title_md, self.text_md, self.hint_md,
            self.w_js, self.w_key,
            visible=False, sizing_mode="stretch_width", margin=(0, 4, 10, 0), css_classes=["laav-tour-panel"],
            styles={"background": "#f3f5f8", "border-left": "6px solid #2c4a66", "padding": "4px 2px"})

    # ------------------------------------------------------------------ navigation
    def start(self, step: int = 0) -> None:
        """Enter the tour at ``step`` (0-based), on the document's thread: the steps' cards
        come with the later cards and must be on the page first."""
        self.host.schedule(self._start, step, now_if_on_doc_thread=True)

    def _start(self, step: int) -> None:
        if not self.active:
            self.host.complete_page()  # the steps' cards, if the later cards are still to come
            self._saved = {name: (c.visible, dict(c.styles or {})) for name, c in self.cards.items()}
            self._saved["__color"] = self.controls.color_mode
            view = getattr(self.host, "frame_view", None)  # its misclassified rings before the tour
            self._errors_before = None if view is None else view.error_rings
            self._hint_step = None  # the keys are said at the first step shown (go)
            self.active = True
            self.panel.visible = True
            self._run, self._keys_done = secrets.token_hex(4), 0  # the page counts from 1 again
            self._js("on:" + self._run)
        self.go(step)

    def next(self) -> None:
        if self.step >= len(TOUR) - 1:
            self.end()
        else:
            self.go(self.step + 1)

    def go(self, step: int) -> None:
        """Show step ``step`` (clamped to the tour)."""
        if not self.active:
            return
        self.step = max(0, min(int(step), len(TOUR) - 1))
        s = TOUR[self.step]
        seq = self.host.sequence
        color = s.color if seq is None or seq.labels is not None else s.color_no_truth
        with self.host.hold():
            for name, c in self.cards.items():
                c.visible = name in s.cards
                c.styles = {**self._saved[name][1],
                            **(HIGHLIGHT if name == s.cards[0] else NO_HIGHLIGHT)}
            self.step_md.object = f"Tour · step {self.step + 1} of {len(TOUR)}"
            self.title_md.object = s.title
            self.text_md.object = self._text(s)
            self.w_back.disabled = self.step == 0
            self.w_next.label = "Next ▶" if self.step < len(TOUR) - 1 else "Finish"
            # the keys are said once, at the step a tour (or a link) opens on, unless that step
            # has this run's facts (step 4: a failing run's fill a projector's height): then at
            # the next step shown (the others keep the height)
            if self._hint_step is None and not s.facts:
                self._hint_step = self.step
            self.hint_md.visible = self.step == self._hint_step
            self._rename(s)
        if color is not None and self.controls.color_mode != color:
            self.controls.set_color_mode(color)
        self._error_rings(s.error_rings)
        self._js("scroll")
        self._sync_url()

    def _rename(self, s) -> None:
        """(Inside a batch.) Step ``s``'s header on its card (``TourStep.card_title``; None:
        no step, the tour ends). The card an earlier step renamed gets its own title back,
        unless its title changed meanwhile (the cards that retitle themselves, e.g. for a
        sequence without ground truth, keep theirs): no other card's title is touched."""
        back, self._renamed = self._renamed, None
        if back is not None:
            name, own, shown = back
            card = self.cards[name]
            if card.title == shown:
                card.title = own
        name = None if s is None or not s.card_title else s.cards[0]
        card = self.cards.get(name)
        if isinstance(card, pn.Card):
            self._renamed = (name, card.title, s.card_title)
            card.title = s.card_title

    def _error_rings(self, on: bool | None) -> None:
        """The frame view's misclassified rings on or off (None: as before the tour); the
        tour touches no other layer (:attr:`explorer.cards.frame.FrameView.error_rings`)."""
        view = getattr(self.host, "frame_view", None)
        if view is not None and self._errors_before is not None:
            view.error_rings = self._errors_before if on is None else on

    def _text(self, s) -> str:
        """Step ``s``'s text for the result shown (with the facts of this run, if it has any)."""
        res = self.host.result
        complete = self.controls.state.sequence.is_complete
        if res is None:
            target = self.controls.state.target
            return s.text_for(target.params, target.n_motions, complete)
        text = s.text_for(res.params, res.n_motions, complete)
        if s.facts == "rv":
            rv_view = getattr(self.host, "rv_view", None)
            # (a preview of LAAV's own chain: its trials for a missed motion still computing)
            searching = bool(getattr(self.host, "previewing", False)) and V.own_chain_preview(res)
            facts = fine_tuning_facts(self.host.sequence, res.voting,
                                      None if rv_view is None else rv_view.plain, searching)
            # (its own paragraph, smaller: on a failing run the facts run to five sentences,
            # and the step's two sentences stay the lesson)
            text += f'\n\n<span class="facts">{facts}</span>' if facts else ""
        return text

    def refresh(self) -> None:
        """(Document thread.) The step's text again, for a new result or plain RV's run."""
        if self.active:
            text = self._text(TOUR[self.step])
            if self.text_md.object != text:
                self.text_md.object = text

    def end(self) -> None:
        """Leave the tour: every card and the colour-by as before it."""
        if not self.active:
            return
        self.active = False
        with self.host.hold():
            for name, c in self.cards.items():
                visible, styles = self._saved[name]
                c.visible, c.styles = visible, {**styles, **NO_HIGHLIGHT}
            self.panel.visible = False
            self._rename(None)
        color = self._saved.get("__color")
        if color is not None and self.controls.color_mode != color:
            self.controls.set_color_mode(color)
        self._error_rings(None)
        self._js("off")
        self._sync_url()

    def _sync_url(self) -> None:
        """The page address says which step is shown (``tour=N``), so a link opens it there."""
        sync = getattr(self.host, "_sync_url", None)
        if sync is not None:
            sync()

    @property
    def texts(self) -> tuple[str, str]:
        """The title and text shown."""
        return self.title_md.object, self.text_md.object

    # ------------------------------------------------------------------ the page's keys
    def _js(self, cmd: str) -> None:
        self._n_js += 1
        self.w_js.value = f"{cmd}:{self._n_js}"

    def _on_key(self, event) -> None:
        head, _, tail = str(event.new).partition(":")
        run, _, count = head.partition(".")
        if run != self._run or not count.isdigit():
            return  # another tour's (or explorer's) presses
        # "RUN.N:k1,k2,...": this tour's presses after the last one applied
        n, keys = int(count), tail.split(",")
        new = keys[max(0, len(keys) - (n - self._keys_done)):] if n > self._keys_done else []
        self._keys_done = max(self._keys_done, n)
        for key in new:
            if not self.active:
                return
            if key == "next":
                if self.step < len(TOUR) - 1:  # the last step ends by its button only
                    self.go(self.step + 1)
            elif key == "back":
                self.go(self.step - 1)
            elif key == "end":
                self.end()
