"""Missing data (issue 14 item 3): every stage segments tracks that start late, end early
and have gaps; points seen too briefly get label -1 with a reason; -1 counts as an error.

The strategy per stage is in ``docs/ALGORITHM.md``, "Missing data". The scenes here are
:func:`laav.synthetic.make_sequence` scenes occluded by :func:`laav.synthetic.occlude`.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import laav
from laav import LaavParams, Sequence
from laav._visibility import (
    MIN_ASSIGN_FRAMES,
    NO_FRAME_PAIR,
    UNLABELLED_REASONS,
    decidable,
    filled,
    min_overlap,
    pair_pool,
)
from laav.atoms import build_atoms
from laav.coarse import merge_models
from laav.graph import atom_graph
from laav.multicut import solve_multicut
from laav.refine import assign_by_subspace
from laav.synthetic import crop_view, make_sequence, occlude


def _scene(seed: int, n_frames: int = 20, n_points: int = 200) -> Sequence:
    """Two motions for even seeds, three for odd ones (noise free)."""
    return make_sequence(1 + seed % 2, n_frames=n_frames, n_points=n_points, rng=seed)


def _quiet_segment(seq, C, params=None, seed=0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", laav.LaavWarning)
        return laav.segment(seq, C, params, seed=seed)


# ------------------------------------------------------------------ the occlusion model


def test_occlude_hides_the_share_asked_for_as_late_starts_early_ends_and_one_gap():
    seq = _scene(0)
    F = seq.n_frames
    for fraction in (0.2, 0.4, 0.6):
        occl = occlude(seq, fraction, 7)
        vis = occl.visible
        assert not occl.is_complete
        assert np.count_nonzero(~vis) == round(fraction * vis.size)  # exactly
        assert occl.track_lengths.min() >= 2
        assert np.isnan(occl.points[~vis]).all() and np.array_equal(occl.points[vis], seq.points[vis])
        assert np.array_equal(occl.labels, seq.labels)
        # the visible frames of a track: at most two runs (one gap), inside [first, last]
        runs = (np.diff(vis.astype(np.int8), axis=0) == 1).sum(axis=0) + vis[0]
        assert runs.max() <= 2
        first = vis.argmax(axis=0)
        last = F - 1 - vis[::-1].argmax(axis=0)
        assert (first > 0).any() and (last < F - 1).any() and (runs == 2).any()
    assert np.array_equal(occlude(seq, 0.4, 3).visible, occlude(seq, 0.4, 3).visible)
    assert not np.array_equal(occlude(seq, 0.4, 3).visible, occlude(seq, 0.4, 4).visible)
    even = occlude(seq, 0.3, 0, spread=0.0).track_lengths
    assert np.ptp(even) <= 2  # spread 0: every track loses the same share (+-1 to hit it exactly)
    assert occlude(seq, 0.0, 0) is seq


def test_occlude_treats_both_ends_of_the_sequence_alike():
    """The split of a track's loss into start, gap and end is uniform over all splits: the
    first and the last frame keep about as many points (until 2026-12-03 every occluded
    track lost its last frame, which then held no point), the start or the end run is
    empty for some tracks, and each run holds about a third of the hidden entries."""
    seq = make_sequence(n_objects=2, n_frames=40, n_points=2000, rng=0)
    vis = occlude(seq, 0.2, 1).visible
    first, last = vis[0].sum(), vis[-1].sum()
    assert min(first, last) > 0.8 * max(first, last) and last > 0
    start = vis.argmax(axis=0)  # the frames hidden before a track's first seen one
    end = vis[::-1].argmax(axis=0)  # and after its last
    lost = (~vis).sum(axis=0)
    assert ((start == 0) & (lost > 0)).any() and ((end == 0) & (lost > 0)).any()
    for run in (start, end, lost - start - end):  # the gap: the rest
        assert 0.28 < run.sum() / lost.sum() < 0.39


def test_occlude_refuses_bad_input():
    seq = _scene(0)
    with pytest.raises(ValueError, match="complete sequence"):
        occlude(occlude(seq, 0.2, 0), 0.2, 0)
    with pytest.raises(ValueError, match="fraction"):
        occlude(seq, 0.95, 0)  # more than 1 - 2 / F
    with pytest.raises(ValueError, match="fraction"):
        occlude(seq, -0.1, 0)
    with pytest.raises(ValueError, match="spread"):
        occlude(seq, 0.2, 0, spread=2.0)
    with pytest.raises(ValueError, match="Sequence"):
        occlude(seq.points, 0.2, 0)


def test_crop_view_hides_what_leaves_the_view_and_keeps_the_geometry():
    # issue 14 item 4: objects (and background) entering and leaving the view
    seq = make_sequence(2, n_frames=30, n_points=300, rng=0)
    c = crop_view(seq, 0.6)
    w, h = seq.image_size
    x0, y0 = 0.2 * w, 0.2 * h
    assert c.image_size == (int(np.ceil(0.6 * w)), int(np.ceil(0.6 * h)))
    # every kept track is seq's, shifted, visible exactly where it lies inside the window
    inside = ((seq.points[..., 0] >= x0) & (seq.points[..., 0] <= w - x0)
              & (seq.points[..., 1] >= y0) & (seq.points[..., 1] <= h - y0))
    keep = np.flatnonzero(inside.sum(0) >= 2)
    assert keep.size == c.n_points < seq.n_points
    np.testing.assert_array_equal(c.visible, inside[:, keep])
    np.testing.assert_array_equal(c.labels, seq.labels[keep])
    np.testing.assert_allclose(c.points[c.visible], (seq.points[:, keep] - [x0, y0])[c.visible])
    # objects enter (tracks that start late) and leave (tracks that end early) the view
    first = c.visible.argmax(0)
    last = c.n_frames - 1 - c.visible[::-1].argmax(0)
    for k in (1, 2):
        mine = c.labels == k
        assert max((first[mine] > 0).sum(), (last[mine] < c.n_frames - 1).sum()) >= 0.3 * mine.sum()
    # LAAV through every stage on it (measured 3.6 %: the points near the border)
    res = _quiet_segment(c, 3)
    assert laav.misclassification_rate(c.labels, res.labels) <= 0.05


def test_crop_view_refuses_bad_input():
    seq = _scene(0)
    for bad in (0.0, 1.5, -0.2, (10, 10, 5, 50), (0, 0, np.nan, 5), "x", "1234", (True, 0, 50, 50)):
        with pytest.raises(ValueError, match="window"):
            crop_view(seq, bad)
    with pytest.raises(ValueError, match="image_size"):
        crop_view(Sequence(seq.points, seq.labels), 0.5)
    with pytest.raises(ValueError, match="keeps no track of motion"):
        crop_view(seq, (0, 0, 3, 3))
    with pytest.raises(ValueError, match="Sequence"):
        crop_view(seq.points, 0.5)


# ------------------------------------------------------------------ end to end

#: Scenes and levels of the accuracy test (seconds: about 1 s per run).
SCENES = (0, 1, 4, 5)


@pytest.mark.parametrize("fraction, limit", [(0.2, 0.01), (0.4, 0.02)])
def test_segment_with_missing_data_is_accurate(fraction, limit):
    """Measured (2026-12, seeds 0-7 of ``_scene``, occlusion seed = scene seed, LAAV seed 0):
    20 % missing: 0 points wrong in all 8 scenes; 40 %: 0 in 6, 1 of 200 (0.5 %, scene 1)
    and 2 of 200 (1.0 %, scene 5). The limits, 1 % and 2 % per scene (2 and 4 points of
    200), are the issue's target at 40 % (2 % mean on Hopkins155) applied per scene, and
    half of it at 20 %; noise-free scenes should be no harder than Hopkins155."""
    errors = []
    for s in SCENES:
        seq = _scene(s)
        occl = occlude(seq, fraction, s)
        res = _quiet_segment(occl, seq.n_motions)
        assert res.labels.shape == (seq.n_points,)
        errors.append(laav.misclassification_rate(seq.labels, res.labels))
    assert max(errors) <= limit, errors


def test_same_seed_same_labels_and_the_seed_matters_only_through_its_streams():
    seq = _scene(1)
    occl = occlude(seq, 0.4, 1)
    a = _quiet_segment(occl, 3, seed=5)
    b = _quiet_segment(occl, 3, seed=5)
    assert np.array_equal(a.labels, b.labels)
    assert np.array_equal(a.coarse.point_labels, b.coarse.point_labels)
    assert np.array_equal(a.voting.unlabelled_code, b.voting.unlabelled_code)
    # the staged pipeline reruns only what a change touches and equals a fresh run
    pipe = laav.Pipeline(occl, 3, seed=5)
    assert np.array_equal(pipe.result.labels, a.labels)
    res = pipe.update(lam=5.0)
    assert np.array_equal(res.labels, _quiet_segment(occl, 3, LaavParams(lam=5.0), seed=5).labels)
    res = pipe.update(r1=15.0, r2=30.0)  # the masked neighbourhoods answer a smaller radius
    fresh = _quiet_segment(occl, 3, LaavParams(lam=5.0, r1=15.0, r2=30.0), seed=5)
    assert res.atoms.n_atoms == fresh.atoms.n_atoms
    assert all(np.array_equal(x, y) for x, y in zip(res.atoms.members, fresh.atoms.members))
    assert np.array_equal(res.coarse.point_labels, fresh.coarse.point_labels)
    assert np.array_equal(res.labels, fresh.labels)  # label names included


def test_plain_random_voting_runs_on_missing_data():
    seq = _scene(2)
    occl = occlude(seq, 0.3, 2)
    v = laav.random_voting(occl, 2, seed=0)
    assert v.unlabelled_code is not None and v.unlabelled_code.shape == (seq.n_points,)
    assert laav.misclassification_rate(seq.labels, v.labels) <= 0.02
    again = laav.random_voting(occl, 2, seed=0)
    assert np.array_equal(v.labels, again.labels)


def test_complete_data_runs_the_complete_code():
    """An all-visible mask is the complete-data path: the same labels as no mask at all
    (the masked code would differ: its neighbourhoods use every shared frame)."""
    seq = _scene(0)
    masked = Sequence(seq.points, seq.labels, visible=np.ones((seq.n_frames, seq.n_points), bool))
    assert masked.is_complete
    a = _quiet_segment(seq, 2)
    b = _quiet_segment(masked, 2)
    assert np.array_equal(a.labels, b.labels)
    assert a.voting.unlabelled_code is None and not a.unlabelled_reason
    assert np.array_equal(a.unlabelled_code, np.zeros(seq.n_points, np.int8))
    full = np.ones((seq.n_frames, seq.n_points), bool)
    rng = np.random.default_rng(0)
    at = build_atoms(seq.points, rng=rng, visible=full)
    ref = build_atoms(seq.points, rng=np.random.default_rng(0))
    assert at.ref_frames is None and at.seen is None
    assert all(np.array_equal(x, y) for x, y in zip(at.members, ref.members))


# ------------------------------------------------------------------ hidden entries are never read


def _junk(points: np.ndarray, vis: np.ndarray, seed: int) -> np.ndarray:
    junk = np.random.default_rng(seed).choice([np.nan, np.inf, -np.inf, 1e300, 0.0, -7.0],
                                              size=points.shape)
    return np.where(vis[..., None], points, junk)


def test_every_stage_ignores_what_hidden_entries_hold():
    """Each stage, given arrays and a mask, gives the same result whether the hidden entries
    hold the true coordinates or junk (NaN, inf, 1e300, 0): the visibility handling is what
    every stage reads, never the hidden coordinates."""
    seq = _scene(1)
    occl = occlude(seq, 0.4, 1)
    vis = occl.visible
    true_pts = seq.points  # hidden entries: the real coordinates
    junk_pts = _junk(true_pts, vis, 0)
    p, C = LaavParams(), seq.n_motions
    out = []
    for pts in (true_pts, junk_pts):
        atoms = build_atoms(pts, p, np.random.default_rng(0), visible=vis)
        graph = atom_graph(pts, atoms, p, visible=vis)
        mc = solve_multicut(graph, p.n_fine(C))
        co = merge_models(pts, atoms, mc, C, p, np.random.default_rng(1), visible=vis)
        v = laav.random_voting(pts, C, p, np.random.default_rng(2),
                               init_labels=co.point_labels, visible=vis)
        out.append((atoms, graph, co, v))
    (a1, g1, c1, v1), (a2, g2, c2, v2) = out
    assert a1.n_atoms > 10
    assert all(np.array_equal(x, y) for x, y in zip(a1.members, a2.members))
    assert np.array_equal(a1.affines, a2.affines, equal_nan=True)
    assert np.array_equal(a1.seen, a2.seen) and not a1.seen.all()
    assert np.array_equal(g1.edges, g2.edges)
    assert np.array_equal(g1.errors, g2.errors, equal_nan=True)
    assert np.array_equal(c1.affinity, c2.affinity)
    assert np.array_equal(c1.point_labels, c2.point_labels)
    assert np.array_equal(v1.labels, v2.labels)
    # and through a Sequence (which stores NaN there) the labels are those of the arrays
    res = _quiet_segment(Sequence(junk_pts, seq.labels, visible=vis), C)
    assert np.array_equal(res.labels, _quiet_segment(occl, C).labels)


def test_neighbourhoods_need_enough_shared_frames():
    """Two tracks that share fewer than min_overlap frames are never neighbours, however
    close they are where both are seen."""
    seq = _scene(0)
    F, P = seq.n_frames, seq.n_points
    vis = np.ones((F, P), bool)
    m = min_overlap(F)
    vis[m - 1:, 0] = False  # point 0: frames 0 .. m-2
    vis[:1, 1] = False  # point 1: frames 1 .. F-1 -> shares m - 2 frames with point 0
    pts = seq.points.copy()
    pts[:, 1] = pts[:, 0] + 0.5  # half a pixel from point 0 wherever both are seen
    from laav.atoms import FAR, MaskedNeighbourhoods

    nb = MaskedNeighbourhoods(pts, vis)
    assert nb.distances(np.array([0]), np.array([1]))[0] == FAR
    indptr, near, _ = nb.within(40.0)
    assert 1 not in near[indptr[0]:indptr[1]]
    vis[m - 1, 0] = True  # now m - 1 shared frames... one more makes m
    vis[m, 0] = True
    nb = MaskedNeighbourhoods(pts, vis)
    assert nb.distances(np.array([0]), np.array([1]))[0] == pytest.approx(0.5 * np.sqrt(2))


# ------------------------------------------------------------------ -1: seen too briefly


def test_points_seen_too_briefly_get_minus_one_with_a_reason_and_count_as_errors():
    seq = make_sequence(1, n_frames=21, n_points=160, rng=3)
    F, P = seq.n_frames, seq.n_points
    gap = F // 3
    vis = np.ones((F, P), bool)
    brief = np.arange(0, P, 20)  # 8 points, seen in frames 10 .. 12 only
    short = np.arange(10, P, 20)  # 8 points, seen in frames 10 .. 10 + gap - 1 only
    vis[:, brief] = vis[:, short] = False
    vis[10:13, brief] = True
    vis[10:10 + gap, short] = True
    occl = Sequence(seq.points, seq.labels, visible=vis, name="brief")
    pool = pair_pool(vis, 16)
    no_pair = np.union1d(brief, short)
    assert not decidable(vis, pool)[no_pair].any() and decidable(vis, pool).sum() == P - no_pair.size
    assert MIN_ASSIGN_FRAMES == 4 and 3 < MIN_ASSIGN_FRAMES <= gap
    res = _quiet_segment(occl, 2)
    # no vote reaches either group; the 7-frame tracks are placed by the motions'
    # trajectory subspaces (right: the first scene's motions differ), the 3-frame ones not
    assert np.array_equal(np.flatnonzero(res.labels == -1), brief)
    assert np.array_equal(np.flatnonzero(res.unlabelled_code), brief)
    assert (res.unlabelled_code[brief] == NO_FRAME_PAIR).all()
    assert set(res.unlabelled_reason) == set(brief.tolist())
    assert res.unlabelled_reason[int(brief[0])] == UNLABELLED_REASONS[NO_FRAME_PAIR]
    assert "seen too briefly" in res.unlabelled_reason[int(brief[0])]
    assert laav.UNLABELLED_REASONS is UNLABELLED_REASONS
    # -1 counts as an error: the rest is right, so the error is exactly their share
    err = laav.misclassification_rate(seq.labels, res.labels)
    rest = np.setdiff1d(np.arange(P), brief)
    assert laav.misclassification_rate(seq.labels[rest], res.labels[rest]) == 0.0
    assert err == pytest.approx(brief.size / P)
    assert (res.voting.votes[no_pair] == 0).all()  # placed without a vote


def test_subspace_assignment_places_tracks_by_their_motion():
    """assign_by_subspace on its own: short tracks of two motions go to their motions'
    subspaces; a wrong motion's subspace would not fit them (swap the motions' labels
    and every placed track follows)."""
    seq = make_sequence(1, n_frames=21, n_points=160, rng=3)
    F, P = seq.n_frames, seq.n_points
    vis = np.ones((F, P), bool)
    targets = np.arange(5, P, 9)
    vis[:, targets] = False
    vis[4:9, targets] = True  # 5 frames each
    pts = filled(seq.points, vis)
    lab = seq.labels.copy()
    lab[targets] = -1
    got = assign_by_subspace(pts, lab, 2, vis, targets, MIN_ASSIGN_FRAMES)
    assert np.array_equal(got, seq.labels[targets])
    swapped = np.where(lab >= 0, 1 - lab, -1)
    assert np.array_equal(assign_by_subspace(pts, swapped, 2, vis, targets, MIN_ASSIGN_FRAMES),
                          1 - seq.labels[targets])
    # fewer frames than asked: -1
    assert (assign_by_subspace(pts, lab, 2, vis, targets, 6) == -1).all()


def test_too_little_seen_together_is_a_clear_error():
    """Every track seen in two consecutive frames only: no two frames share the 16 points
    two motions' fundamental matrices need."""
    seq = _scene(0, n_points=60)
    F, P = seq.n_frames, seq.n_points
    vis = np.zeros((F, P), bool)
    q = np.arange(P)
    vis[q % (F - 1), q] = True
    vis[q % (F - 1) + 1, q] = True
    occl = Sequence(seq.points, seq.labels, visible=vis)
    with pytest.raises(ValueError, match="no two frames share 16 visible points"):
        laav.random_voting(occl, 2, seed=0)
    with pytest.raises(ValueError, match="no two frames share"):
        laav.segment(occl, 2)


# ------------------------------------------------------------------ what stays refused or falls back


def test_estimating_the_number_of_motions_needs_enough_complete_tracks():
    """The estimate fits whole trajectories: on incomplete data it runs on the stretch of
    frames and the tracks seen throughout it that hold the most entries (occlude() breaks
    every track over the whole sequence), and says clearly when no stretch of 10 frames is
    seen whole by enough tracks."""
    seq = _scene(0)
    occl = occlude(seq, 0.2, 0)
    assert not occl.visible.all(axis=0).any()
    res = laav.segment(occl, "auto")
    assert res.n_motions == seq.n_motions and "tracks seen in frames" in res.motion_count.reason
    assert laav.misclassification_rate(seq.labels, res.labels) <= 0.05
    few = occl.subset(np.arange(20))  # 20 broken tracks: no stretch is seen whole by 16
    with pytest.raises(ValueError, match="tracks are seen in every frame of a stretch"):
        laav.segment(few, "auto")


def test_the_coding_merge_falls_back_to_the_epipolar_merge_with_a_warning():
    seq = _scene(0)
    occl = occlude(seq, 0.2, 0)
    with pytest.warns(laav.LaavWarning, match="coding"):
        res = laav.segment(occl, 2, LaavParams(coarse_merge="coding", fine_per_motion=3))
    assert res.coarse.method == "epipolar"
    assert np.isnan(res.coarse.merge_cost[0, 1])
    assert laav.misclassification_rate(seq.labels, res.labels) <= 0.02


def test_default_selection_runs_on_missing_data_by_the_subspace_cost():
    """The default's selection (``rv_select="laav"``, LAAV's own candidates) and the joint
    one need whole trajectories for their coding length: on incomplete tracks both still
    run plain RV beside LAAV's trial and select, by the masked subspace cost, exactly as
    ``rv_select="subspace"`` does; so the default and ``with_plain_rv()`` (the default
    until 2026-12-02) give the same labels there."""
    seq = _scene(1)
    occl = occlude(seq, 0.4, 1)
    res = _quiet_segment(occl, seq.n_motions)
    assert res.params.rv_select == "laav"
    assert res.voting.score == "subspace" and len(res.voting.costs) >= 2
    for other in (LaavParams(rv_select="subspace"), LaavParams.with_plain_rv()):
        old = _quiet_segment(occl, seq.n_motions, other)
        np.testing.assert_array_equal(res.labels, old.labels)
        assert res.voting.costs == old.voting.costs


def test_coarse_labels_are_a_candidate_on_incomplete_tracks_only():
    """``rv_coarse_candidate`` (ours, the default): on incomplete tracks LAAV's coarse labels,
    the points in no atom placed by the coarse motions' fits, are scored beside the informed
    trial and plain RV's; kept when best; not on complete tracks, nor when switched off."""
    seq = _scene(1)
    occl = occlude(seq, 0.4, 1)
    truth = seq.labels
    start = truth.copy()
    start[::5] = -1  # a fifth of the points in no atom
    kw = dict(visible=occl.visible, init_labels=start)
    on = laav.random_voting(occl.points, seq.n_motions, LaavParams(), seed=0, **kw)
    off = laav.random_voting(occl.points, seq.n_motions, LaavParams(rv_coarse_candidate=False),
                             seed=0, **kw)
    assert "coarse" in on.costs and "coarse" not in off.costs
    assert set(on.costs) - {"coarse"} == set(off.costs)
    # its labels: the start's where known, the others placed by the motions' fits (all right
    # on this noise-free scene); polished like every candidate
    from laav._visibility import decidable, filled, pair_pool
    from laav.selection import coarse_candidate
    from laav.voting import _Masks

    pool = pair_pool(occl.visible, 8 * seq.n_motions)
    idx = np.flatnonzero(decidable(occl.visible, pool))
    sub_vis = occl.visible[:, idx]
    mk = _Masks(sub_vis, pool)
    labels0 = np.where(start[idx] >= 0, start[idx], 0)
    cand = coarse_candidate(filled(occl.points[:, idx], sub_vis), seq.n_motions, LaavParams(),
                             start[idx], labels0, np.zeros((idx.size, seq.n_motions)), mk)
    np.testing.assert_array_equal(cand[0], truth[idx])
    assert cand[4] == 0 and cand[5] is False  # no voting
    assert on.selected in ("informed", "coarse")  # right ones, polished alike (1 of 200 moved)
    assert laav.misclassification_rate(truth, on.labels) <= 0.01
    # complete tracks: never a candidate
    full = laav.random_voting(seq.points, seq.n_motions, LaavParams(), seed=0, init_labels=start)
    assert "coarse" not in full.costs


def test_the_selection_keeps_the_coarse_labels_when_voting_went_astray(monkeypatch):
    """Where LAAV's informed trial drifts away from right coarse labels (here: replaced by a
    random labelling) and plain RV is no better (2 iterations), the selection keeps the
    coarse labels themselves; without them it returns a worse labelling."""
    import laav.voting as V

    seq = _scene(1)
    occl = occlude(seq, 0.4, 1)
    start = seq.labels.copy()
    start[::5] = -1

    def astray(points, C, params, stream, labels0, votes0, known, masks, memo):
        labels = np.random.default_rng(7).integers(0, C, labels0.size)
        votes = np.zeros((labels0.size, C))
        trial = (labels, votes, np.zeros(1, np.int64), np.zeros(1), 1, False)
        return trial, [trial], None

    monkeypatch.setattr(V, "_first_trial", astray)
    weak = LaavParams(rv_max_iter=2, rv_trials=2)
    kw = dict(seed=0, init_labels=start, visible=occl.visible)
    on = laav.random_voting(occl.points, seq.n_motions, weak, **kw)
    off = laav.random_voting(occl.points, seq.n_motions, weak.replace(rv_coarse_candidate=False), **kw)
    assert on.selected == "coarse"
    assert on.costs["coarse"] < min(v for k, v in on.costs.items() if k != "coarse")
    err_on = laav.misclassification_rate(seq.labels, on.labels)
    assert err_on <= 0.01  # measured 0.5 %: the polish moves one point
    assert "coarse" not in off.costs
    assert laav.misclassification_rate(seq.labels, off.labels) > err_on  # measured 4 %


def test_paper_preset_runs_on_missing_data():
    seq = _scene(0)
    occl = occlude(seq, 0.2, 0)
    res = _quiet_segment(occl, 2, LaavParams.paper())
    assert res.labels.shape == (seq.n_points,)
    assert (res.atoms.ref_frames >= 0).all()


def test_degenerate_input_checks_read_only_visible_entries():
    """check_degenerate on incomplete data: hidden entries (NaN) never enter its tests."""
    rng = np.random.default_rng(0)
    F, P = 6, 30
    still = np.broadcast_to(rng.uniform(0, 300, (1, P, 2)), (F, P, 2)).copy()
    vis = np.ones((F, P), bool)
    vis[4:, :5] = False
    with pytest.warns(laav.LaavWarning, match="no point moves"):
        laav.random_voting(Sequence(still, visible=vis), 2, LaavParams(rv_max_iter=5), seed=0)
    same = np.broadcast_to(still[:, :1], (F, P, 2)).copy()  # one trajectory P times,
    common = np.ones((F, P), bool)
    common[4:] = False  # ... all hidden in the same frames (else they differ in where)
    with pytest.raises(ValueError, match="only 1 distinct trajectory"):
        laav.segment(Sequence(same, visible=common), 2)


def test_missing_data_labels_follow_the_units_of_the_parameters():
    """Scaling the coordinates by s with ``LaavParams.scaled(s)``, or shifting them, leaves
    the labels of an incomplete sequence as they were (the masked code's constants are in
    the parameters' units, its subspaces pass through the visible points' corner; see
    tests/test_scale_invariance.py for complete data). A noisy scene: its labels are not
    decided by rounding."""
    from laav.synthetic import add_noise

    seq = add_noise(make_sequence(2, n_frames=20, n_points=200, rng=1), 0.5, 1)
    occl = occlude(seq, 0.3, 1)
    base = _quiet_segment(occl, 3)
    assert laav.misclassification_rate(seq.labels, base.labels) <= 0.01
    for s in (1e-3, 0.125, 10.0):
        scaled = Sequence(occl.points * s, occl.labels, visible=occl.visible)
        assert np.array_equal(_quiet_segment(scaled, 3, LaavParams().scaled(s)).labels, base.labels), s
    for t in (1e3, -5e4):
        shifted = Sequence(occl.points + t, occl.labels, visible=occl.visible)
        assert np.array_equal(_quiet_segment(shifted, 3).labels, base.labels), t


def test_masked_selection_cost_prefers_the_true_motions_to_points_moved_wrong():
    """The model selection's subspace cost on incomplete data (rank-5 subspaces fitted on the
    visible entries) must rise when points are moved to a wrong motion. Its alternating
    least squares used to stop after 12 sweeps from a row-mean start, far from the fit's
    minimum often enough that 5 or 10 points moved wrong cost less than the truth (seeds 1
    and 5 here); the cost then chose wrong labellings (Hopkins155 truck2 at 40 % missing:
    a 20 % wrong labelling over a right one; benchmarks/TUNING.md)."""
    from laav._visibility import filled
    from laav.refine import subspace_cost

    for seed in range(6):
        seq = _scene(seed)
        occl = occlude(seq, 0.4, seed)
        vis, C = occl.visible, seq.n_motions
        pts = filled(occl.points, vis)
        truth = subspace_cost(pts, seq.labels, C, visible=vis)
        rng = np.random.default_rng(seed)
        for k in (5, 10, 20):
            wrong = seq.labels.copy()
            q = rng.choice(wrong.size, k, replace=False)
            wrong[q] = (wrong[q] + 1) % C
            assert subspace_cost(pts, wrong, C, visible=vis) > truth, (seed, k)


def test_masked_fit_starts_from_each_motions_translation():
    """The masked subspace fit's start guesses an unseen entry from the point's nearest seen
    frame, moved by the mean displacement of the points seen in both frames: exact for
    points that all translate together."""
    from laav.refine import _impute_by_translation

    rng = np.random.default_rng(0)
    F, n = 9, 12
    shift = np.cumsum(rng.normal(size=(F, 2)), axis=0)  # one translation per frame
    X = (rng.normal(size=(1, n, 2)) * 50 + shift[:, None, :]).transpose(0, 2, 1).reshape(2 * F, n)
    vis = rng.random((F, n)) > 0.4
    vis[:, 0] = vis[0] = True  # every frame shares a point with every other
    guess = _impute_by_translation(np.where(np.repeat(vis, 2, axis=0), X, 0.0),
                                   np.repeat(vis, 2, axis=0).astype(np.float64))
    np.testing.assert_allclose(guess, X, atol=1e-9)
