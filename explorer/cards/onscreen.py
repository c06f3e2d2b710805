"""Plots painted, and their glyphs' data computed, only where a person can see them.

A result changes every card's plots, but at 1280x800 only card 1's frame view (and the
top of card 2's graph) is on screen: the other six figures are below the fold, in folded
cards or in the hidden A/B pair. Bokeh paints every plot whose data changed, seen or not,
and in a GPU-less browser each full paint (axes and their tick labels measured through the
page's computed styles, legends, glyphs) takes 15-30 ms: about 165 ms of the page's main
thread per R1 move on the demo, of which the frame view's was ~40 ms (CPU profile of
headless Chromium, docs/bench/explorer_browser_latency.md). Before painting, bokeh computes
every changed renderer's glyph data five times (the glyph and its selection, nonselection,
muted and decimated variants: positions, colours, spatial index), about 31 renderers below
the fold per R1 move on the demo: keeping that for when they are seen took 19-21 ms off the
page's work after an R1 result, and adds about 35 ms to a card's paint when it is scrolled to
(docs/bench/explorer_browser_latency_2026-12-05c.md).

:data:`JS_PAINT_ON_SCREEN`, run once when the page's document is ready, has bokeh's figure
views defer a paint while their element is off screen (an ``IntersectionObserver`` on each
figure's element; the viewport and the scrolling main area can be extended
:data:`MARGIN_BELOW_PX` downwards, where the browser supports ``scrollMargin`` (Chromium 120+);
0: what can be seen) and make it when the element comes into view. Bokeh's
own bookkeeping is untouched: what a deferred paint must redraw accumulates as it does
between two animation frames (``invalidate_painters``), and the deferred call is bokeh's
``schedule_paint`` itself.

A glyph renderer's new data on such a plot (its source, glyph or view changed: bokeh's
``update_data``) waits too: the plot keeps the renderers concerned (``_laav_stale``) and,
when it comes into view, has bokeh apply each one's data in full (its own ``update_data``:
``set_data``, which also marks the plot's data ranges for an update, then the renderer
marked for repainting), the plot paused meanwhile, before the paint. While data wait, the
plot is not painted at all, also not by bokeh's direct paints after a layout (a card shown,
a size changed): old glyphs against new sources would be wrong, and a legend reading its new
rows' colours past the old ones throws. Such renderers are not hit-tested either. The models
themselves (sources, ranges, legends' items, texts) are updated at once, as the server sends
them; only what the page computes from them to draw waits. A plot whose visibility is not
yet known (a new one, before the observer's first report) is drawn as before. A data range
shared with a plot whose data wait would be computed from that plot's old bounds; no range
of the explorer is shared so (each figure's auto ranges are its own). ``window.__laavNoDefer
= true`` in the page makes renderers compute their data at once again (a measurement switch:
``benchmarks/explorer_offscreen_ab.py``).
"""

from __future__ import annotations

from bokeh.models import CustomJS

#: How far below the viewport a plot counts as on screen (px). 0: only what can be seen. At
#: 200 px (until 2026-12-05) a card just below the fold was kept drawn, so that scrolling
#: down showed it painted rather than a frame later; but at 1280x800 card 2's graph begins 17
#: px below the fold, and every frame move made and painted its nodes and edges for nobody:
#: frame moves 40.6-41.6 ms at 0 against 49.8-53.8 ms at 200 (medians of 10, three
#: interleaved pairs, docs/bench/explorer_browser_latency_2026-12-05c.md).
MARGIN_BELOW_PX = 0

#: The page's side, once per page (``plot``: any figure of the page; its view class,
#: bokeh's ``FigureView`` (a ``PlotView``), is every figure's: the explorer makes no plain
#: ``Plot``). Idempotent: a second run changes nothing.
JS_PAINT_ON_SCREEN = r"""
const PV = plot.default_view;
// bokeh's GlyphRendererView (every glyph renderer's view class), from any glyph renderer
// (the frame view has some): without one, only the paints wait
let GV = null;
for (const m of plot.document ? plot.document.all_models : [])
  if (m.type === 'GlyphRenderer' && m.default_view) { GV = m.default_view; break; }
if (PV && typeof IntersectionObserver === 'function'
    && !Object.prototype.hasOwnProperty.call(PV.prototype, '_laav_on_screen')) {
  const orig_schedule_paint = PV.prototype.schedule_paint, orig_paint = PV.prototype.paint;
  const orig_remove = PV.prototype.remove, orig_actual_paint = PV.prototype._actual_paint;
  const orig_update_data = GV ? GV.prototype.update_data : null;
  const orig_hit_test = GV ? GV.prototype.hit_test : null;
  const waiting = (v) => !!(v._laav_stale && v._laav_stale.size);
  // A plot come into view: its renderers' data that waited applied, one renderer after
  // another, with bokeh's own update_data (set_data in full, then the renderer marked for
  // repainting, which the plot's next paint otherwise skips), then painted. Until then the
  // plot is not painted (see paint below; a renderer in flight still counts as waiting) and
  // is paused as well. One reveal at a time per plot (a second call gets the first's
  // promise; _laav_revealing is cleared when it ends, however it ends); data arriving
  // meanwhile is applied at once (update_data below). _laav_deferred (a paint or data
  // waiting) stays set until the plot's paint (_actual_paint).
  const reveal = (v) => {
    if (v._laav_revealing) return v._laav_revealing;
    const p = (async () => {
      v.pause();
      try {
        while (waiting(v) && !v.is_destroyed) {
          const rv = v._laav_stale.values().next().value;
          if (!rv.is_destroyed) {
            try { await orig_update_data.call(rv); } catch (err) { console.error(err); }
          }
          if (v._laav_stale) v._laav_stale.delete(rv);
        }
      } finally {
        v.unpause(true);
      }
      if (!v.is_destroyed) orig_schedule_paint.call(v);
    })();
    v._laav_revealing = p;
    p.finally(() => { if (v._laav_revealing === p) v._laav_revealing = null; });
    return p;
  };
  const obs = new IntersectionObserver((entries) => {
    for (const e of entries) {
      const v = e.target._laav_plot_view;
      if (!v) continue;
      // whether the element intersects the (extended) viewport, as the observer last said
      // (undefined before its first report: drawn as before)
      v._laav_shown = e.isIntersecting;
      if (!e.isIntersecting || v.is_destroyed) continue;
      if (waiting(v)) reveal(v);
      else if (v._laav_deferred) orig_schedule_paint.call(v);
    }
  }, {rootMargin: '0px 0px ' + margin + 'px 0px',
      // the page's main area is a scrolling box inside a fixed viewport: the margin must
      // widen its clip too (browsers without scrollMargin ignore it: no margin there)
      scrollMargin: '0px 0px ' + margin + 'px 0px'});
  PV.prototype._laav_on_screen = true;
  PV.prototype.schedule_paint = function () {
    const el = this.el;
    if (el && el._laav_plot_view !== this) {
      el._laav_plot_view = this;
      obs.observe(el);
    }
    if (this._laav_shown === false && !this.is_paused) {
      this._laav_deferred = true;  // painted when it comes into view
      return;
    }
    return orig_schedule_paint.call(this);  // (paused: bokeh paints nothing now; a deferral stays)
  };
  // Bokeh also paints without scheduling (after a layout: a card shown, a size changed). With
  // a renderer's data still waiting that paint would draw old glyphs against new sources (a
  // legend reads its new rows' colours past the old ones and throws): it waits for the
  // reveal (at once when the plot is seen).
  PV.prototype.paint = function (...args) {
    if (waiting(this) || this._laav_revealing) {
      this._laav_deferred = true;
      if (this._laav_shown !== false) reveal(this);
      return;
    }
    return orig_paint.apply(this, args);
  };
  if (typeof orig_actual_paint === 'function') {
    PV.prototype._actual_paint = function (...args) {
      this._laav_deferred = false;  // painted, whoever asked
      return orig_actual_paint.apply(this, args);
    };
  }
  PV.prototype.remove = function () {
    if (this.el) obs.unobserve(this.el);
    this._laav_stale = null;
    return orig_remove.call(this);
  };
  if (GV) {
    // A renderer's new data (its source, glyph or view changed) on a plot off screen: kept
    // for when the plot is seen (bokeh computes them for the glyph and its four variants).
    // window.__laavNoDefer: computed at once (a measurement switch).
    GV.prototype.update_data = function (...args) {
      const v = this.plot_view;
      if (!window.__laavNoDefer && v && v._laav_shown === false && !v._laav_revealing) {
        (v._laav_stale = v._laav_stale || new Set()).add(this);
        v._laav_deferred = true;
        return Promise.resolve();
      }
      return orig_update_data.apply(this, args);
    };
    // (a renderer whose data wait has nothing to hit: its glyph holds the old rows; bokeh's
    // PlotView.export, which paints without paint(), is reached by the save tool of a plot
    // on screen only, whose data no longer wait)
    GV.prototype.hit_test = function (...args) {
      const v = this.plot_view;
      if (v && v._laav_stale && v._laav_stale.has(this)) return null;
      return orig_hit_test.apply(this, args);
    };
  }
}
"""


def paint_on_screen_script(plot) -> CustomJS:
    """The script (:data:`JS_PAINT_ON_SCREEN`) for the document's ``document_ready`` event;
    ``plot``: any bokeh figure of the page."""
    return CustomJS(args={"plot": plot, "margin": MARGIN_BELOW_PX}, code=JS_PAINT_ON_SCREEN)
