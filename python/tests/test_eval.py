"""monovo.evaluate and evaluate_many against `monovo eval --json` on the same files: equal
to the last bit (the same Rust code; JSON writes the shortest text that reads back as the
same double)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import monovo

from conftest import cli, cli_error, cli_json

KEYS = [
    "status", "reason", "e_align", "e_s", "e_r", "e_t", "e_rmse",
    "rmse_start", "rmse_end", "poses", "poses_start", "poses_end",
]


def runs(root: Path) -> list[tuple[Path, Path]]:
    out = []
    for run in sorted((root / "results").glob("*/*/*.txt")):
        out.append((run, root / "dataset" / run.parent.name / "groundtruthSync.txt"))
    return out


def as_json(e: monovo.Evaluation) -> dict:
    """The attributes as `--json` writes them (null where infinite)."""
    d = {k: getattr(e, k) for k in KEYS}
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def text_rows(path: Path) -> np.ndarray:
    rows = [
        [float(x) for x in line.replace(",", " ").split()]
        for line in path.read_text().splitlines()
        if line.strip() and not line.lstrip().startswith("#")
    ]
    return np.asarray(rows, dtype=np.float64).reshape(-1, 8)


def test_every_run_equals_the_cli(synth_results):
    pairs = runs(synth_results)
    assert len(pairs) == 36
    statuses = set()
    for est, gt in pairs:
        want = cli_json("eval", est, "--gt", gt)
        got = monovo.evaluate(est, gt)
        assert list(want) == KEYS
        assert as_json(got) == want, est
        assert json.loads(got.to_json()) == want
        statuses.add(got.status)
    # the set has failed runs and backwards runs with 2e9 - t stamps
    assert statuses == {"ok", "failed"}


def test_arrays_paths_and_many_agree(synth_results):
    pairs = runs(synth_results)
    by_path = monovo.evaluate_many(pairs)
    one_thread = monovo.evaluate_many(pairs, threads=1)
    arrays = [(text_rows(e), text_rows(g)) for e, g in pairs]
    by_array = monovo.evaluate_many(arrays, threads=2)
    for (e, g), a, b, c, (ea, ga) in zip(pairs, by_path, one_thread, by_array, arrays):
        want = as_json(monovo.evaluate(e, g))
        assert as_json(a) == want
        assert as_json(b) == want
        assert as_json(c) == want
        assert as_json(monovo.evaluate(ea, ga)) == want
        # any float dtype and Python lists are read as float64
        assert as_json(monovo.evaluate(ea.tolist(), ga)) == want


def test_read_trajectory_is_the_file(synth_results):
    est, _ = runs(synth_results)[0]
    a = monovo.read_trajectory(est)
    assert a.shape[1] == 8 and a.dtype == np.float64
    np.testing.assert_array_equal(a, text_rows(est))


def test_evaluation_details(synth_results):
    ok = next(monovo.evaluate(e, g) for e, g in runs(synth_results) if monovo.evaluate(e, g).ok)
    assert ok.positions.shape == (ok.poses, 3)
    assert ok.times.shape == (ok.poses,)
    assert np.all(np.diff(ok.times) >= 0)
    s, e = ok.start, ok.end
    assert s.shape == (4, 4) and e.shape == (4, 4)
    # e_s = s_start / s_end from the similarities' scales
    scale = lambda m: np.cbrt(np.linalg.det(m[:3, :3]))
    assert ok.e_s == pytest.approx(scale(s) / scale(e), rel=1e-9)
    assert ok.e_s_sym == pytest.approx(max(ok.e_s, 1 / ok.e_s))
    assert "Evaluation(status='ok'" in repr(ok)


def test_failed_runs_are_results_not_errors(tmp_path):
    gt = np.array([[i, i, 0.0, 0.0, 0, 0, 0, 1] for i in range(8)], dtype=float)
    gt[:, 2] = [0, 0, 1, 1, 0, 0, 1, 1]
    empty = np.zeros((0, 8))
    r = monovo.evaluate(empty, gt)
    assert r.status == "failed" and r.reason == "the estimate has no pose"
    assert math.isinf(r.e_align) and json.loads(r.to_json())["e_align"] is None
    far = gt.copy()
    far[:, 0] += 0.5
    assert "no ground-truth row" in monovo.evaluate(far, gt).reason


def test_errors_carry_the_cli_messages(tmp_path, synth_results):
    _, gt = runs(synth_results)[0]
    bad = tmp_path / "bad.txt"
    bad.write_text("0 0 0 0 0 0 0 1\n1 0 0 0,5 0 0 0 1\n")
    with pytest.raises(monovo.FormatError) as e:
        monovo.evaluate(bad, gt)
    assert str(e.value) == cli_error("eval", bad, "--gt", gt)
    assert isinstance(e.value, ValueError) and "line 2" in str(e.value)
    missing = tmp_path / "missing.txt"
    with pytest.raises(monovo.FileError) as e:
        monovo.evaluate(missing, gt)
    assert isinstance(e.value, OSError)
    assert str(e.value) == cli_error("eval", missing, "--gt", gt)
    with pytest.raises(monovo.FormatError, match="N x 8"):
        monovo.evaluate(np.zeros((3, 7)), gt)
    with pytest.raises(monovo.FormatError, match=r"pairs\[1\]"):
        monovo.evaluate_many([(runs(synth_results)[0][0], gt), (bad, gt)])
    zero_q = np.array([[0, 0, 0, 0, 0, 0, 0, 0.0]])
    with pytest.raises(monovo.FormatError, match="quaternion is zero"):
        monovo.evaluate(zero_q, gt)
    with pytest.raises(monovo.FormatError, match="format"):
        monovo.evaluate(bad, gt, format="g2o")


def test_evo_round_trip(synth_results):
    pytest.importorskip("evo")
    from evo.core.trajectory import PoseTrajectory3D
    from evo.tools import file_interface

    est, gt = runs(synth_results)[0]
    traj = file_interface.read_tum_trajectory_file(str(est))
    a = monovo.from_evo(traj)
    np.testing.assert_array_equal(a, text_rows(est))
    back = monovo.to_evo(a)
    assert isinstance(back, PoseTrajectory3D)
    np.testing.assert_array_equal(back.orientations_quat_wxyz, traj.orientations_quat_wxyz)
    want = as_json(monovo.evaluate(est, gt))
    assert as_json(monovo.evaluate(traj, gt)) == want
    assert as_json(monovo.evaluate(monovo.to_evo(est), gt)) == want
