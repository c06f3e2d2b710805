"""Reading and writing sequences: the Hopkins155 ground truth, round trips, and bad input.

Every bad input must raise :class:`laav.SequenceError` (never another exception type) with
a message that names the file (or the ``source`` given to :class:`laav.Sequence`).
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import laav
from laav import Sequence, SequenceError, load_sequence, save_sequence

HYPOTHESIS = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


# --------------------------------------------------------------------------- helpers


def _random_sequence(
    seed: int = 0,
    *,
    frames: int = 5,
    points: int = 12,
    motions: int | None = 2,
    image_size: tuple[int, int] | None = (640, 480),
    name: str = "roundtrip",
) -> Sequence:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-50.0, 700.0, size=(frames, points, 2)) + rng.standard_normal() / 3
    labels = None
    if motions is not None:
        labels = np.concatenate([np.arange(motions), rng.integers(0, motions, points - motions)])
        rng.shuffle(labels)
    return Sequence(points=pts, labels=labels, name=name, image_size=image_size)


def _write_mat(path: Path, **arrays) -> Path:
    scipy.io.savemat(str(path), arrays, do_compression=False, format="5")
    return path


def _hopkins_y(frames: int = 4, points: int = 10, seed: int = 0) -> np.ndarray:
    """A valid Hopkins-style ``y`` (3 x P x F, third row 1)."""
    rng = np.random.default_rng(seed)
    y = np.ones((3, points, frames))
    y[:2] = rng.uniform(0, 640, size=(2, points, frames))
    return y


def _assert_error_names(path, excinfo) -> None:
    assert str(path) in str(excinfo.value), f"message does not name {path}: {excinfo.value}"


def _expect_error(path) -> pytest.ExceptionInfo:
    with pytest.raises(SequenceError) as excinfo:
        load_sequence(path)
    _assert_error_names(path, excinfo)
    return excinfo


# --------------------------------------------------------------------------- Hopkins155


def _benchmark_rows(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [r for r in rows if r["in_hopkins155"] == "yes"]


@pytest.mark.hopkins
def test_hopkins_table_counts(hopkins_rows):
    bench = _benchmark_rows(hopkins_rows)
    names = [r["sequence"] for r in bench]
    assert len(bench) == 155
    assert len(set(names)) == 155
    assert "dancing" not in names
    assert Counter(int(r["num_motions"]) for r in bench) == {2: 120, 3: 35}
    assert {r["sequence"] for r in hopkins_rows if r["in_hopkins155"] == "no"} == {"dancing"}


@pytest.mark.hopkins
def test_hopkins_all_155_sequences_load(hopkins_root, hopkins_rows):
    bench = _benchmark_rows(hopkins_rows)
    problems: list[str] = []
    motions: Counter[int] = Counter()
    for row in bench:
        name = row["sequence"]
        folder = hopkins_root / name
        file = folder / f"{name}_truth.mat"
        try:
            by_folder = load_sequence(folder)
            by_file = load_sequence(file)
            by_str = load_sequence(str(file))
        except SequenceError as exc:
            problems.append(f"{name}: {exc}")
            continue
        mat = scipy.io.loadmat(str(file))
        y = mat["y"].astype(np.float64)
        expected_points = np.transpose(y[:2] / y[2], (2, 1, 0))
        expected_labels = mat["s"].astype(np.int64).ravel() - 1
        F, P = int(row["num_frames"]), int(row["num_points"])
        n_motions = int(row["num_motions"])
        motions[by_folder.n_motions] += 1
        for how, seq in (("folder", by_folder), ("file", by_file), ("str", by_str)):
            checks = {
                "name": seq.name == name,
                "n_frames": seq.n_frames == F,
                "n_points": seq.n_points == P,
                "n_motions": seq.n_motions == n_motions,
                "image_size": seq.image_size == (int(row["width"]), int(row["height"])),
                "points dtype": seq.points.dtype == np.float64,
                "points shape": seq.points.shape == (F, P, 2),
                "points values": np.array_equal(seq.points, expected_points),
                "labels dtype": seq.labels is not None and seq.labels.dtype == np.int64,
                "labels values": seq.labels is not None
                and np.array_equal(seq.labels, expected_labels),
                "labels 0-based": seq.labels is not None
                and set(np.unique(seq.labels).tolist()) == set(range(n_motions)),
            }
            bad = [k for k, ok in checks.items() if not ok]
            if bad:
                problems.append(f"{name} (via {how}): {', '.join(bad)}")
    assert not problems, "\n".join(problems)
    assert sum(motions.values()) == 155
    assert motions == {2: 120, 3: 35}


@pytest.mark.hopkins
def test_find_truth_files_covers_benchmark(hopkins_root, hopkins_rows):
    found = {p.parent.name for p in laav.find_truth_files(hopkins_root)}
    assert {r["sequence"] for r in _benchmark_rows(hopkins_rows)} <= found


@pytest.mark.hopkins
@pytest.mark.parametrize("suffix", [".npz", ".mat"])
def test_hopkins_round_trip(hopkins_root, tmp_path, suffix):
    seq = load_sequence(hopkins_root / "1R2RC")
    back = load_sequence(save_sequence(seq, tmp_path / f"1R2RC_truth{suffix}"))
    assert np.array_equal(back.points, seq.points)
    assert np.array_equal(back.labels, seq.labels)
    assert back.image_size == seq.image_size
    assert back.name == "1R2RC"


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("suffix", [".npz", ".mat"])
@pytest.mark.parametrize("with_labels", [True, False], ids=["labels", "no-labels"])
@pytest.mark.parametrize("with_size", [True, False], ids=["size", "no-size"])
def test_round_trip(tmp_path, suffix, with_labels, with_size):
    seq = _random_sequence(
        seed=4 * (suffix == ".mat") + 2 * with_labels + with_size,
        motions=3 if with_labels else None,
        image_size=(720, 480) if with_size else None,
    )
    path = save_sequence(seq, tmp_path / f"roundtrip{suffix}")
    assert path == tmp_path / f"roundtrip{suffix}"
    back = load_sequence(path)
    assert back.points.dtype == np.float64
    assert np.array_equal(back.points, seq.points)
    assert back.name == "roundtrip"
    if with_labels:
        assert back.labels is not None and back.labels.dtype == np.int64
        assert np.array_equal(back.labels, seq.labels)
        assert back.n_motions == 3
    else:
        assert back.labels is None
    if with_size:
        assert back.image_size == (720, 480)
    elif suffix == ".npz":
        assert back.image_size is None
    else:
        # Hopkins .mat files always carry width/height; without a known frame size the
        # writer stores the points' bounding size, as documented in save_sequence.
        _, xmax, _, ymax = seq.extent()
        assert back.image_size == (math.ceil(xmax), math.ceil(ymax))
    # and a second trip changes nothing more
    again = load_sequence(save_sequence(back, tmp_path / f"again{suffix}"))
    assert np.array_equal(again.points, back.points)
    assert again.image_size == back.image_size


def test_save_unknown_extension(tmp_path):
    with pytest.raises(SequenceError) as excinfo:
        save_sequence(_random_sequence(), tmp_path / "x.txt")
    _assert_error_names(tmp_path / "x.txt", excinfo)


@HYPOTHESIS
@given(
    frames=st.integers(2, 6),
    points=st.integers(8, 30),
    motions=st.one_of(st.none(), st.integers(1, 5)),
    with_size=st.booleans(),
    suffix=st.sampled_from([".npz", ".mat"]),
    seed=st.integers(0, 2**32 - 1),
)
def test_round_trip_property(tmp_path_factory, frames, points, motions, with_size, suffix, seed):
    seq = _random_sequence(
        seed,
        frames=frames,
        points=points,
        motions=motions,
        image_size=(1 + seed % 4000, 1 + seed % 3000) if with_size else None,
    )
    path = save_sequence(seq, tmp_path_factory.mktemp("rt") / f"roundtrip{suffix}")
    back = load_sequence(path)
    assert np.array_equal(back.points, seq.points)
    if motions is None:
        assert back.labels is None
    else:
        assert np.array_equal(back.labels, seq.labels)
    if with_size:
        assert back.image_size == seq.image_size


# --------------------------------------------------------------------------- bad input


def test_missing_file(tmp_path):
    _expect_error(tmp_path / "nope_truth.mat")
    _expect_error(str(tmp_path / "nope.npz"))


def test_folder_with_no_files(tmp_path):
    (tmp_path / "notes.txt").write_text("nothing here")
    _expect_error(tmp_path)


def test_folder_with_two_files(tmp_path):
    seq = _random_sequence()
    save_sequence(seq, tmp_path / "a_truth.mat")
    save_sequence(seq, tmp_path / "b_truth.mat")
    excinfo = _expect_error(tmp_path)
    assert "2" in str(excinfo.value)


def test_folder_with_one_file_loads(tmp_path):
    seq = _random_sequence()
    save_sequence(seq, tmp_path / "only_truth.mat")
    assert np.array_equal(load_sequence(tmp_path).points, seq.points)


@pytest.mark.parametrize("name", ["empty_truth.mat", "empty.npz"])
def test_empty_file(tmp_path, name):
    (tmp_path / name).write_bytes(b"")
    _expect_error(tmp_path / name)


@pytest.mark.parametrize("name", ["notes_truth.mat", "notes.npz", "notes.txt"])
def test_text_file(tmp_path, name):
    (tmp_path / name).write_text("sequence,points\n1R2RC,459\n")
    _expect_error(tmp_path / name)


def test_png_like_binary(tmp_path):
    path = tmp_path / "image_truth.mat"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(range(256)) * 4)
    _expect_error(path)


def test_npy_is_not_npz(tmp_path):
    path = tmp_path / "points.npz"
    with open(path, "wb") as fh:
        np.save(fh, _random_sequence().points)
    _expect_error(path)


def test_truncated_mat(tmp_path):
    full = save_sequence(_random_sequence(points=40), tmp_path / "full_truth.mat").read_bytes()
    path = tmp_path / "half_truth.mat"
    path.write_bytes(full[: len(full) // 2])
    _expect_error(path)


@pytest.mark.hopkins
def test_truncated_hopkins_mat(hopkins_root, tmp_path):
    full = (hopkins_root / "1R2RC" / "1R2RC_truth.mat").read_bytes()
    path = tmp_path / "1R2RC_truth.mat"
    path.write_bytes(full[: len(full) // 2])
    _expect_error(path)


@pytest.mark.parametrize("fraction", [0.1, 0.5, 0.9])
def test_truncated_npz(tmp_path, fraction):
    full = save_sequence(_random_sequence(points=40), tmp_path / "full.npz").read_bytes()
    path = tmp_path / "cut.npz"
    path.write_bytes(full[: int(len(full) * fraction)])
    _expect_error(path)


@HYPOTHESIS
@given(data=st.data())
def test_corrupted_npz_never_escapes(tmp_path_factory, data):
    # Random byte damage to a valid .npz: it either still loads or raises SequenceError.
    # (No such test for .mat: scipy's MAT reader itself can crash on damaged bytes.)
    folder = tmp_path_factory.mktemp("corrupt")
    raw = bytearray(save_sequence(_random_sequence(points=20), folder / "ok.npz").read_bytes())
    for _ in range(data.draw(st.integers(1, 5))):
        raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    path = folder / "bad.npz"
    path.write_bytes(bytes(raw))
    try:
        load_sequence(path)
    except SequenceError as exc:
        assert str(path) in str(exc)


def test_mat_without_y(tmp_path):
    path = _write_mat(tmp_path / "noy_truth.mat", x=_hopkins_y(), s=np.ones((10, 1)))
    excinfo = _expect_error(path)
    assert "'y'" in str(excinfo.value)


@pytest.mark.parametrize(
    "shape",
    [(3, 10), (10,), (4, 10, 5), (1, 10, 5), (3, 10, 5, 2), (3, 10, 1)],
    ids=str,
)
def test_mat_y_wrong_dims(tmp_path, shape):
    path = _write_mat(tmp_path / "dims_truth.mat", y=np.ones(shape))
    _expect_error(path)


@pytest.mark.parametrize(
    "value", ["text", np.array([1 + 2j] * 30).reshape(3, 10, 1)], ids=["text", "complex"]
)
def test_mat_y_not_real_numbers(tmp_path, value):
    y = value if isinstance(value, str) else np.broadcast_to(value, (3, 10, 4)).copy()
    path = _write_mat(tmp_path / "kind_truth.mat", y=y)
    _expect_error(path)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("row", [0, 1, 2], ids=["x", "y", "w"])
def test_mat_nonfinite_coordinates(tmp_path, bad, row):
    y = _hopkins_y()
    y[row, 3, 2] = bad
    path = _write_mat(tmp_path / "nonfinite_truth.mat", y=y, s=np.ones((10, 1)))
    excinfo = _expect_error(path)
    assert "NaN or infinite" in str(excinfo.value)


def test_mat_zero_homogeneous_coordinate(tmp_path):
    y = _hopkins_y()
    y[2, 0, 0] = 0.0
    _expect_error(_write_mat(tmp_path / "zero_truth.mat", y=y))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_npz_nonfinite_coordinates(tmp_path, bad):
    pts = _random_sequence().points.copy()
    pts[1, 4, 0] = bad
    path = tmp_path / "nonfinite.npz"
    np.savez(path, points=pts)
    _expect_error(path)


def test_fewer_than_8_points(tmp_path):
    _expect_error(_write_mat(tmp_path / "few_truth.mat", y=_hopkins_y(points=7)))
    np.savez(tmp_path / "few.npz", points=np.zeros((4, 7, 2)))
    _expect_error(tmp_path / "few.npz")


def test_fewer_than_2_frames(tmp_path):
    _expect_error(_write_mat(tmp_path / "one_truth.mat", y=_hopkins_y(frames=1)))
    np.savez(tmp_path / "one.npz", points=np.zeros((1, 10, 2)))
    _expect_error(tmp_path / "one.npz")


def test_label_count_mismatch(tmp_path):
    excinfo = _expect_error(
        _write_mat(tmp_path / "count_truth.mat", y=_hopkins_y(), s=np.ones((9, 1), np.uint8))
    )
    assert "9 labels for 10 points" in str(excinfo.value)
    np.savez(tmp_path / "count.npz", points=np.zeros((3, 10, 2)), labels=np.zeros(11, int))
    _expect_error(tmp_path / "count.npz")


def test_empty_motion_label(tmp_path):
    s = np.array([1, 3] * 5, np.uint8).reshape(-1, 1)  # 1-based: motion 2 has no points
    excinfo = _expect_error(_write_mat(tmp_path / "gap_truth.mat", y=_hopkins_y(), s=s))
    assert "label(s) [2]" in str(excinfo.value)  # the file's own (1-based) number
    np.savez(tmp_path / "gap.npz", points=np.zeros((3, 10, 2)), labels=np.array([0, 2] * 5))
    _expect_error(tmp_path / "gap.npz")


def test_mat_labels_must_be_one_based(tmp_path):
    s = np.array([0, 1] * 5, np.uint8).reshape(-1, 1)
    excinfo = _expect_error(_write_mat(tmp_path / "zero_truth.mat", y=_hopkins_y(), s=s))
    assert "1-based" in str(excinfo.value)


@pytest.mark.parametrize(
    "labels",
    [
        np.array([0, 1.5] * 5),
        np.array([0, np.nan] * 5),
        np.array([0, -1] * 5),
        np.array(["a"] * 10),
        np.array([0] * 9 + [10**15]),  # once made the gap check enumerate 10**15 labels
        np.array([0] * 9 + [1e300]),
        np.array([0, 1j] * 5),
    ],
    ids=["fraction", "nan", "negative", "text", "huge-int", "huge-float", "complex"],
)
def test_npz_bad_labels(tmp_path, labels):
    path = tmp_path / "labels.npz"
    np.savez(path, points=np.zeros((3, 10, 2)), labels=labels)
    _expect_error(path)


def test_npz_missing_points(tmp_path):
    path = tmp_path / "nopoints.npz"
    np.savez(path, labels=np.zeros(10, int), width=np.array(640), height=np.array(480))
    excinfo = _expect_error(path)
    assert "'points'" in str(excinfo.value)


def test_npz_object_array_is_refused(tmp_path):
    path = tmp_path / "pickled.npz"
    np.savez(path, points=np.array([None, "x"], dtype=object))
    _expect_error(path)


@pytest.mark.parametrize("width", [np.inf, np.nan, "wide", 0, -640, np.ones(2)], ids=str)
@pytest.mark.parametrize("suffix", [".npz", ".mat"])
def test_bad_image_size(tmp_path, suffix, width):
    path = tmp_path / f"size{suffix}"
    arrays = {"width": np.asarray(width), "height": np.asarray(480)}
    if suffix == ".npz":
        np.savez(path, points=np.zeros((3, 10, 2)), **arrays)
    else:
        _write_mat(path, y=_hopkins_y(), **arrays)
    _expect_error(path)


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root reads anything")
def test_unreadable_file(tmp_path):
    path = save_sequence(_random_sequence(), tmp_path / "locked.npz")
    path.chmod(0)
    try:
        _expect_error(path)
    finally:
        path.chmod(0o644)


# --------------------------------------------------------------------------- properties

_wrong_shapes = hnp.array_shapes(min_dims=0, max_dims=5, min_side=0, max_side=6).filter(
    lambda s: len(s) != 3 or s[2] != 2
)
_finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@HYPOTHESIS
@given(shape=_wrong_shapes, source=st.text(min_size=1, max_size=20))
def test_wrong_shape_always_raises_naming_source(shape, source):
    with pytest.raises(SequenceError) as excinfo:
        Sequence(points=np.zeros(shape), source=source)
    assert source in str(excinfo.value)


@HYPOTHESIS
@given(shape=_wrong_shapes)
def test_wrong_shape_in_npz_always_raises_naming_file(tmp_path_factory, shape):
    path = tmp_path_factory.mktemp("shape") / "wrong.npz"
    np.savez(path, points=np.zeros(shape))
    _expect_error(path)


@HYPOTHESIS
@given(
    shape=st.tuples(st.integers(2, 5), st.integers(8, 15)),
    data=st.data(),
)
def test_nonfinite_anywhere_always_raises(tmp_path_factory, shape, data):
    F, P = shape
    pts = data.draw(hnp.arrays(np.float64, (F, P, 2), elements=_finite))
    spots = data.draw(
        st.lists(
            st.tuples(st.integers(0, F - 1), st.integers(0, P - 1), st.integers(0, 1)),
            min_size=1,
            max_size=6,
        )
    )
    for spot in spots:
        pts[spot] = data.draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    with pytest.raises(SequenceError) as excinfo:
        Sequence(points=pts, source="<hypothesis>")
    assert "<hypothesis>" in str(excinfo.value)

    folder = tmp_path_factory.mktemp("nonfinite")
    np.savez(folder / "pts.npz", points=pts)
    _expect_error(folder / "pts.npz")

    y = np.ones((3, P, F))
    y[:2] = np.transpose(pts, (2, 1, 0))
    if data.draw(st.booleans(), label="also in w"):
        y[2, spots[0][1], spots[0][0]] = data.draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    _expect_error(_write_mat(folder / "pts_truth.mat", y=y))


@HYPOTHESIS
@given(
    shape=st.tuples(st.integers(2, 6), st.integers(8, 40)),
    data=st.data(),
)
def test_valid_arrays_always_construct(shape, data):
    F, P = shape
    dtype = data.draw(st.sampled_from([np.float64, np.float32, np.int64, np.int16]))
    elements = (
        st.integers(-30000, 30000)
        if np.issubdtype(dtype, np.integer)
        else st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False, width=32)
    )
    pts = data.draw(hnp.arrays(dtype, (F, P, 2), elements=elements))
    n_motions = data.draw(st.integers(1, min(5, P)))
    labels = np.concatenate(
        [
            np.arange(n_motions),
            data.draw(hnp.arrays(np.int64, P - n_motions, elements=st.integers(0, n_motions - 1))),
        ]
    )
    labels = data.draw(st.permutations(labels.tolist()))
    seq = Sequence(points=pts, labels=labels if data.draw(st.booleans()) else None)
    assert seq.points.dtype == np.float64 and seq.points.shape == (F, P, 2)
    assert np.array_equal(seq.points, pts.astype(np.float64))
    assert not seq.points.flags.writeable
    if seq.labels is not None:
        assert seq.labels.dtype == np.int64
        assert seq.n_motions == n_motions


def test_mat_round_trip_of_a_frame_wider_than_uint16(tmp_path):
    """Hopkins stores sizes as uint16; a panorama 70,000 px wide must still save and load."""
    seq = _random_sequence(seed=9, motions=2, image_size=(70_000, 480))
    back = load_sequence(save_sequence(seq, tmp_path / "wide.mat"))
    assert back.image_size == (70_000, 480)
    assert np.array_equal(back.points, seq.points) and np.array_equal(back.labels, seq.labels)


def test_safe_name_and_stored_name(tmp_path):
    """Names from inside files become safe base names; stored names lose control characters."""
    for raw, want in [("../../evil/x", "evil_x"), ("/etc/passwd", "etc_passwd"), ("..", "sequence"),
                      ("", "sequence"), ("cars1", "cars1"), (".bashrc", "bashrc"), ("a\\b c", "a_b_c")]:
        assert laav.safe_name(raw) == want
    assert len(laav.safe_name("x" * 1000)) == 100
    seq = _random_sequence(name="\x1b]0;owned\x07two\nlines" + "y" * 300)
    back = load_sequence(save_sequence(seq, tmp_path / "n.npz"))
    assert back.name.startswith("]0;ownedtwolines") and len(back.name) == 200
    path = tmp_path / "weird.npz"
    np.savez(path, points=seq.points, name=np.array(["a", "b"]))  # not one string: the file stem
    assert load_sequence(path).name == "weird"


# --------------------------------------------------------------------------- untrusted files


def _segfaulting_mat(path: Path) -> Path:
    """A MAT v5 file that crashes scipy's reader: the data tag of ``y`` says miCOMPRESSED."""
    save_sequence(_random_sequence(frames=6, points=40), path.with_name("seed_truth.mat"))
    b = bytearray(path.with_name("seed_truth.mat").read_bytes())
    b[b.index(b"\x01\x00\x01\x00y\x00\x00\x00") + 8] = 15  # after the name 'y': miDOUBLE -> 15
    path.write_bytes(bytes(b))
    return path


def test_mat_content_named_npz_is_parsed_in_the_child(tmp_path, monkeypatch):
    seq = _random_sequence()
    mat = save_sequence(seq, tmp_path / "real_truth.mat")
    fake = tmp_path / "looks_like.npz"
    fake.write_bytes(mat.read_bytes())
    monkeypatch.setattr(laav.io, "_read_mat_here", lambda *a: pytest.fail("MAT parsed in-process"))
    back = load_sequence(fake, isolated=True)
    np.testing.assert_array_equal(back.points, seq.points)
    np.testing.assert_array_equal(back.labels, seq.labels)


def test_a_mat_file_crashing_scipy_is_refused_in_and_out_of_process(tmp_path):
    bad = _segfaulting_mat(tmp_path / "crash.npz")
    # the file really crashes scipy's reader...
    code = "import sys, scipy.io; scipy.io.loadmat(sys.argv[1])"
    run = subprocess.run([sys.executable, "-c", code, str(bad)], capture_output=True, timeout=120)
    assert run.returncode == -signal.SIGSEGV
    # ...but its structure is checked first: refused in-process and in the child alike
    for isolated in (False, True):
        with pytest.raises(SequenceError, match=r"crash\.npz: corrupt MAT file: real part has "
                                                r"element type 15 \(byte \d+\)"):
            load_sequence(bad, isolated=isolated)


def test_a_crash_of_the_reader_child_is_a_clean_error(tmp_path, monkeypatch):
    """A crash the structure check did not foresee costs only the isolated reader's child."""
    script = tmp_path / "crashing_child.py"
    script.write_text("import os, signal, sys\nsys.stdin.readline()\nos.kill(os.getpid(), signal.SIGSEGV)\n")
    reader = laav.io._MatReader()
    monkeypatch.setattr(reader, "script", script)
    monkeypatch.setattr(laav.io, "_READER", reader)
    good = save_sequence(_random_sequence(), tmp_path / "good_truth.mat")
    with pytest.raises(SequenceError, match=r"good_truth\.mat: corrupt MAT file \(the reader "
                                            r"crashed: signal SIGSEGV\)"):
        load_sequence(good, isolated=True)
    reader.close()
    monkeypatch.undo()
    # the next file gets a fresh (real) reader
    assert laav.load_sequence_isolated(good).n_points == 12


def test_truncated_mat_and_pickle_npz_are_clean_errors_when_isolated(tmp_path):
    mat = save_sequence(_random_sequence(), tmp_path / "full_truth.mat").read_bytes()
    for cut in (130, 300, len(mat) // 2, len(mat) - 9):
        p = tmp_path / f"cut{cut}.npz"
        p.write_bytes(mat[:cut])
        with pytest.raises(SequenceError, match=f"cut{cut}.npz: "):
            load_sequence(p, isolated=True)
    marker = tmp_path / "pickle_ran"

    class Evil:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    p = tmp_path / "pickled.npz"
    np.savez(p, points=np.array([Evil(), 1], dtype=object))
    with pytest.raises(SequenceError, match="pickled.npz: .*(pickle|object)"):
        load_sequence(p, isolated=True)
    p.write_bytes(__import__("pickle").dumps(Evil()))
    with pytest.raises(SequenceError, match="pickled.npz: not a MATLAB v5"):
        load_sequence(p, isolated=True)
    assert not marker.exists()


def test_cli_and_bench_survive_a_crashing_mat(tmp_path, capsys):
    from laav import bench
    from laav.cli import main

    bad = _segfaulting_mat(tmp_path / "bad_truth.mat")
    assert main(["segment", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad_truth.mat: corrupt MAT file: real part" in err
    data = tmp_path / "data"
    for name in ("bad", "good"):
        (data / name).mkdir(parents=True)
    _segfaulting_mat(data / "bad" / "bad_truth.mat")
    save_sequence(_random_sequence(points=20), data / "good" / "good_truth.mat")
    msgs: list[str] = []
    found = bench.discover(data, log=msgs.append)
    assert [s.name for s in found] == ["good"]
    assert len(msgs) == 1 and msgs[0].startswith("skipping bad: ") and "corrupt MAT" in msgs[0]


# --------------------------------------------------------------------------- size limits


def _npz_with_headers(path: Path, members: dict, compress=False) -> Path:
    """An ``.npz`` whose members hold only ``.npy`` headers declaring ``(shape, dtype)``,
    or real arrays (ndarray values)."""
    import io as _io
    import zipfile

    from numpy.lib import format as npy

    mode = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(path, "w", mode) as zf:
        for name, spec in members.items():
            buf = _io.BytesIO()
            if isinstance(spec, np.ndarray):
                npy.write_array(buf, spec)
            else:
                shape, dtype = spec
                npy.write_array_header_1_0(
                    buf, {"descr": npy.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
                          "shape": shape})
            zf.writestr(name + ".npy", buf.getvalue())
    return path


def _peak_bytes(fn):
    import tracemalloc

    tracemalloc.start()
    try:
        fn()
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peak


def test_npz_declaring_a_huge_array_is_refused_before_reading(tmp_path):
    p = _npz_with_headers(tmp_path / "bomb.npz", {"points": ((10**6, 10**6, 2), "<f8")})
    assert p.stat().st_size < 4096
    with pytest.raises(SequenceError) as info:
        _peak_bytes(lambda: load_sequence(p))
    msg = str(info.value)
    assert str(p) in msg and "1,000,000 points exceed the limit of 20,000" in msg


def test_npz_member_over_the_byte_limit(tmp_path):
    pts = np.random.default_rng(0).uniform(0, 100, (3, 20, 2))
    p = _npz_with_headers(tmp_path / "labels.npz", {"points": pts, "labels": ((10**9,), "<i8")})
    with pytest.raises(SequenceError, match=r"declare 8,000,000,960 bytes, over the limit of "
                                            r"268,435,456 bytes") as info:
        load_sequence(p)
    assert str(p) in str(info.value)
    p2 = _npz_with_headers(tmp_path / "name.npz", {"points": pts, "name": ((), "<U100000000")})
    with pytest.raises(SequenceError, match="over the limit"):
        load_sequence(p2)


def test_compressed_npz_bomb_stays_small_in_memory(tmp_path):
    big = np.zeros((50, 20_001, 2))  # 16 MB of zeros, a few KB compressed
    p = _npz_with_headers(tmp_path / "zeros.npz", {"points": big}, compress=True)
    assert p.stat().st_size < 100_000
    del big
    box = {}

    def load():
        try:
            load_sequence(p)
        except SequenceError as exc:
            box["error"] = str(exc)

    assert _peak_bytes(load) < 2_000_000
    assert "20,001 points exceed the limit of 20,000" in box["error"]
    assert load_sequence(p, max_bytes=10**9, max_points=30_000).n_points == 20_001
    with pytest.raises(SequenceError, match="20,001 points exceed the limit of 20,000"):
        load_sequence(p, max_points=20_000)


@pytest.mark.parametrize("isolated", [False, True])
def test_mat_with_too_many_points(tmp_path, isolated):
    p = tmp_path / "many_truth.mat"
    scipy.io.savemat(str(p), {"y": np.ones((3, 21_000, 2))}, do_compression=True)
    with pytest.raises(SequenceError, match="21,000 points exceed the limit of 20,000") as info:
        load_sequence(p, isolated=isolated)
    assert str(p) in str(info.value)
    assert load_sequence(p, isolated=isolated, max_points=21_000).n_points == 21_000


def test_isolated_mat_over_the_byte_limit_is_not_read(tmp_path):
    p = tmp_path / "small_truth.mat"
    save_sequence(_random_sequence(0, points=30), p)
    with pytest.raises(SequenceError, match=r"over the limit of 1,000 bytes") as info:
        load_sequence(p, isolated=True, max_bytes=1000)
    assert str(p) in str(info.value)
    assert load_sequence(p, isolated=True).n_points == 30  # the reader still works afterwards


@pytest.mark.parametrize("bad", [0, -5, 2.5, True, "10"])
def test_bad_limits(tmp_path, bad):
    with pytest.raises(ValueError, match="max_points must be a positive integer"):
        load_sequence(tmp_path, max_points=bad)


def test_label_gaps_are_named_in_the_files_own_numbers(tmp_path):
    import scipy.io as sio

    rng = np.random.default_rng(0)
    P, F = 30, 5
    y = np.concatenate([rng.uniform(0, 100, (2, P, F)), np.ones((1, P, F))])
    s = np.r_[np.ones(10), np.full(10, 3.0), np.full(10, 3.0)]  # Hopkins: 1-based, no 2
    path = tmp_path / "gap_truth.mat"
    sio.savemat(path, {"x": y, "y": y, "s": s[:, None]})
    with pytest.raises(laav.SequenceError, match=r"variable 's' has no point with motion label\(s\) "
                                                 r"\[2\] \(1-based labels must be 1..3"):
        laav.load_sequence(path)
    with pytest.raises(laav.SequenceError, match="they look 1-based: subtract 1"):
        laav.Sequence(y[:2].transpose(2, 1, 0), np.r_[np.ones(15), np.full(15, 2)].astype(int))
