"""The explorer's cards: each module holds one part of the page, its widgets and figures,
how it draws a result and its callbacks; :class:`explorer.app.Explorer` composes them.

=================  ===========================================================
``controls``       sidebar: frame, colour-by, parameter sliders, seed, C, reset
``files``          sidebar: the sequence shown, upload, exports
``status``         header name, status line, what changed, alerts
``frame``          1 · atoms: points, trails, atoms, error / change rings
``view3d``         the 3-D space-time view (a viser server in an iframe)
``graph``          2 · multicut graph and the GAEC replay
``coarse``         3 · fine-to-coarse: affinity Z, merge table (+ ``epipolar``)
``epipolar``       3 · the epipolar check of two fine models
``rv``             4 · Random Voting convergence, LAAV's start vs plain RV
``numbers``        5 · every stage's numbers
``sweep``          the seed sweep: seeds 0-9 in the background, a click loads one
``tour``           the guided tour: one stage at a time, large type (texts: ``explorer.tour``)
``live``           frame moves drawn in the page (bokeh CustomJS) for cards 1 and 2
``base``           card / figure helpers, sizes, the :class:`~base.Host` protocol
=================  ===========================================================
"""
