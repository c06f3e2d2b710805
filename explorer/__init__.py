"""laav-explore: the live browser explorer of every LAAV stage (panel + viser).

>>> from explorer import Explorer                   # doctest: +SKIP
>>> Explorer.from_file("cars1_truth.mat")           # doctest: +SKIP  (displays in Jupyter)
>>> Explorer.from_file("clip.mp4")                  # doctest: +SKIP  (a video: tracked first)

The explorer only uses the public API of :mod:`laav`. Modules: :mod:`explorer.state`
(sequence, pipeline, worker thread; no GUI), :mod:`explorer.video` (a video tracked for the
explorer, its frames kept small; no GUI), :mod:`explorer.views` (result -> plot data),
:mod:`explorer.app` (panel page), :mod:`explorer.viser_view` (3-D view),
:mod:`explorer.cli` (the ``laav-explore`` command).
"""

from .state import ExplorerState

__all__ = ["Explorer", "ExplorerState"]


def __getattr__(name):  # panel is imported only when the page is needed
    if name == "Explorer":
        from .app import Explorer

        return Explorer
    raise AttributeError(f"module 'explorer' has no attribute {name!r}")
