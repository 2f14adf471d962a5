"""monovo.ape, monovo.rpe and monovo.kitti against `monovo ape/rpe/kitti --json` on the real
trajectories of tests/fixtures/metrics (every case of peers.json, its command-line flags
turned into keyword arguments): equal to the last bit, from paths, arrays and evo
trajectories, and equal to evo's, the TUM scripts' and the KITTI devkit's own numbers within
the tolerances of crates/cli/tests/metrics.rs."""

from __future__ import annotations

import io
import json
import shutil
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import monovo

from conftest import ROOT, cli, cli_error

PEERS = json.loads((ROOT / "tests" / "fixtures" / "metrics" / "peers.json").read_text())

# the flags of peers.json as keyword arguments (evo's names)
SWITCHES = {
    "-a": ["align"],
    "-s": ["correct_scale"],
    "-as": ["align", "correct_scale"],
    "--align_origin": ["align_origin"],
    "--all_pairs": ["all_pairs"],
    "--pairs_from_reference": ["pairs_from_reference"],
}
VALUED = {
    "-r": ("pose_relation", str),
    "--n_to_align": ("n_to_align", int),
    "--t_max_diff": ("t_max_diff", float),
    "--t_offset": ("t_offset", float),
    "--sync_method": ("sync_method", str),
    "-d": ("delta", float),
    "--delta": ("delta", float),
    "-u": ("delta_unit", str),
    "-t": ("delta_tol", float),
    "--max_pairs": ("max_pairs", int),
    "--scale": ("scale", float),
}


def kwargs_of(args: list) -> dict:
    """Command-line flags as keyword arguments (a repeated option: the last wins)."""
    kw: dict = {}
    i = 0
    while i < len(args):
        a = args[i]
        if a in SWITCHES:
            kw.update({k: True for k in SWITCHES[a]})
        else:
            assert a in VALUED, f"a flag the test does not know: {a}"
            name, conv = VALUED[a]
            kw[name] = conv(args[i + 1])
            i += 1
        i += 1
    return kw


def close(a: float, b: float, rel: float, abs_: float) -> bool:
    return abs(a - b) <= rel * max(abs(a), abs(b)) + abs_


def path(rel: str) -> str:
    return str(ROOT / rel)


def as_array(p: str) -> np.ndarray:
    """A trajectory file as numbers: N x 8 TUM rows, N x 12 KITTI rows."""
    a = np.loadtxt(p, comments="#", ndmin=2)
    return monovo.read_trajectory(p) if a.shape[1] == 8 else a


def cli_results(calls: list) -> list:
    """`monovo ARGS --json` of each call on 4 threads: the object, or the error message."""

    def one(args):
        p = cli(*args, "--json", check=False)
        if p.returncode == 0:
            return json.loads(p.stdout)
        return p.stderr.strip().splitlines()[-1].removeprefix("monovo: error: ")

    with ThreadPoolExecutor(4) as ex:
        return list(ex.map(one, calls))


def without_names(d: dict) -> dict:
    return {k: v for k, v in d.items() if k not in ("reference", "estimate", "sequences")}


def test_ape_and_rpe_equal_the_cli_and_evo():
    cases = PEERS["evo"]["cases"]
    assert len(cases) >= 180
    calls, inputs = [], []
    for c in cases:
        tool = "ape" if c["tool"] == "evo_ape" else "rpe"
        fmt = "kitti" if c["id"].startswith("kitti") else "tum"
        ref, est = path(c["reference"]), path(c["estimate"])
        calls.append([tool, fmt, ref, est, *c["args"]])
        inputs.append((getattr(monovo, tool), fmt, ref, est, kwargs_of(c["args"])))
    arrays = {p: as_array(p) for _, _, r, e, _ in inputs for p in (r, e)}
    for c, want, (fn, fmt, ref, est, kw) in zip(cases, cli_results(calls), inputs):
        if "error" in c:
            with pytest.raises(monovo.FormatError) as e:
                fn(ref, est, format=fmt, **kw)
            assert str(e.value) == want, c["id"]
            continue
        got = fn(ref, est, format=fmt, **kw)
        assert got.to_dict() == want, c["id"]
        assert json.loads(got.to_json()) == want
        for k, v in c["stats"].items():
            assert close(getattr(got, k), v, 1e-9, 1e-14), (c["id"], k, getattr(got, k), v)
        assert got.errors.shape == (got.n,)
        # from arrays: the same numbers, the inputs named as evo names them
        a = fn(arrays[ref], arrays[est], **kw)
        assert without_names(a.to_dict()) == without_names(want), c["id"]
        assert (a.reference, a.estimate) == ("reference", "estimate")


def test_tum_scripts_equal_the_cli_and_the_scripts():
    cases = PEERS["tum"]["cases"]
    assert len(cases) >= 60
    calls = [
        ["ape" if c["tool"] == "tum_ate" else "rpe", "--tum", path(c["reference"]),
         path(c["estimate"]), *c["args"]]
        for c in cases
    ]
    for c, want, call in zip(cases, cli_results(calls), calls):
        fn = monovo.ape if call[0] == "ape" else monovo.rpe
        got = fn(call[2], call[3], tum=True, **kwargs_of(c["args"]))
        assert got.to_dict() == want, c["id"]
        assert got.convention == "tum"
        for k, v in c["translational"].items():
            assert close(getattr(got, k), v, 1e-9, 1e-14), (c["id"], k)
        if "rotational_deg" in c:
            assert isinstance(got.rotational_error, monovo.ErrorStats)
            for k in ["rmse", "mean", "median", "std", "min", "max"]:
                assert close(getattr(got.rotational_error, k), c["rotational_deg"][k], 1e-9, 2e-6)
        else:
            assert got.rotational_error is None


def test_kitti_equals_the_cli_and_the_devkit(tmp_path):
    for c in PEERS["kitti"]["cases"]:
        seqs = [[path(p) for p in s] for s in c["sequences"]]
        if len(seqs) == 1:
            gt, est = seqs[0]
        else:  # pooled: two folders of NN.txt
            gt, est = tmp_path / "gt", tmp_path / "est"
            for k, (g, e) in enumerate(seqs):
                for d, f in ((gt, g), (est, e)):
                    d.mkdir(exist_ok=True)
                    shutil.copy(f, d / f"{k:02}.txt")
        (want,) = cli_results([["kitti", gt, est]])
        got = monovo.kitti(gt, est)
        assert got.to_dict() == want, c["id"]
        assert got.segments == c["segments"]
        assert close(got.t_err, c["t_err"], 1e-8, 0) and close(got.r_err_rad_per_m, c["r_err"], 1e-8, 0)
        assert [x.length for x in got.lengths] == [x["length"] for x in c["lengths"]]
        for mine, theirs in zip(got.lengths, c["lengths"]):
            assert close(mine.t_err_percent / 100, theirs["t_err"], 1e-8, 0)
        if len(seqs) == 1:
            a = monovo.kitti(as_array(gt), as_array(est))
            assert without_names(a.to_dict()) == without_names(want)
            assert a.sequences == [["groundtruth", "estimate"]]
    # evo's Umeyama first, as the command's -as
    g, e = (path(p) for p in PEERS["kitti"]["cases"][0]["sequences"][0])
    (want,) = cli_results([["kitti", g, e, "-as"]])
    assert monovo.kitti(g, e, align=True, correct_scale=True).to_dict() == want


def test_result_details_and_evo_inputs(tmp_path):
    c = next(c for c in PEERS["evo"]["cases"] if c["args"] == ["-as"] and c["tool"] == "evo_ape")
    ref, est = path(c["reference"]), path(c["estimate"])
    r = monovo.ape(ref, est, align=True, correct_scale=True)
    assert r.metric == "ape" and r.convention == "evo" and r.unit == "m"
    assert r.alignment.mode == "sim3" and r.alignment.rotation.shape == (3, 3)
    assert r.alignment.translation.shape == (3,)
    np.testing.assert_allclose(r.alignment.rotation @ r.alignment.rotation.T, np.eye(3), atol=1e-12)
    assert r.compared_pose_pairs == r.n == len(r.arrays["timestamps"])
    assert "MetricResult(" in repr(r) and "rmse=" in repr(r)
    # the arrays are the ones of the command's evo result zip
    z = tmp_path / "ape.zip"
    cli("ape", ref, est, "-as", "--save_results", z)
    with zipfile.ZipFile(z) as f:
        names = [n for n in f.namelist() if n.endswith(".npy")]
        assert sorted(Path(n).stem for n in names) == sorted(r.arrays)
        for n in names:
            np.testing.assert_array_equal(np.load(io.BytesIO(f.read(n))), r.arrays[Path(n).stem])
    np.testing.assert_array_equal(r.errors, r.arrays["error_array"])
    # evo trajectories are read as arrays
    pytest.importorskip("evo")
    e = monovo.ape(monovo.to_evo(ref), monovo.to_evo(est), align=True, correct_scale=True)
    assert without_names(e.to_dict()) == without_names(r.to_dict())


def test_errors_carry_the_cli_messages(tmp_path):
    c = PEERS["evo"]["cases"][0]
    ref, est = path(c["reference"]), path(c["estimate"])
    missing = str(tmp_path / "missing.txt")
    with pytest.raises(monovo.FileError) as e:
        monovo.rpe(ref, missing)
    assert str(e.value) == cli_error("rpe", ref, missing)
    far = tmp_path / "far.txt"
    far.write_text("".join(f"{1000 + i} 0 0 {i} 0 0 0 1\n" for i in range(5)))
    with pytest.raises(monovo.FormatError) as e:
        monovo.ape(ref, far)
    assert str(e.value) == cli_error("ape", ref, far)
    k = PEERS["kitti"]["cases"]
    g04, g07 = path(k[0]["sequences"][0][0]), path("tests/fixtures/metrics/kitti_07_estimate.txt")
    with pytest.raises(monovo.FormatError) as e:
        monovo.kitti(g04, g07)
    assert str(e.value) == cli_error("kitti", g04, g07)
    # options that do not apply are refused as the command refuses them, in evo's names
    with pytest.raises(monovo.FormatError, match="tum aligns .* correct_scale"):
        monovo.ape(ref, est, tum=True, correct_scale=True)
    with pytest.raises(monovo.FormatError, match="delta_unit s: evo has no delta in seconds"):
        monovo.rpe(ref, est, delta_unit="s")
    with pytest.raises(monovo.FormatError, match="scale is the TUM RGB-D script's: add tum"):
        monovo.ape(ref, est, scale=2.0)
    with pytest.raises(monovo.FormatError, match="posyaw is an alignment of its own"):
        monovo.ape(ref, est, posyaw=True, align=True)
    with pytest.raises(monovo.FormatError, match="pose_relation `angle`: expected one of"):
        monovo.ape(ref, est, pose_relation="angle")
    with pytest.raises(monovo.FormatError, match="align: expected True or False"):
        monovo.ape(ref, est, align="yes")  # type: ignore[arg-type]
    with pytest.raises(monovo.FormatError, match="N x 8 .* N x 12"):
        monovo.ape(np.zeros((3, 7)), est)
    with pytest.raises(monovo.FormatError, match="the estimate: row 0: not a rotation"):
        monovo.kitti(np.eye(3, 4).reshape(1, 12), np.zeros((1, 12)))
    with pytest.raises(TypeError):
        monovo.ape(ref, est, delta=2)  # type: ignore[call-arg]
