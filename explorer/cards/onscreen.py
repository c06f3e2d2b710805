"""Plots painted only where a person can see them.

A result changes every card's plots, but at 1280x800 only card 1's frame view (and the
top of card 2's graph) is on screen: the other six figures are below the fold, in folded
cards or in the hidden A/B pair. Bokeh paints every plot whose data changed, seen or not,
and in a GPU-less browser each full paint (axes and their tick labels measured through the
page's computed styles, legends, glyphs) takes 15-30 ms: about 165 ms of the page's main
thread per R1 move on the demo, of which the frame view's was ~40 ms (CPU profile of
headless Chromium, docs/bench/explorer_browser_latency.md).

:data:`JS_PAINT_ON_SCREEN`, run once when the page's document is ready, has bokeh's figure
views defer a paint while their element is off screen (an ``IntersectionObserver`` on each
figure's element; the viewport and the scrolling main area extended :data:`MARGIN_BELOW_PX`
downwards, where the browser supports ``scrollMargin`` (Chromium 120+), so that the next card
down is ready when scrolled to) and make it when the element comes into view. Bokeh's
own bookkeeping is untouched: what a deferred paint must redraw accumulates as it does
between two animation frames (``invalidate_painters``), and the deferred call is bokeh's
``schedule_paint`` itself. The data are applied at once either way (glyph data, ranges,
legends' models): only the painting waits. A plot whose visibility is not yet known (a new
one, before the observer's first report) is painted as before.
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
if (PV && typeof IntersectionObserver === 'function'
    && !Object.prototype.hasOwnProperty.call(PV.prototype, '_laav_on_screen')) {
  const paint = PV.prototype.schedule_paint, remove = PV.prototype.remove;
  const actual = PV.prototype._actual_paint;
  const shown = new WeakMap();  // plot view -> its element intersects the (extended) viewport
  const obs = new IntersectionObserver((entries) => {
    for (const e of entries) {
      const v = e.target._laav_plot_view;
      if (!v) continue;
      shown.set(v, e.isIntersecting);
      if (e.isIntersecting && v._laav_deferred) {
        v._laav_deferred = false;
        paint.call(v);
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
  if (typeof actual === 'function') {
    PV.prototype._actual_paint = function (...args) {
      this._laav_deferred = false;  // painted, whoever asked (bokeh also paints directly)
      return actual.apply(this, args);
    };
  }
  PV.prototype.remove = function () {
    if (this.el) obs.unobserve(this.el);
    return remove.call(this);
  };
}
"""


def paint_on_screen_script(plot) -> CustomJS:
    """The script (:data:`JS_PAINT_ON_SCREEN`) for the document's ``document_ready`` event;
    ``plot``: any bokeh figure of the page."""
    return CustomJS(args={"plot": plot, "margin": MARGIN_BELOW_PX}, code=JS_PAINT_ON_SCREEN)
