"""Cameras against OpenCV's projections (tests/fixtures/datasets/peers), the rectifier against
`monovo camera`, the response calibration against `monovo calib response`."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import monovo

from conftest import FIXTURES, cli, cli_json


def test_projections_equal_opencv():
    peers = json.loads((FIXTURES / "peers" / "opencv_projections.json").read_text())
    assert len(peers["cases"]) == 8
    for case in peers["cases"]:
        cam = monovo.Camera.from_file(FIXTURES / case["file"], cam=case["cam"])
        got = cam.project(np.asarray(case["points"]))
        # the same tolerance as the Rust test of these numbers: well below a micro-pixel
        np.testing.assert_allclose(got, case["pixels"], rtol=0, atol=1e-6, err_msg=case["file"])


@pytest.mark.parametrize(
    "model,params",
    [
        ("pinhole", [300, 310, 319.5, 239.5]),
        ("fov", [277.5, 291.7, 312.5, 240.0, 0.897966326944875]),
        ("radtan", [458.654, 457.296, 367.215, 248.375, -0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]),
        ("equidistant", [190.97, 190.97, 254.93, 256.90, 0.0034, 0.0007, -0.0021, 0.0002]),
        ("double_sphere", [158.28, 158.24, 254.73, 256.42, -0.18, 0.59]),
        ("eucm", [380.0, 380.0, 320.0, 240.0, 0.62, 1.1]),
        ("unified", [460.0, 460.0, 320.0, 240.0, 0.9, -0.2, 0.05, 0.0, 0.0]),
    ],
)
def test_unproject_project_round_trip(model, params):
    cam = monovo.Camera(model, params, size=(640, 480))
    assert cam.model == model and cam.params == params
    u, v = np.meshgrid(np.arange(0, 640, 7.0), np.arange(0, 480, 5.0))
    px = np.column_stack([u.ravel(), v.ravel()])
    rays = cam.unproject(px)
    ok = ~np.isnan(rays).any(axis=1)
    assert ok.mean() > 0.9
    np.testing.assert_allclose(np.linalg.norm(rays[ok], axis=1), 1.0, atol=1e-12)
    back = cam.project(rays[ok] * 3.0)
    # pixels beyond a wide-angle model's image circle may have rays that do not project back
    good = ~np.isnan(back).any(axis=1)
    assert good.mean() > 0.9
    np.testing.assert_allclose(back[good], px[ok][good], atol=1e-6)
    # one point in, one point out
    assert cam.project([0.0, 0.0, 1.0]).shape == (2,)
    K = cam.K
    assert (K[0, 0], K[1, 1], K[0, 2], K[1, 2]) == tuple(params[:4])
    assert pickle.loads(pickle.dumps(cam)) == cam


def test_rectifier_equals_monovo_camera(synth_sequence):
    f = synth_sequence / "camera.txt"
    for pinhole, size in [(None, None), ("full", "320x240"), ("0.5 0.6 0.5 0.5 0", "200x150")]:
        args = [] if pinhole is None else ["--pinhole", pinhole, "--size", size]
        want = cli_json("camera", f, *args)
        r = monovo.Rectifier.from_file(f, pinhole=pinhole, size=size)
        K = r.K
        assert (K[0, 0], K[1, 1], K[0, 2], K[1, 2]) == (want["fx"], want["fy"], want["cx"], want["cy"])
        assert r.camera.size == (want["width"], want["height"])
        assert r.valid_mask.shape == (want["height"], want["width"])
    r = monovo.Rectifier.from_file(f)
    img = np.full(r.input_camera.size[::-1], 77, np.uint8)
    out = r(img)
    assert out.dtype == np.uint8 and (out[r.valid_mask] == 77).all()
    assert r(img.astype(np.uint16) * 257).dtype == np.uint16
    assert r(img.astype(np.float32)).dtype == np.float32
    with pytest.raises(monovo.FormatError):
        monovo.Camera("fisheye", [1, 2, 3, 4])
    with pytest.raises(monovo.FormatError, match="takes 5 parameters"):
        monovo.Camera("fov", [1, 2, 3, 4])


def test_response_and_vignette_files(synth_sequence):
    u = monovo.InverseResponse.from_file(synth_sequence / "pcalib.txt")
    text = [float(x) for x in (synth_sequence / "pcalib.txt").read_text().split()]
    np.testing.assert_array_equal(u.values, text)
    assert u.bits == 8 and len(u) == 256
    ramp = np.arange(256, dtype=np.uint8).reshape(16, 16)
    np.testing.assert_array_equal(u(ramp).ravel(), text)
    assert monovo.InverseResponse(u.values).to_text() == u.to_text()
    png = np.asarray(Image.open(synth_sequence / "vignette.png")).astype(np.float64)
    v = monovo.Vignette.from_file(synth_sequence / "vignette.png")
    np.testing.assert_allclose(v.values, png / png.max(), rtol=1e-6)
    with pytest.raises(monovo.FormatError, match="strictly increase"):
        monovo.InverseResponse(np.r_[u.values[:100], u.values[99], u.values[101:]])


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("sweep") / "sweep"
    cli("synth", "sweep", "-o", d, "--size", "160x128", "--frames", 24, "--png")
    return d


def test_response_calibration_equals_the_cli(sweep, tmp_path):
    out = tmp_path / "pcalib.txt"
    cli("calib", "response", sweep, "-o", out)
    want = [float(x) for x in out.read_text().split()]
    want_std = [float(x) for x in (tmp_path / "pcalib_std.txt").read_text().split()]
    cal = monovo.calibrate_response(sweep)
    assert isinstance(cal.response, monovo.InverseResponse)
    np.testing.assert_array_equal(cal.response.values, want)
    np.testing.assert_array_equal(cal.std_error, want_std)
    assert cal.frames == 24 and "std_error" in cal.keys()
    # the same frames from memory
    seq = monovo.Sequence(sweep)
    frames = [f.image for f in seq]
    mem = monovo.calibrate_response(frames, seq.exposures_ms)
    np.testing.assert_array_equal(mem.response.values, want)
    # options are the library's, by name; an unknown one is an error naming it
    opts = monovo.response_options()
    assert "max_iterations" in opts
    few = monovo.calibrate_response(sweep, options={"max_iterations": 2})
    assert few.iterations <= 2
    with pytest.raises(monovo.FormatError, match="max_iteration"):
        monovo.calibrate_response(sweep, options={"max_iteration": 2})


def test_vignette_calibration_equals_the_cli(tmp_path):
    seq = tmp_path / "wall"
    cli("synth", "vignette", "-o", seq, "--size", "160x128", "--frames", 60, "--png", "--seed", 2)
    out = tmp_path / "vignette.png"
    want = cli_json("calib", "vignette", seq, "-o", out, "--max-iterations", 8)
    cal = monovo.calibrate_vignette(seq, options={"max_iterations": 8})
    assert cal.frames == 60 and cal.frames_used == want["frames_used"]
    assert cal.vignette.shape == (128, 160) and cal.vignette.dtype == np.float32
    assert cal.std_error.shape == (128, 160) and cal.counts.shape == (128, 160)
    # the map the command writes: round(V * 65535) of the same float32 values
    png = np.asarray(Image.open(out)).astype(np.float64)
    q = np.floor((cal.vignette * np.float32(65535)).astype(np.float64) + 0.5)
    np.testing.assert_array_equal(q, png)
    assert cal.iterations == want["iterations"]
    with pytest.raises(monovo.FormatError, match="grid_size"):
        monovo.calibrate_vignette(seq, options={"grid_size": 3})
