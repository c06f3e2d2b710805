"""Plots painted, and their glyphs' data computed, only where a person can see them.

A result changes every card's plots, but at 1280x800 only card 1's frame view (and the
top of card 2's graph) is on screen: the other six figures are below the fold, in folded
cards or in the hidden A/B pair. Bokeh paints every plot whose data changed, seen or not,
and in a GPU-less browser each full paint (axes and their tick labels measured through the
page's computed styles, legends, glyphs) takes 15-30 ms: about 165 ms of the page's main
thread per R1 move on the demo, of which the frame view's was ~40 ms (CPU profile of
headless Chromium, docs/bench/explorer_browser_latency.md). Before painting, bokeh computes
every changed renderer's glyph data five times (the glyph and its selection, nonselection,
muted and decimated variants: positions, colours, spatial index): about 37 ms of an R1 move's
page time for the plots below the fold (docs/bench/explorer_browser_latency_2026-12-05c.md).

:data:`JS_PAINT_ON_SCREEN`, run once when the page's document is ready, has bokeh's figure
views defer a paint while their element is off screen (an ``IntersectionObserver`` on each
figure's element; the viewport and the scrolling main area extended :data:`MARGIN_BELOW_PX`
downwards, where the browser supports ``scrollMargin`` (Chromium 120+), so that the next card
down is ready when scrolled to) and make it when the element comes into view. Bokeh's
own bookkeeping is untouched: what a deferred paint must redraw accumulates as it does
between two animation frames (``invalidate_painters``), and the deferred call is bokeh's
``schedule_paint`` itself. A glyph renderer's new data on such a plot (its source, glyph or
view changed: bokeh's ``update_data``) waits too: the plot keeps the renderers concerned
(``_laav_stale``) and, when it comes into view, has bokeh compute each one's data in full
(``update_data``: ``set_data``, which also marks the plot's data ranges for an update,
then the renderer marked for repainting) before the paint. The
models themselves (sources, ranges, legends' items, texts) are updated at once, as the
server sends them; only what the page computes from them to draw waits. A plot whose
visibility is not yet known (a new one, before the observer's first report) is drawn as
before. ``window.__laavNoDefer = true`` in the page makes renderers compute their data at
once again (a measurement switch: ``benchmarks/explorer_offscreen_ab.py``).
"""

from __future__ import annotations

from bokeh.models import CustomJS

#: How far below the viewport a plot counts as on screen (px): scrolling down shows a
#: painted card rather than one painted a frame later.
MARGIN_BELOW_PX = 200

#: The page's side, once per page (``plot``: any figure of the page; its view class,
#: bokeh's ``FigureView`` (a ``PlotView``), is every figure's: the explorer makes no plain
#: ``Plot``). Idempotent: a second run changes nothing.
JS_PAINT_ON_SCREEN = r"""
const PV = plot.default_view;
let GV = null;  // bokeh's GlyphRendererView (every glyph renderer's view class)
for (const m of plot.document.all_models)
  if (m.type === 'GlyphRenderer' && m.default_view) { GV = m.default_view; break; }
if (PV && GV && typeof IntersectionObserver === 'function'
    && !Object.prototype.hasOwnProperty.call(PV.prototype, '_laav_on_screen')) {
  const paint = PV.prototype.schedule_paint, remove = PV.prototype.remove;
  const actual = PV.prototype._actual_paint, update = GV.prototype.update_data;
  const shown = new WeakMap();  // plot view -> its element intersects the (extended) viewport
  // a plot come into view: its renderers' data that waited applied (bokeh's own
  // update_data, in full: set_data, then the renderer marked to be repainted, which the
  // plot's next paint otherwise skips), then painted; _laav_deferred stays set until then
  const reveal = async (v) => {
    const stale = v._laav_stale;
    v._laav_stale = null;
    if (stale) {
      for (const rv of stale) {
        if (rv.plot_view === v) {
          try { await update.call(rv); } catch (err) { console.error(err); }
        }
      }
    }
    if (v._laav_stale && v._laav_stale.size) return reveal(v);  // more came meanwhile
    paint.call(v);
  };
  const obs = new IntersectionObserver((entries) => {
    for (const e of entries) {
      const v = e.target._laav_plot_view;
      if (!v) continue;
      shown.set(v, e.isIntersecting);
      if (e.isIntersecting && (v._laav_deferred || (v._laav_stale && v._laav_stale.size))) {
        v._laav_deferred = true;
        reveal(v);
      }
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
    if (shown.get(this) === false && !this.is_paused) {
      this._laav_deferred = true;  // painted when it comes into view
      return;
    }
    return paint.call(this);  // (paused: bokeh paints nothing now; a deferral stays)
  };
  // a renderer's new data (its source, glyph or view changed) on a plot off screen: kept
  // for when the plot is seen (bokeh computes them for the glyph and its four variants);
  // window.__laavNoDefer: computed at once (a measurement switch)
  GV.prototype.update_data = function (...args) {
    const v = this.plot_view;
    if (!window.__laavNoDefer && v && shown.get(v) === false && !v.is_paused) {
      (v._laav_stale = v._laav_stale || new Set()).add(this);
      v._laav_deferred = true;
      return Promise.resolve();
    }
    return update.apply(this, args);
  };
  if (typeof actual === 'function') {
    PV.prototype._actual_paint = function (...args) {
      // painted, whoever asked (bokeh also paints directly); with data still waiting the
      // plot stays to be painted when seen
      this._laav_deferred = !!(this._laav_stale && this._laav_stale.size);
      return actual.apply(this, args);
    };
  }
  PV.prototype.remove = function () {
    if (this.el) obs.unobserve(this.el);
    this._laav_stale = null;
    return remove.call(this);
  };
}
"""


def paint_on_screen_script(plot) -> CustomJS:
    """The script (:data:`JS_PAINT_ON_SCREEN`) for the document's ``document_ready`` event;
    ``plot``: any bokeh figure of the page."""
    return CustomJS(args={"plot": plot, "margin": MARGIN_BELOW_PX}, code=JS_PAINT_ON_SCREEN)
