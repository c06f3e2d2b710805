"""The sidebar's controls: the view (frame, colour-by) and the parameters (sliders for the
main :class:`laav.LaavParams` fields, seed, C, reset), mapped onto
:meth:`ExplorerState.request <explorer.state.ExplorerState.request>`.

A parameter's callback only requests; the state's worker computes, and the app draws the
result when it arrives.
"""

from __future__ import annotations

import panel as pn

from .. import views as V
from ..state import check_motions
from .base import SIDE_W, Host

#: Parameter sliders: LaavParams field -> (label, type, start, end, step).
PARAM_SLIDERS = {
    "r1": ("R1 — inner atom radius (px)", float, 2.0, 100.0, 1.0),
    "r2": ("R2 — outer atom radius (px)", float, 4.0, 160.0, 1.0),
    "fine_models": ("fine models of the multicut (paper: 2C)", int, 1, 18, 1),
    "lam": ("λ — epipolar voting strength (1/px²)", float, 0.1, 10.0, 0.1),
    "coding_eps": ("ε — coding merge distortion (px)", float, 1.0, 40.0, 0.5),
    "rv_alpha": ("RV α — forgetting factor", float, 0.5, 1.0, 0.01),
    "rv_max_iter": ("RV iteration cap", int, 10, 500, 10),
}
#: The fine-models slider reaches at least this many per motion: the default (4 C, or 2 C
#: for the paper preset) then sits inside its range, with room to try more, not at its end.
FINE_PER_MOTION_END = 6


class Controls:
    """Frame, colour-by, the parameter sliders, seed, C and reset, for ``state``."""

    def __init__(self, host: Host, state, seq, defaults) -> None:
        self.host, self.state, self.defaults = host, state, defaults
        self.switching = False  # a new sequence is being read or computed (see lock_motions)
        #: (radius slider, the value it had, the value it was pushed to) when the other radius
        #: pushed it along (R1 < R2): it returns towards its own value when the pushing one
        #: goes back (:meth:`_order_radii`)
        self._pushed = None
        st = state.target
        p = st.params
        self.w_frame = pn.widgets.Player(label="frame", start=0, end=max(seq.n_frames - 1, 1), value=0,
                                         loop_policy="loop", interval=250, width=SIDE_W,
                                         show_loop_controls=False, value_align="start",
                                         scale_buttons=0.8)
        # panel waits 50 ms after a browser change before handling it (to gather a drag's
        # values); a frame move costs the server a few ms (the explorer's callbacks 3-12 ms,
        # its whole handling 11-23 ms in live traces: docs/bench/
        # explorer_browser_latency_2026-12-05h.md), so the wait was most of its share of the
        # latency (docs/bench/explorer_browser_latency.md). Changes arriving while one
        # is handled are still gathered into one. The parameter sliders go without it too:
        # a value that comes during a computation supersedes it (ExplorerState), so there is
        # nothing to gather, and the wait was 50 ms of every parameter change's latency.
        self.w_frame._debounce = 0
        self.w_color = pn.widgets.Select(label="Colour points by", options=list(V.COLOR_MODES),
                                         value="ground truth" if seq.labels is not None
                                         else "final (after Random Voting)", width=SIDE_W)
        self.w_params: dict = {}
        #: each slider's own range: a value from elsewhere (a URL, a params.json, the Advanced
        #: card) beyond it widens the slider while it is shown, and the range comes back after
        self._ranges: dict = {}
        for name, (label, typ, lo, hi, step) in PARAM_SLIDERS.items():
            default = getattr(defaults, name)
            if name == "fine_models":
                value = p.n_fine(st.n_motions, seq.is_complete)
                hi = max(hi, FINE_PER_MOTION_END * st.n_motions)
                w = pn.widgets.IntSlider(label=label, start=lo, end=hi, step=step, value=value,
                                         width=SIDE_W)
            elif typ is int:
                w = pn.widgets.IntSlider(label=label, start=lo, end=max(hi, 2 * default),
                                         step=step, value=int(getattr(p, name)), width=SIDE_W)
            else:
                w = pn.widgets.FloatSlider(label=label, start=lo, end=max(hi, 2.0 * default)
                                           if name != "rv_alpha" else hi, step=step,
                                           value=float(getattr(p, name)), width=SIDE_W)
            w.param.watch(self._on_param, "value")
            w._debounce = 0  # as the frame player's (above): a newer value supersedes at once
            self.w_params[name] = w
            self._ranges[name] = (w.start, w.end)
        # (a seed beyond 99, e.g. from the page address, widens the slider: its handle shows it)
        self.w_seed = pn.widgets.IntSlider(label="seed (random stages)", start=0,
                                           end=max(99, min(st.seed, 2**53 - 1)),
                                           value=st.seed, width=SIDE_W)
        self.w_seed.param.watch(self._on_param, "value")
        self.w_seed._debounce = 0
        # C: at least 1 and at most the number of points, checked by the state, which says
        # why a value is refused (no bounds on the box: the page's box neither clamped nor
        # sent a value beyond them, so a typed 0 showed and did nothing, with no message).
        # A number box, not an integer one: the page's integer box drops what is not a
        # digit as it is typed, so "2.5" became C = 25; a fraction is refused with a message
        self.w_motions = pn.widgets.FloatInput(label="C — number of motions", value=st.n_motions,
                                               step=1, width=140)
        self.w_motions.param.watch(self._on_param, "value")
        self.w_reset = pn.widgets.Button(label="Reset parameters to defaults", color="warning",
                                         width=SIDE_W)
        self.w_reset.on_click(self._on_reset)

    @property
    def color_mode(self) -> str:
        """The colour-by choice as a :data:`views.COLOR_MODES` key (``gt``, ``final``, …)."""
        return V.COLOR_MODES[self.w_color.value]

    def set_color_mode(self, mode: str) -> None:
        """Colour by ``mode`` (a :data:`views.COLOR_MODES` key); a mode that needs ground truth
        (:data:`views.TRUTH_MODES`) on a sequence without it is not offered: the final labels."""
        label = V.COLOR_LABELS[mode]
        self.w_color.value = label if label in self.w_color.options else V.COLOR_LABELS["final"]

    # ------------------------------------------------------------------ widgets -> request
    def _fine_models(self, v: int, C: int):
        """The ``fine_models`` field for the slider's number ``v`` of fine models with C
        motions: what is asked for now when it gives ``v`` (an explicit number typed in the
        Advanced card stays one), None (auto) when ``v`` is ``fine_per_motion`` C, else ``v``."""
        tp, complete = self.state.target.params, self._complete()
        try:
            if v == tp.n_fine(C, complete):
                return tp.fine_models
        except ValueError:  # the fine models asked for are fewer than this C
            pass
        try:
            auto = tp.replace(fine_models=None).n_fine(C, complete)
        except ValueError:  # C itself is invalid (the state says so): keep the number
            return v
        return None if self.defaults.fine_models is None and v == auto else v

    def _complete(self) -> bool:
        """Whether the sequence shown has complete tracks (the merge and the number of fine
        models that ``coarse_merge="auto"`` and ``fine_per_motion=None`` mean depend on it)."""
        return bool(self.state.sequence.is_complete)

    def widget_params(self) -> dict:
        out = {}
        C = int(self.w_motions.value or 1)
        for name, w in self.w_params.items():
            v = w.value
            if name == "fine_models":
                v = self._fine_models(int(v), C)
            elif isinstance(getattr(self.defaults, name), float):
                v = float(v)
                if v != getattr(self.state.target.params, name):
                    # a value the page moved: 12 significant digits, since a slider's steps
                    # add up in its floating point (0.1 + 67 x 0.1 = 6.800000000000001),
                    # which the URL and the run then carried; an unmoved slider keeps the
                    # exact value a URL or a params file put there
                    v = float(f"{v:.12g}")
            else:
                v = int(v)
            out[name] = v
        return out

    def _motions(self):
        """C to request: None (keep the state's) while another sequence is being loaded; a
        whole number as an int, anything else as typed (the state refuses it, saying why)."""
        return None if self.switching or self.w_motions.value is None else _whole(self.w_motions.value)

    def _on_param(self, event=None) -> None:
        if self.host.quieted:
            return
        r1, r2 = self.w_params["r1"], self.w_params["r2"]
        if event is not None and event.obj in (r1, r2):
            self._order_radii(event.obj)
        if event is not None and event.obj is self.w_motions:
            fm = self.w_params["fine_models"]
            # from the C the slider was set for, not the box's previous value: that may be
            # one the state refused (a typed 0), which the fine models never followed. It is
            # the C asked for last, or while another sequence is being read (whose settings
            # the state already holds) the C shown
            held = self.state.settings if self.switching else self.state.target
            old, new = held.n_motions, _whole(event.new)
            # the fine models follow only a C the state can take (it refuses the others,
            # saying why; they must not move the slider meanwhile)
            refused = False
            try:
                check_motions(self.state.target_sequence, new)
            except ValueError:
                old, refused = None, True
            # the fine models follow C (k C by default)
            k = self.state.target.params.replace(fine_models=None).n_fine(1, self._complete())
            if old is not None and fm.value == k * old:
                with self.host.quiet():
                    fm.end = max(fm.end, FINE_PER_MOTION_END * int(event.new or 1))
                    fm.value = k * int(event.new or 1)
        self.state.request(params=self.widget_params(), seed=int(self.w_seed.value),
                           n_motions=self._motions())
        if event is not None and event.obj is self.w_motions and refused and not self.switching:
            # the box shows the C in use again (the refusal's message stays): a refused value
            # left in it made every later change of any control a request with it, refused
            # too, until C was typed again
            with self.host.quiet():
                self.w_motions.value = self.state.target.n_motions

    def _order_radii(self, moved) -> None:
        """R1 < R2 always (atoms need a ring): when ``moved`` (the R1 or R2 slider) passes
        the other radius, that one moves along, within its slider, instead of a refusal that
        held every later change back. The value it had is remembered: when ``moved`` goes
        back, the pushed radius follows it back to that value and stops there (R1 20 -> 60
        -> 20 leaves R2 at 40, not at 61). Anything else that sets the pushed radius (by
        hand, a reset, a URL, another sequence's settings) makes that its own value."""
        r1, r2 = self.w_params["r1"], self.w_params["r2"]
        other = r2 if moved is r1 else r1
        if self._pushed is not None and (self._pushed[0] is moved
                                         or self._pushed[0].value != self._pushed[2]):
            self._pushed = None  # set since: its own value now
        with self.host.quiet():
            if r1.value >= r2.value:
                own = other.value if self._pushed is None else self._pushed[1]
                if moved is r1:
                    r2.end = max(r2.end, r1.value + r2.step)
                    r2.value = r1.value + r2.step
                else:
                    r1.value = max(r1.start, r2.value - r1.step)
                self._pushed = (other, own, other.value)
            elif self._pushed is not None and self._pushed[0] is other:
                own = self._pushed[1]  # back towards it, as near as R1 < R2 allows
                near = (max(own, r1.value + r2.step) if other is r2
                        else min(own, r2.value - r1.step))
                other.value = near
                self._pushed = None if near == own else (other, own, near)

    def _on_reset(self, event=None) -> None:
        """Every parameter (with or without a control here), and the seed, to its default."""
        d = self.defaults
        with self.host.quiet():
            C = int(self.w_motions.value or 1)
            for name, w in self.w_params.items():
                w.value = d.n_fine(C, self._complete()) if name == "fine_models" else getattr(d, name)
            self.w_seed.value = 0
        self.state.request(params={**d.to_dict(), **self.widget_params()}, seed=0, n_motions=self._motions())

    # ------------------------------------------------------------------ settings -> widgets
    def show_settings(self, settings) -> None:
        """Put ``settings`` on the controls without triggering a computation."""
        self._pushed = None  # (radii set from elsewhere: nothing to go back to)
        with self.host.quiet():
            C = settings.n_motions
            fm = self.w_params["fine_models"]
            n_fine = settings.params.n_fine(C, self._complete())
            fm.end = max(fm.end, FINE_PER_MOTION_END * C, n_fine)
            for name, w in self.w_params.items():
                v = n_fine if name == "fine_models" else getattr(settings.params, name)
                if name != "fine_models":  # (its own range again for a value within it: a
                    # URL's λ = 1e9 left the slider 1e9 long, useless in steps of 0.1, for good)
                    lo, hi = self._ranges[name]
                    w.start, w.end = min(lo, v), max(hi, v)
                w.value = v
            # the page's numbers are doubles: the slider's end stays below 2**53 (a larger
            # seed is kept by the state and the URL, the slider shows its end)
            self.w_seed.end = max(self.w_seed.end, min(settings.seed, 2**53 - 1))
            self.w_seed.value = settings.seed
            self.w_motions.value = C

    def sync_to(self, settings) -> None:
        """After a load, show the settings actually used (never after a slider move: the
        widgets may already be ahead of the result being applied)."""
        p = settings.params
        for name, w in self.w_params.items():
            v = (p.n_fine(settings.n_motions, self._complete()) if name == "fine_models"
                 else getattr(p, name))
            if self.state.error is None and w.value != v:
                w.value = v
        if self.state.error is None and self.w_seed.value != settings.seed:
            self.w_seed.value = settings.seed

    def lock_motions(self, locked: bool) -> None:
        """While another sequence is read and first computed, the C box (which belongs to the
        sequence) is locked and slider moves keep the C of the sequence being loaded."""
        self.switching = locked
        self.w_motions.disabled = locked

    def fit_frames(self, seq) -> None:
        """The frame player over ``seq``'s frames (back to 0 when past its end)."""
        self.w_frame.end = max(seq.n_frames - 1, 1)
        if self.w_frame.value > seq.n_frames - 1:
            self.w_frame.value = 0

    def fit_color(self, seq, shown_seq) -> None:
        """The colourings ``seq`` can show: without ground truth, none that needs it
        (:data:`views.TRUTH_MODES`; one chosen becomes the final labels), and the truth again
        for a sequence with it after one without (``shown_seq``: the sequence shown until
        now, None at first)."""
        has_truth = seq.labels is not None
        if not has_truth and self.color_mode in V.TRUTH_MODES:
            self.w_color.value = V.COLOR_LABELS["final"]
        elif has_truth and shown_seq is not None and shown_seq.labels is None:
            self.w_color.value = V.COLOR_LABELS["gt"]
        self.w_color.options = [label for label, mode in V.COLOR_MODES.items()
                                if has_truth or mode not in V.TRUTH_MODES]


def _whole(v):
    """``v`` as an int when it is a whole number (the C box's 3.0), else unchanged."""
    if isinstance(v, float) and v.is_integer():
        return int(v)
    return v
