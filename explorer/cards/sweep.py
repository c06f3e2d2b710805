"""Card · Seed sweep: seeds 0-9 with the settings shown, every stage's error per seed, a
click on a row loads that seed.

The sweep runs in the background (:class:`explorer.sweep.SeedSweep`, its own worker
thread): the page stays live, rows appear as their seeds finish, and a change of the
parameters, C or the sequence cancels it (a seed change does not: the rows stay valid).
"""

from __future__ import annotations

import time
from functools import partial

import panel as pn

from .. import sweep as S
from .. import views as V
from ..sweep import SEEDS, SeedSweep, header_line, row_line, table_columns, worst_seed, worst_stage
from .base import HTML, Host, Markdown, card

_EMPTY = {k: [] for k in ("seed", "fine", "coarse", "final", "agreement", "group", "converged", "iterations",
                          "time", "note")}
# a row of the table: one button, its cells aligned in a fixed-width font
_ROW_CSS = [":host .bk-btn { font-family: ui-monospace, 'DejaVu Sans Mono', monospace; font-size: 13px; "
            "white-space: pre; text-align: left; padding: 2px 8px; }"]
_HEAD_STYLE = {"font-family": "ui-monospace, 'DejaVu Sans Mono', monospace", "font-size": "13px",
               "white-space": "pre", "font-weight": "bold", "padding-left": "9px"}


#: The card's title and its caption before a sweep, with and without ground truth.
TITLES = {True: f"Seed sweep: every stage's error for seeds {SEEDS[0]}-{SEEDS[-1]}",
          False: f"Seed sweep: does the segmentation change with the seed? (seeds {SEEDS[0]}-{SEEDS[-1]})"}
CAPTIONS = {True: ("Runs LAAV with the settings shown for every seed, in the background, and lists each "
                   "stage's error; click a row to load that seed."),
            False: ("Runs LAAV with the settings shown for every seed, in the background, and groups the "
                    "seeds by the segmentation they give (no ground truth: no error to list); click a row "
                    "to load that seed.")}


class SweepView:
    """The Run button, the progress line, the table of seeds and its caption.

    ``host`` is the app (``schedule``, ``hold``, ``quieted``); ``state`` the
    :class:`~explorer.state.ExplorerState` whose target settings the sweep uses;
    ``controls`` the sidebar's (a row's click moves the seed slider, as a user would).
    """

    def __init__(self, host: Host, state, controls) -> None:
        self.host, self.state, self.controls = host, state, controls
        # each seed's pipeline is kept by the state: a click on its row shows it at once
        self.sweep = SeedSweep(on_row=self._row_from_worker, on_end=self._end_from_worker,
                               on_pipeline=state.offer_pipeline)
        self._t0 = 0.0
        self._has_truth = True
        self.w_run = pn.widgets.Button(label=f"Run seeds {SEEDS[0]}-{SEEDS[-1]}", color="primary",
                                       width=150, margin=(6, 10))
        self.w_run.on_click(self._on_run)
        # (shown only while a sweep runs: disabled, panel draws it as bright as an active one)
        self.w_stop = pn.widgets.Button(label="Stop", color="warning", width=80, margin=(6, 6),
                                        disabled=True, visible=False)
        self.w_stop.on_click(self._on_stop)
        self.progress_bar = pn.indicators.Progress(value=0, max=len(SEEDS), width=180, height=14,
                                                   margin=(14, 6), bar_color="primary", visible=False)
        self.progress_md = Markdown("", margin=(4, 6), sizing_mode="stretch_width")
        # the table: a header line and one button per seed (a click loads that seed)
        self.data = dict(_EMPTY)
        self.selected: int | None = None  # the row clicked last
        self.header = HTML("", margin=(4, 10, 0, 10), styles=_HEAD_STYLE, visible=False)
        self.row_buttons = []
        for i in range(len(SEEDS)):
            b = pn.widgets.Button(label="", color="light", margin=(1, 10), stylesheets=_ROW_CSS,
                                  visible=False)
            b.on_click(partial(self._on_row, i))
            self.row_buttons.append(b)
        self.caption = Markdown(CAPTIONS[True], sizing_mode="stretch_width", max_width=820, margin=(0, 10))
        self.card = card(TITLES[True],
                         pn.Row(self.w_run, self.w_stop, self.progress_bar, self.progress_md,
                                sizing_mode="stretch_width"),
                         self.header, pn.Column(*self.row_buttons, margin=0), self.caption)

    def show_sequence(self, seq) -> None:
        """(Inside a hold.) The title and the caption for ``seq`` (with or without ground
        truth), unless a sweep's rows are shown."""
        truth = seq.labels is not None
        if self.card.title != TITLES[truth]:
            self.card.title = TITLES[truth]
        if not self.data["seed"] and not self.sweep.running:
            self.caption.object = CAPTIONS[truth]

    # ------------------------------------------------------------------ run / stop
    def run(self) -> int:
        """Start a sweep with the settings most recently asked for (any thread)."""
        st = self.state
        seq, target = st.target_sequence, st.target
        self._has_truth = seq.labels is not None
        self._t0 = time.monotonic()
        sid = self.sweep.start(seq, target.n_motions, target.params)
        self.host.schedule(self._show_started, sid, seq)
        return sid

    def _on_run(self, event=None) -> None:
        self.run()

    def _on_stop(self, event=None) -> None:
        if self.sweep.cancel():
            self.host.schedule(self._show_stopped, "Stopped")

    def settings_changed(self) -> None:
        """(Any thread; the app calls it on every request.) The parameters, C or the sequence
        now asked for are not the sweep's: a running sweep is cancelled, finished rows are
        cleared (they belong to other settings)."""
        st, sw = self.state, self.sweep
        if sw.key is None or sw.matches(st.target_sequence, st.target.n_motions, st.target.params):
            return
        running = sw.cancel()
        sw.key = None
        self.host.schedule(self._show_stopped, "Cancelled: the settings changed" if running else None)

    # ------------------------------------------------------------------ worker -> page
    def _row_from_worker(self, sid, row, done, total) -> None:
        self.host.schedule(self._show_row, sid, done, total)

    def _end_from_worker(self, sid, rows, cancelled) -> None:
        self.host.schedule(self._show_end, sid, cancelled)

    def _show_started(self, sid, seq) -> None:
        if sid != self.sweep.sweep_id:
            return
        with self.host.hold():
            self.selected = None
            rows = list(self.sweep.rows)  # (a first seed may have finished already)
            self._show_table(table_columns(rows) if rows else dict(_EMPTY))
            self.progress_bar.value = len(rows)
            self.progress_bar.visible = True
            self._stop_offered(True)
            self.progress_md.object = f"Seed sweep of {V.md_text(seq.name)}: running seed {SEEDS[0]}…"
            self.caption.object = "Rows appear as their seeds finish; click one to load that seed."

    def _show_row(self, sid, done, total) -> None:
        if sid != self.sweep.sweep_id:
            return
        rows = list(self.sweep.rows)
        with self.host.hold():
            self._show_table(table_columns(rows))
            self.progress_bar.value = done
            left = f"running seed {SEEDS[done]}…" if done < total else "done"
            self.progress_md.object = (f"{done} of {total} seeds ({time.monotonic() - self._t0:.1f} s), "
                                       f"{left}")

    def _show_end(self, sid, cancelled) -> None:
        if sid != self.sweep.sweep_id or cancelled:
            return
        rows = list(self.sweep.rows)
        with self.host.hold():
            self.progress_bar.visible = False
            self._stop_offered(False)
            self.progress_md.object = (f"{len(rows)} seeds in {time.monotonic() - self._t0:.1f} s.")
            self.caption.object = self._summary(rows)

    def _stop_offered(self, on: bool) -> None:
        self.w_stop.disabled = not on
        self.w_stop.visible = on

    def _show_stopped(self, why: str | None) -> None:
        with self.host.hold():
            self.progress_bar.visible = False
            self._stop_offered(False)
            if why is None:  # finished rows of other settings
                self._show_table(dict(_EMPTY))
                self.progress_md.object = ""
                self.caption.object = ("The settings changed since the last sweep: its rows were "
                                       "cleared. Run it again for the settings shown.")
            else:
                n = len(self.data["seed"])
                self.progress_md.object = f"{why} after {n} of {len(SEEDS)} seeds."
                if why.startswith("Cancelled"):  # rows of other settings: cleared, and said so
                    self._show_table(dict(_EMPTY))
                    self.caption.object = ("Its rows were cleared (they were for other settings). "
                                           "Run it again for the settings shown.")

    def _summary(self, rows) -> str:
        if rows[0].error_final is None:
            return _summary_without_truth(rows)
        worst = worst_seed(rows)
        if worst is None:
            r = rows[0]
            same = (f"fine {100 * (r.error_fine or 0):.1f} %, coarse {100 * (r.error_coarse or 0):.1f} %, "
                    f"final {100 * r.error_final:.1f} %")
            return f"**Every seed gives the same result** ({same}). Click a row to load that seed."
        r = next(r for r in rows if r.seed == worst)
        finals = [x.error_final for x in rows]
        bad_final = sum(x.error_final > 0.01 for x in rows)
        bad_coarse = sum((x.error_coarse or 0) > 0.01 for x in rows)
        stage = worst_stage(rows)
        head = (f"**Worst: seed {worst}**" if stage == "final" else
                f"**Every seed ends at final {100 * r.error_final:.1f} %; the worst {stage} stage: "
                f"seed {worst}**")
        more = ("" if all(x.all_iterations == x.iterations for x in rows) else
                " Iterations: the returned trial's, and in brackets every trial's of that run.")
        return (f"{head} (fine {100 * (r.error_fine or 0):.1f} %, coarse "
                f"{100 * (r.error_coarse or 0):.1f} %, final {100 * r.error_final:.1f} %). "
                f"Final error over the seeds: mean {100 * sum(finals) / len(finals):.1f} %; "
                f"above 1 %: {bad_final} of {len(rows)} seeds at the final stage, "
                f"{bad_coarse} at the coarse stage. Click a row to load that seed.{more}")

    # ------------------------------------------------------------------ a click loads a seed
    def _show_table(self, data: dict) -> None:
        """(Inside a hold.) The rows of ``data`` (:func:`explorer.sweep.table_columns`) on the
        buttons; the worst row amber, the row clicked last blue."""
        self.data = data
        n = len(data["seed"])
        self.header.object = header_line(self._has_truth) if n else ""
        self.header.visible = n > 0
        for i, b in enumerate(self.row_buttons):
            b.visible = i < n
            if i < n:
                b.label = row_line(data, i, self._has_truth)
                b.color = ("primary" if data["seed"][i] == self.selected else
                           "warning" if data["note"][i] else "light")

    def _on_row(self, i: int, event=None) -> None:
        if self.host.quieted or i >= len(self.data["seed"]):
            return
        self.selected = int(self.data["seed"][i])
        with self.host.hold():
            self._show_table(self.data)
        self.load_seed(self.selected)

    def load_seed(self, seed: int) -> None:
        """Show ``seed`` (the sidebar's seed slider moves and the page recomputes)."""
        w = self.controls.w_seed
        w.end = max(w.end, seed)
        if w.value == seed:
            self.state.request(seed=seed)
        else:
            w.value = seed

    def close(self) -> None:
        self.sweep.close()


def _summary_without_truth(rows) -> str:
    """The caption of a finished sweep on a sequence without ground truth: the segmentations
    the seeds give (:func:`explorer.sweep.segmentation_groups`), not a worst seed."""
    groups = S.segmentation_groups(rows)
    conv = sum(x.converged for x in rows)
    tail = f" Random Voting converged for {conv} of {len(rows)}. Click a row to load that seed."
    same = (f"a seed joins a segmentation when its final labels are those of the segmentation's "
            f"first seed on at least {100 * S.SAME_SEGMENTATION:.0f} % of the points")
    if len(groups) == 1:
        return f"**Every seed gives the same segmentation** ({same}).{tail}"
    parts = "; ".join(f"{S.group_name(k)} from seed{'s' if len(g) > 1 else ''} "
                      f"{', '.join(str(rows[i].seed) for i in g)} ({len(g)} of {len(rows)})"
                      for k, g in enumerate(groups))
    scatter = ""
    if 2 * max(len(g) for g in groups) < len(rows):  # no segmentation for half the seeds
        scatter = (" Seeds that scatter over this many segmentations are also what a wrong C gives "
                   "(tracks of C + 1 motions forced into C, or the reverse): try C ± 1 in the C box "
                   "and sweep again.")
    return (f"No ground truth: the seeds are grouped by the segmentation they give ({same}). "
            f"**{len(groups)} different segmentations:** {parts}. At most one of them is right, and "
            "the seeds cannot say which (the most frequent need not be): compare them, e.g. pin one "
            "as A and load another." + scatter + tail)
