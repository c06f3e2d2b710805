"""The staged pipeline: segment, Pipeline.update, LAAV / RandomVoting estimators."""

from __future__ import annotations

import numpy as np
import pytest

import laav.pipeline as pipeline_module
from laav import (
    LaavParams,
    Pipeline,
    Sequence,
    misclassification_rate,
    segment,
)
from laav.params import STAGES

synthetic = pytest.importorskip("laav.synthetic")

_cache: dict = {}


#: The preset with plain RV beside LAAV's trial (the default until 2026-12-02): the plain-RV
#: memo and the preview exist for it.
PLAIN = LaavParams.with_plain_rv()


def scene(n_objects=1, seed=0, n_points=200, n_frames=15):
    key = (n_objects, seed, n_points, n_frames)
    if key not in _cache:
        _cache[key] = synthetic.make_sequence(n_objects=n_objects, n_frames=n_frames,
                                              n_points=n_points, rng=seed)
    return _cache[key]


def _rot(axis, angle):
    axis = np.asarray(axis, float)
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def clustered_scene(seed=0, n_frames=12, per_cluster=6):
    """Two rigid objects made of 12 tight clusters each (about r1 across, > r2 apart), so
    that with the default radii every feature lands in an atom."""
    rng = np.random.default_rng(seed)
    f, cx, cy = 700.0, 320.0, 240.0
    pts, labels = [], []
    for k, (x0, x1) in enumerate([(-2.2, -0.4), (0.4, 2.2)]):
        for gx in np.linspace(x0, x1, 3):
            for gy in np.linspace(-1.2, 1.2, 4):
                z = rng.uniform(7.0, 10.0)
                c = np.array([gx * z / 8.0, gy * z / 8.0, z])
                ang = np.linspace(0, 2 * np.pi, per_cluster, endpoint=False) + rng.uniform(0, 1)
                r = 0.1 * z / 8.0
                pts.append(c + np.column_stack([r * np.cos(ang), r * np.sin(ang),
                                                rng.uniform(-0.05, 0.05, per_cluster)]))
                labels += [k] * per_cluster
    X = np.concatenate(pts)
    labels = np.array(labels)
    axes = [rng.normal(size=3) for _ in range(2)]
    trans = [np.array([0.25, 0.1, 0.3]), np.array([-0.2, 0.15, -0.3])]
    frames = []
    for t in np.linspace(0, 1, n_frames):
        Y = np.empty_like(X)
        for k in range(2):
            m = labels == k
            cen = X[m].mean(0)
            Y[m] = (X[m] - cen) @ _rot(axes[k], 0.12 * t).T + cen + trans[k] * t
        frames.append(np.column_stack([f * Y[:, 0] / Y[:, 2] + cx, f * Y[:, 1] / Y[:, 2] + cy]))
    return Sequence(np.stack(frames), labels, name="clusters")


def assert_same_result(a, b):
    """Two LaavResults agree in labels and every stage output."""
    assert np.array_equal(a.labels, b.labels)
    assert a.n_motions == b.n_motions and a.seed == b.seed and a.params == b.params
    A, B = a.atoms, b.atoms
    assert A.n_atoms == B.n_atoms
    assert all(np.array_equal(x, y) for x, y in zip(A.members, B.members))
    assert np.array_equal(A.seeds, B.seeds) and np.array_equal(A.owner, B.owner)
    assert np.array_equal(A.affines, B.affines)
    assert np.array_equal(a.graph.edges, b.graph.edges)
    assert np.array_equal(a.graph.costs, b.graph.costs)
    assert np.array_equal(a.multicut.atom_labels, b.multicut.atom_labels)
    assert np.array_equal(a.multicut.multicut_labels, b.multicut.multicut_labels)
    assert np.array_equal(a.coarse.fine_to_coarse, b.coarse.fine_to_coarse)
    assert np.array_equal(a.coarse.affinity, b.coarse.affinity)
    assert np.array_equal(a.coarse.point_labels, b.coarse.point_labels)
    assert np.array_equal(a.voting.labels, b.voting.labels)
    assert np.array_equal(a.voting.changed, b.voting.changed)
    assert a.voting.trial_iterations == b.voting.trial_iterations
    assert a.voting.costs == b.voting.costs and a.voting.score == b.voting.score


def test_segment_is_deterministic():
    seq = scene(2, 1)
    assert_same_result(segment(seq, 3, seed=4), segment(seq, 3, seed=4))
    # a raw array gives the same as the Sequence
    assert np.array_equal(segment(seq.points, 3, seed=4).labels, segment(seq, 3, seed=4).labels)


def test_result_structure():
    seq = scene(1, 0)
    res = segment(seq, 2)
    assert res.labels.shape == (seq.n_points,) and res.labels.dtype == np.int64
    assert set(np.unique(res.labels)) <= {0, 1}
    assert set(res.timings) == set(STAGES) and all(t >= 0 for t in res.timings.values())
    st = res.stage_labels()
    assert set(st) == {"fine", "coarse", "final"}
    assert st["final"] is res.labels
    assert np.array_equal(st["coarse"] >= 0, st["fine"] >= 0)
    assert res.multicut.n_models == res.params.n_fine(2) == 4 * 2  # the joint merge's 4C
    assert res.voting.initialised


UPDATES = [
    {"lam": 5.0},
    {"r1": 15.0},
    {"r2": 55.0},
    {"fine_models": 5},
    {"rv_alpha": 0.8},
    {"seed": 3},
    {"n_motions": 2},
    {"lam": 0.5, "rv_alpha": 0.95},
    {"graph_neighbors": 3, "rv_lambda": 4.0},
    # read by the selection's joint score, outside rv_*: the default's epipolar merge ignores
    # them, so the coarse labels stay and only the voting's memo key can tell
    {"coarse_epipolar_weight": 50.0},
    {"coding_eps": 25.0},
    # a coarse-stage field that also sets the number of fine models (2C -> 4C / 3C): the
    # multicut must run again (it did not: 6 fine models against a fresh run's 12)
    {"coarse_merge": "joint"},
    {"coarse_merge": "coding"},
    {"coarse_merge": "auto", "rv_select": "laav", "rv_subspace_weight": 1.0},
]


@pytest.mark.parametrize("change", UPDATES, ids=lambda d: ",".join(d))
def test_update_equals_fresh_segment(change):
    seq = scene(2, 2)
    pipe = Pipeline(seq, 3, seed=0)
    res = pipe.update(**change)
    kw = dict(change)
    seed = kw.pop("seed", 0)
    C = kw.pop("n_motions", 3)
    fresh = segment(seq, C, LaavParams().replace(**kw), seed=seed)
    assert_same_result(res, fresh)
    assert pipe.result is res
    if set(change) & {"r1", "seed", "n_motions", "lam"}:
        # and changing back returns to the original result (a few cases, for time)
        back = {k: (getattr(LaavParams(), k) if k not in ("seed", "n_motions") else
                    {"seed": 0, "n_motions": 3}[k]) for k in change}
        assert_same_result(pipe.update(**back), segment(seq, 3, seed=0))


def test_update_reuses_upstream_stages():
    seq = scene(1, 1)
    pipe = Pipeline(seq, 2, seed=0)
    r0 = pipe.result
    r1 = pipe.update(lam=4.0)  # coarse stage
    assert r1.atoms is r0.atoms and r1.graph is r0.graph and r1.multicut is r0.multicut
    assert r1.coarse is not r0.coarse
    assert r1.timings["atoms"] == r1.timings["graph"] == r1.timings["multicut"] == 0.0
    # the same coarse labels: the fine-tuning is reused, and its time says so (0, as the
    # Numbers card's "reused"), not the microseconds of comparing its inputs
    assert np.array_equal(r1.coarse.point_labels, r0.coarse.point_labels)
    assert r1.voting is r0.voting and r1.timings["voting"] == 0.0
    r2 = pipe.update(rv_alpha=0.85)  # voting stage only
    assert r2.coarse is r1.coarse and r2.atoms is r0.atoms
    assert r2.voting is not r1.voting
    r3 = pipe.update(fine_models=3)  # multicut
    assert r3.graph is r0.graph and r3.multicut is not r2.multicut
    r4 = pipe.update(r1=12.0)  # atoms and everything after
    assert r4.atoms is not r3.atoms and r4.graph is not r3.graph
    assert r4.multicut is not r3.multicut
    r5 = pipe.update(lam=4.0)  # unchanged value: nothing to do
    assert r5 is r4
    assert pipe.update() is r4


def test_fine_tuning_is_reused_only_when_its_inputs_are_unchanged(monkeypatch):
    seq = scene(1, 1)
    pipe = Pipeline(seq, 2, seed=0)
    r0 = pipe.result
    real = pipeline_module.random_voting
    calls = []
    monkeypatch.setattr(pipeline_module, "random_voting",
                        lambda *a, **k: calls.append(1) or real(*a, **k))

    def update(**change):
        del calls[:]
        res = pipe.update(**change)
        return res, len(calls)

    lam = r0.params.lam * 1.01
    r1, n = update(lam=lam)  # coarse reruns; its labels stay the same here
    assert r1.coarse is not r0.coarse
    assert np.array_equal(r1.coarse.point_labels, r0.coarse.point_labels)
    assert r1.voting is r0.voting and n == 0
    # the seed feeds the voting's generator, so a seed change reruns it (with everything)
    r2, n = update(seed=1)
    assert n == 1 and r2.voting is not r1.voting
    # an rv_* change reruns it although the coarse labels are the same
    r3, n = update(rv_alpha=0.85)
    assert n == 1 and r3.coarse is r2.coarse and r3.voting is not r2.voting
    # other coarse labels (C = 1 labels everything 0): rerun, and back again
    r4, n = update(n_motions=1)
    assert n == 1
    r5, n = update(n_motions=2)
    assert n == 1
    monkeypatch.undo()
    assert_same_result(r1, segment(seq, 2, LaavParams(lam=lam), seed=0))
    assert_same_result(r3, segment(seq, 2, LaavParams(lam=lam, rv_alpha=0.85), seed=1))
    assert_same_result(r5, r3)


@pytest.mark.parametrize("change, match", [
    ({"r1": 50.0}, "r2 must be larger than r1"),
    ({"r2": 10.0}, "r2 must be larger than r1"),
    ({"fine_models": 2}, "fine_models"),
    ({"rv_alpha": 1.5}, "alpha"),
    ({"rv_alpha": 0.0}, "alpha"),
    ({"n_motions": 0}, "n_motions"),
    ({"n_motions": 10_000}, "n_motions"),
    ({"n_motions": 2.5}, "n_motions"),
    ({"no_such_param": 1}, "unknown"),
    ({"lam": -1.0, "r1": 5.0}, "lam"),
    ({"rv_select": "best"}, "rv_select"),
    ({"rv_select_agreement": -0.5}, "rv_select_agreement"),
])
def test_invalid_update_leaves_pipeline_unchanged(change, match):
    seq = scene(2, 0)
    pipe = Pipeline(seq, 3, seed=1)
    res, params, C, seed = pipe.result, pipe.params, pipe.n_motions, pipe.seed
    with pytest.raises(ValueError, match=match):
        pipe.update(**change)
    assert pipe.result is res and pipe.params is params
    assert pipe.n_motions == C and pipe.seed == seed
    # still works afterwards and still equals a fresh run
    assert_same_result(pipe.update(lam=3.0), segment(seq, 3, LaavParams(lam=3.0), seed=1))


def test_failed_stage_leaves_pipeline_consistent(monkeypatch):
    """If a stage raises during update(), the pipeline must keep its previous state: a
    later update must still equal a fresh segment. Currently the stages that ran before
    the failure stay in the stage cache (here atoms for r1=10) while params roll back to
    r1=20, so the next update(lam=...) mixes the two."""
    seq = scene(1, 2)
    pipe = Pipeline(seq, 2, seed=0)
    res = pipe.result
    real = pipeline_module.random_voting

    def boom(*args, **kwargs):
        raise RuntimeError("voting failed")

    monkeypatch.setattr(pipeline_module, "random_voting", boom)
    with pytest.raises(RuntimeError):
        pipe.update(r1=10.0)
    monkeypatch.setattr(pipeline_module, "random_voting", real)
    assert pipe.result is res and pipe.params.r1 == 20.0
    assert_same_result(pipe.update(lam=3.0), segment(seq, 2, LaavParams(lam=3.0), seed=0))


def test_no_atoms_falls_back_to_plain_rv():
    seq = scene(1, 0)
    p = LaavParams(r1=0.1, r2=0.2, affine_threshold=1000.0)
    res = segment(seq, 2, p)
    assert res.atoms.n_atoms == 0 and res.graph.n_nodes == 0
    assert res.multicut.n_models == 0
    assert np.all(res.coarse.point_labels == -1)
    assert not res.voting.initialised
    assert res.labels.shape == (seq.n_points,)
    assert misclassification_rate(seq.labels, res.labels) < 0.01


def test_single_motion():
    full = scene(1, 0)
    keep = full.labels == 0
    seq = Sequence(full.points[:, keep], np.zeros(keep.sum(), int))
    res = segment(seq, 1)
    assert np.all(res.labels == 0)
    assert res.coarse.fine_to_coarse.size == 0 or np.all(res.coarse.fine_to_coarse == 0)


@pytest.mark.parametrize("n_objects", [1, 2])
def test_two_frame_sequence(n_objects):
    seq = synthetic.make_sequence(n_objects=n_objects, n_frames=2, n_points=200, rng=0)
    res = segment(seq, seq.n_motions)
    assert res.labels.shape == (seq.n_points,)
    assert res.labels.min() >= 0 and res.labels.max() < seq.n_motions
    pipe = Pipeline(seq, seq.n_motions)
    assert_same_result(pipe.update(lam=4.0), segment(seq, seq.n_motions, LaavParams(lam=4.0)))


def test_every_feature_in_an_atom():
    seq = clustered_scene(0)
    res = segment(seq, 2)
    assert res.atoms.coverage == 1.0 and res.atoms.unassigned.size == 0
    assert np.all(res.coarse.point_labels >= 0)
    assert res.voting.initialised
    err = misclassification_rate(seq.labels, res.labels)
    assert err < 0.01, f"error {err:.3f}"


@pytest.mark.parametrize("n_motions", [0, -1, True, 2.0, 10_000])
def test_segment_rejects_bad_n_motions(n_motions):
    with pytest.raises(ValueError, match="n_motions"):
        segment(scene(1, 0), n_motions)


def test_segment_rejects_bad_points():
    pts = scene(1, 0).points.copy()
    pts[2, 3, 1] = np.inf
    with pytest.raises(ValueError, match="NaN or infinite"):
        segment(pts, 2)
    with pytest.raises(ValueError, match="shape"):
        segment(pts[0], 2)
    with pytest.raises(ValueError, match="fine_models"):
        segment(scene(1, 0), 3, LaavParams(fine_models=2))


def test_update_checks_the_sequence_again_only_for_a_new_number_of_motions(monkeypatch):
    """A slider move must not re-read every coordinate (nor warn again): the degenerate-input
    check runs at construction and when C changes, not on a λ or R1 update."""
    import laav.pipeline as pipeline_module
    from laav.synthetic import make_sequence

    seq = make_sequence(n_objects=1, n_frames=12, n_points=120, rng=0)
    calls = []
    real = pipeline_module.check_degenerate
    monkeypatch.setattr(pipeline_module, "check_degenerate",
                        lambda s, c: (calls.append(c), real(s, c))[1])
    pipe = Pipeline(seq, 2)
    assert calls == [2]
    pipe.update(lam=3.0)
    pipe.update(r1=22.0, seed=1)
    assert calls == [2]
    pipe.update(n_motions=3)
    assert calls == [2, 3]


@pytest.mark.parametrize("change", [{"r2": 45.0}, {"lam": 3.0}], ids=lambda d: ",".join(d))
def test_update_gives_fresh_label_names_when_plain_rv_is_kept(change):
    """Plain RV's runs are kept across these changes (``random_voting(plain_memo=...)``):
    the returned labels must be a fresh run's bit for bit, label names included (a kept
    plain candidate of the same partition as LAAV's own once lent it its names; measured on
    this scene before the fix)."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    pipe = Pipeline(seq, seq.n_motions, PLAIN)
    res = pipe.update(**change)
    fresh = segment(seq, seq.n_motions, PLAIN.replace(**change), seed=0)
    np.testing.assert_array_equal(res.labels, fresh.labels)


@pytest.mark.parametrize("change", [{"coarse_epipolar_weight": 50.0}, {"coding_eps": 25.0}],
                         ids=lambda d: ",".join(d))
def test_selection_fields_outside_rv_reach_the_kept_fine_tuning(change):
    """The selection's joint score reads ``coarse_epipolar_weight`` and ``coding_eps``; the
    epipolar merge does not, so the coarse labels stay and only the memo keys can tell.
    On a noisy scene each moves the candidates' scores clearly, and the update must equal a
    fresh run (plain RV's runs may be kept: they do not read them)."""
    from laav.bench import add_pixel_noise

    seq = add_pixel_noise(scene(2, 2), 1.0, 0)
    pipe = Pipeline(seq, 3, PLAIN, seed=0)  # the epipolar merge (the default's reads them)
    base = pipe.result
    assert np.array_equal(pipe.update(**change).coarse.point_labels, base.coarse.point_labels)
    res = pipe.update(**change)
    fresh = segment(seq, 3, PLAIN.replace(**change), seed=0)
    assert_same_result(res, fresh)
    common = set(base.voting.costs) & set(res.voting.costs)
    assert common and max(abs(base.voting.costs[k] - res.voting.costs[k]) for k in common) > 1e-3


def test_the_coarse_candidate_switch_keeps_plain_rv_runs(monkeypatch):
    """``rv_coarse_candidate`` is read by LAAV's fine-tuning only: toggling it on incomplete
    tracks reruns the selection, not plain RV (its runs are kept), and equals a fresh run."""
    import laav.selection as S
    from laav.synthetic import occlude

    seq = occlude(synthetic.make_sequence(n_objects=1, n_frames=20, n_points=200, rng=3), 0.4, 3)
    pipe = Pipeline(seq, 2, seed=0)
    runs = []
    real = S.plain_run

    def counted(*args, **kw):
        memo, k = args[5], args[6]
        runs.append(memo is None or ("run", k) not in memo)  # True: plain RV actually runs
        return real(*args, **kw)

    monkeypatch.setattr(S, "plain_run", counted)
    res = pipe.update(rv_coarse_candidate=False)
    assert runs and not any(runs)  # every plain RV run came from the memo
    assert "coarse" not in res.voting.costs
    fresh = segment(seq, 2, LaavParams(rv_coarse_candidate=False), seed=0)
    np.testing.assert_array_equal(res.labels, fresh.labels)
    assert res.voting.costs == fresh.voting.costs


def test_preview_is_laavs_own_fine_tuning_before_plain_rv():
    """``update(preview=...)``: on a new seed the callable gets, before plain RV runs, the
    result with LAAV's informed trial alone on the selection's own stream (its trace equals
    the final result's informed trace), polished as the selection polishes it (the labels
    returned when the selection keeps "informed"); the final result is a fresh run's."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    pipe = Pipeline(seq, 3, PLAIN)
    got = []
    res = pipe.update(seed=2, preview=got.append)
    assert len(got) == 1
    pre = got[0]
    assert pre.voting.selected == "informed" and pre.voting.costs == {} and pre.seed == 2
    assert pre.coarse is res.coarse and pre.atoms is res.atoms
    assert pre.voting.n_trials == 1 and pre.voting.n_iterations < res.voting.n_iterations
    np.testing.assert_array_equal(pre.voting.informed_changed, res.voting.informed_changed)
    assert res.voting.selected == "informed"  # this scene's selection keeps LAAV's trial
    np.testing.assert_array_equal(pre.labels, res.labels)
    assert_same_result(res, segment(seq, 3, PLAIN, seed=2))


def test_preview_only_when_more_of_the_fine_tuning_is_to_come():
    """No preview where nothing waits on plain RV: a λ change (its runs are kept), the
    paper's fine-tuning (no plain RV), incomplete tracks (another path). The default runs no
    plain RV: its preview comes when its gate lets a missing-motion start through
    (tests/test_own_chain.py)."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    calls = []
    pipe = Pipeline(seq, 3, PLAIN)
    before = pipe.result
    res = pipe.update(lam=3.0, preview=calls.append)
    assert res.coarse is not before.coarse and res.params.lam == 3.0  # it did rerun
    assert calls == []
    pipe.update(n_motions=2, preview=calls.append)
    assert len(calls) == 1
    Pipeline(seq, 3, LaavParams.paper()).update(seed=1, preview=calls.append)
    hidden = synthetic.occlude(seq, 0.2, 0)
    Pipeline(hidden, 3, PLAIN).update(seed=1, preview=calls.append)
    assert len(calls) == 1
    own = Pipeline(seq, 3).update(seed=1, preview=calls.append)  # the default: no plain RV
    opened = len(own.voting.trial_iterations) > 1  # (a start ran: here one of three)
    assert opened and len(calls) == 2 and calls[1].voting.selected == "informed"


def test_a_step_back_to_a_seed_reuses_plain_rvs_runs(monkeypatch):
    """Plain RV's runs are kept for the last few seeds: a step back (or an interrupted seed
    change) reruns only LAAV's own stages, and the result is a fresh run's."""
    import laav.selection as selection_module

    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    pipe = Pipeline(seq, 3, PLAIN)
    real = selection_module.run_trials  # (plain RV's runs beside LAAV's: laav.selection)
    plain = []

    def counting(points, C, params, rng, start=None, *a, **k):
        if start is None:
            plain.append(1)
        return real(points, C, params, rng, start, *a, **k)

    monkeypatch.setattr(selection_module, "run_trials", counting)
    pipe.update(seed=1)
    assert plain  # a new seed: plain RV runs
    for s in (2, 3, 4, 5):
        pipe.update(seed=s)
    del plain[:]
    back = pipe.update(seed=3)  # one of the last four
    assert plain == []
    pipe.update(seed=1)  # five seeds back: no longer kept
    assert plain
    monkeypatch.undo()
    assert_same_result(back, segment(seq, 3, PLAIN, seed=3))


def test_with_a_preview_the_informed_trial_and_its_polish_run_once(monkeypatch):
    import laav.selection as selection_module
    import laav.voting as voting_module

    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    pipe = Pipeline(seq, 3, PLAIN)
    real_trials, real_polished = voting_module.run_trials, selection_module.Polished
    informed, polished = [], []

    def trials(points, C, params, rng, start=None, *a, **k):
        if start is not None:
            informed.append(1)
        return real_trials(points, C, params, rng, start, *a, **k)

    class Polished(real_polished):
        def __init__(self, *a, **k):
            polished.append(1)
            super().__init__(*a, **k)

    monkeypatch.setattr(voting_module, "run_trials", trials)
    monkeypatch.setattr(selection_module, "Polished", Polished)
    got = []
    pipe.update(seed=1, preview=got.append)
    n_with = (len(informed), len(polished))
    other = Pipeline(seq, 3, PLAIN, seed=0)
    del informed[:], polished[:]
    other.update(seed=1)  # without a preview: as many of each
    assert len(got) == 1 and n_with[0] == 1 and n_with == (len(informed), len(polished))


def test_a_retry_after_an_interrupted_update_gets_its_preview():
    """An update stopped after its memo was made (here: its preview raises) leaves it
    without plain RV's runs; the next try still previews, and ends as a fresh run."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    pipe = Pipeline(seq, 3, PLAIN)

    def boom(result):
        raise RuntimeError("stop")

    with pytest.raises(RuntimeError):
        pipe.update(seed=5, preview=boom)
    assert pipe.seed == 0
    got = []
    res = pipe.update(seed=5, preview=got.append)
    assert len(got) == 1
    assert_same_result(res, segment(seq, 3, PLAIN, seed=5))


def test_a_preview_keeps_the_clear_error_for_bad_settings():
    seq = synthetic.make_sequence(n_objects=2, n_frames=12, n_points=60, rng=0)
    pipe = Pipeline(seq, 2)
    with pytest.raises(ValueError, match="rv_sample_size"):
        pipe.update(seed=1, rv_sample_size=61, preview=lambda r: None)


def test_an_update_switching_the_merge_counts_its_fine_models_as_a_fresh_run():
    seq = scene(2, 2)
    pipe = Pipeline(seq, 3, seed=0)
    for params in (LaavParams.own_chain(), LaavParams(coarse_merge="coding"), LaavParams()):
        res = pipe.update(**params.to_dict())
        assert res.multicut.n_models == params.n_fine(3) == segment(seq, 3, params).multicut.n_models


def _interrupted_update(monkeypatch, pipe, where: str, **change) -> None:
    """``pipe.update(**change)`` stopped by a KeyboardInterrupt from ``laav.pipeline``'s
    ``where`` (a stage function); the function is put back after."""
    real = getattr(pipeline_module, where)

    def stop(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline_module, where, stop)
    with pytest.raises(KeyboardInterrupt):
        pipe.update(**change)
    monkeypatch.setattr(pipeline_module, where, real)


def test_ctrl_c_during_an_update_rolls_the_pipeline_back(monkeypatch):
    """A KeyboardInterrupt (no Exception) in a stage: the pipeline keeps its settings and
    result, and the next update is a fresh run's."""
    seq = scene(1, 1)
    pipe = Pipeline(seq, 2, seed=0)
    before = pipe.result
    _interrupted_update(monkeypatch, pipe, "merge_models", seed=1)
    assert pipe.seed == 0 and pipe.result is before and pipe.params == LaavParams()
    assert_same_result(pipe.update(seed=1), segment(seq, 2, seed=1))


def test_a_sweep_over_a_selection_field_keeps_few_polished_sets():
    """Each coding_eps value scores plain RV's candidates anew; the memo keeps the sets of
    the last POLISHED_KEPT values only (it kept all: ~0.25 MB a value at 1,000 points), and
    a value asked again scores to the same result."""
    from laav.selection import POLISHED_KEPT

    seq = scene(1, 1)
    pipe = Pipeline(seq, 2, PLAIN, seed=0)
    for eps in (6.0, 7.0, 8.0, 9.0, 10.0, 11.0):
        pipe.update(coding_eps=eps)
    for memo in pipe._plain_memos.values():
        assert sum(isinstance(k, tuple) and k[:1] == ("polished",) for k in memo) <= POLISHED_KEPT
    assert_same_result(pipe.update(coding_eps=6.0),
                       segment(seq, 2, PLAIN.replace(coding_eps=6.0), seed=0))


def test_a_lambda_move_reuses_the_coarse_stages_samples_and_shortlist(monkeypatch):
    """λ enters the coarse stage only through exp(-λ d) and the unit of the joint merge's
    epipolar cost: a λ update reuses the pairwise samples and the coding shortlist of the
    present multicut (``merge_models(memo=...)``), and the result is a fresh run's, bit
    for bit; a seed or radius change (a new multicut) computes them again."""
    import laav.coarse as coarse_module

    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    calls = {"pairwise": 0, "shortlist": 0, "fits": 0, "rows": 0}
    real_pw, real_sl = coarse_module._pairwise_draws, coarse_module.shortlist
    real_fit, real_rows = coarse_module._sample_fits, coarse_module.pair_distances

    def rows(*a, **k):
        calls["rows"] += 1
        return real_rows(*a, **k)

    def pw(*a, **k):
        calls["pairwise"] += 1
        return real_pw(*a, **k)

    def sl(*a, **k):
        calls["shortlist"] += 1
        return real_sl(*a, **k)

    def fit(*a, **k):
        calls["fits"] += 1
        return real_fit(*a, **k)

    monkeypatch.setattr(coarse_module, "_pairwise_draws", pw)
    monkeypatch.setattr(coarse_module, "shortlist", sl)
    monkeypatch.setattr(coarse_module, "_sample_fits", fit)
    monkeypatch.setattr(coarse_module, "pair_distances", rows)
    pipe = Pipeline(seq, 3)
    # the joint merge decides without the pairwise votes: drawn, not fitted until read
    n_rows = calls["rows"]
    assert n_rows > 0 and calls == {"pairwise": 1, "shortlist": 1, "fits": 0, "rows": n_rows}
    n = pipe.result.multicut.n_models
    assert pipe.result.coarse.pairwise_vote.shape == (n, n)
    assert calls == {"pairwise": 1, "shortlist": 1, "fits": 1, "rows": n_rows}
    for lam in (3.0, 0.7, 2.0):
        before = dict(calls)
        res = pipe.update(lam=lam)
        res.coarse.pairwise_vote  # noqa: B018 - read: the samples' fits are the memo's
        assert calls == before, lam  # nothing computed again (the joint merge's fits too)
        fresh = segment(seq, 3, LaavParams(lam=lam), seed=0)
        calls["fits"] -= 1  # the fresh run's own fits, once its votes are read below
        calls["rows"] = before["rows"]  # and its own joint-merge fits
        assert_same_result(res, fresh)
        for f in ("pairwise_vote", "epipolar_distance"):
            assert np.array_equal(getattr(res.coarse, f), getattr(fresh.coarse, f)), f
        for f in ("fundamental", "points", "distance", "frames"):
            assert np.array_equal(getattr(res.coarse.vote_samples, f),
                                  getattr(fresh.coarse.vote_samples, f), equal_nan=f != "points"), f
        assert res.coarse.shortlist.score.tolist() == fresh.coarse.shortlist.score.tolist()
    assert calls == {"pairwise": 4, "shortlist": 4, "fits": 1, "rows": n_rows}  # + 3 fresh runs
    pipe.update(seed=1)
    assert calls["pairwise"] == 5 and calls["shortlist"] == 5 and calls["fits"] == 1
    assert calls["rows"] > n_rows  # a new multicut: fitted again
    before = dict(calls)
    res = pipe.update(lam=3.0)
    assert calls == before
    assert_same_result(res, segment(seq, 3, LaavParams(lam=3.0), seed=1))


def test_an_interrupted_update_keeps_the_coarse_memo_of_the_multicut_kept(monkeypatch):
    """A seed change stopped in the fine-tuning (after its own multicut and coarse stage
    ran) rolls back to the old stages and their coarse memo: the next λ move is a fresh
    run's, not one built on the abandoned multicut's samples."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    pipe = Pipeline(seq, 3)
    _interrupted_update(monkeypatch, pipe, "random_voting", seed=4)
    assert pipe.seed == 0
    res = pipe.update(lam=3.0)
    fresh = segment(seq, 3, LaavParams(lam=3.0), seed=0)
    assert_same_result(res, fresh)
    assert np.array_equal(res.coarse.pairwise_vote, fresh.coarse.pairwise_vote)
