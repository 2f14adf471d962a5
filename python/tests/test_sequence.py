"""monovo.Sequence: frames against an independent decoder (Pillow: PNG exactly, JPEG within
the decoders' rounding), timestamps and exposures against times.txt, rectified and
corrected frames against `monovo rectify`, every layout, pickling, the torch dataset."""

from __future__ import annotations

import io
import pickle
import sys
import types
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import monovo

from conftest import cli, cli_error, cli_json


def times_txt(seq: Path) -> list[list[float]]:
    return [
        [float(x) for x in line.split()[1:]]
        for line in (seq / "times.txt").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ]


def zip_frames(seq: Path) -> list[np.ndarray]:
    with zipfile.ZipFile(seq / "images.zip") as z:
        names = sorted(n for n in z.namelist() if n.endswith((".jpg", ".png")))
        return [np.asarray(Image.open(io.BytesIO(z.read(n)))) for n in names]


def folder_frames(d: Path) -> list[np.ndarray]:
    return [np.asarray(Image.open(p)) for p in sorted((d / "images").glob("*.png"))]


def test_frames_times_and_exposures(synth_sequence):
    seq = monovo.Sequence(synth_sequence)
    rows = times_txt(synth_sequence)
    assert len(seq) == len(rows) == 12
    assert seq.layout == "monovo" and seq.dtype == "uint8" and seq.bits == 8
    np.testing.assert_array_equal(seq.timestamps, [r[0] for r in rows])
    np.testing.assert_array_equal(seq.exposures_ms, [r[1] for r in rows])
    info = cli_json("info", synth_sequence)
    assert info["frames"] == len(seq)
    pil = zip_frames(synth_sequence)
    worst = 0
    for k, f in enumerate(seq):
        assert (f.index, f.timestamp, f.exposure_ms) == (k, rows[k][0], rows[k][1])
        assert f.name == seq.names[k]
        assert f.image.dtype == np.uint8 and f.image.shape == (256, 320)
        d = np.abs(f.image.astype(int) - pil[k].astype(int))
        worst = max(worst, d.max())
        # zune-jpeg and libjpeg round the inverse DCT differently, by a grey level at most
        assert d.mean() < 0.05, (k, d.mean())
    assert worst <= 1


def test_png_frames_equal_pillow(synth_png_sequence):
    seq = monovo.Sequence(synth_png_sequence)
    for f, want in zip(seq, zip_frames(synth_png_sequence)):
        np.testing.assert_array_equal(f.image, want)


def test_indexing_slices_and_reverse(synth_sequence):
    seq = monovo.Sequence(synth_sequence)
    frames = list(seq)
    np.testing.assert_array_equal(seq[-1].image, frames[-1].image)
    assert [f.index for f in seq[2:9:3]] == [2, 5, 8]
    assert [f.index for f in seq.frames(reverse=True)] == list(range(11, -1, -1))
    assert [f.index for f in seq.frames(3, 6, prefetch=1)] == [3, 4, 5]
    it = iter(seq)
    assert len(it) == 12
    with pytest.raises(IndexError):
        seq[12]


def test_rectified_frames_equal_the_cli(synth_sequence, tmp_path):
    out = tmp_path / "rect"
    r = cli_json("rectify", synth_sequence, "-o", out, "--compression", "none")
    seq = monovo.Sequence(synth_sequence, rectify=True)
    assert seq.size == (r["width"], r["height"])
    K = seq.camera.K
    assert (K[0, 0], K[1, 1], K[0, 2], K[1, 2]) == (r["fx"], r["fy"], r["cx"], r["cy"])
    for f, want in zip(seq, folder_frames(out)):
        np.testing.assert_array_equal(f.image, want)
    # an explicit pinhole and size, as --pinhole and --size
    out2 = tmp_path / "rect2"
    cli("rectify", synth_sequence, "-o", out2, "--pinhole", "0.5 0.6 0.5 0.5 0", "--size", "200x150")
    seq2 = monovo.Sequence(synth_sequence, pinhole=(0.5, 0.6, 0.5, 0.5), size="200x150")
    assert seq2.camera.size == (200, 150)
    for f, want in zip(seq2.frames(0, 3), folder_frames(out2)):
        np.testing.assert_array_equal(f.image, want)
    # the Rectifier of the same camera.txt gives the same pixels from the raw frames
    rect = monovo.Rectifier.from_file(synth_sequence / "camera.txt")
    np.testing.assert_array_equal(rect(monovo.Sequence(synth_sequence)[4].image), seq[4].image)


def test_photometric_frames_match_the_cli(synth_sequence, tmp_path):
    # --mask-saturated takes the command's float path: U(I) / V, then round(scale * value)
    out = tmp_path / "phot"
    r = cli_json("rectify", synth_sequence, "-o", out, "--photometric", "--mask-saturated",
                 "--depth", "16", "--compression", "none")
    scale = np.float32(r["photometric_scale"])
    seq = monovo.Sequence(synth_sequence, rectify=True, photometric=True, mask_saturated=True)
    assert seq.dtype == "float32"
    nan = 0
    for f, want in zip(seq, folder_frames(out)):
        assert f.image.dtype == np.float32
        nan += np.isnan(f.image).sum()
        # Rust's round() is half away from zero (numpy's half to even)
        got = np.floor((f.image * scale).astype(np.float64) + 0.5)
        got = np.nan_to_num(got).clip(0, 65535)
        np.testing.assert_array_equal(got, want)
    assert nan > 0  # the synthetic frames saturate
    # without masking the command interpolates through a fixed-point table (its fast path):
    # within 1.5% of the float values, 0.05% on average
    out = tmp_path / "phot_fast"
    cli("rectify", synth_sequence, "-o", out, "--photometric", "--depth", "16",
        "--compression", "none")
    seq = monovo.Sequence(synth_sequence, rectify=True, photometric=True)
    for f, want in zip(seq, folder_frames(out)):
        got = f.image * scale
        assert np.abs(got - want).max() <= 1 + 0.015 * got.max()
        assert np.abs(got - want).mean() < 5e-4 * got.mean()
    irr = monovo.Sequence(synth_sequence, rectify=True, irradiance=True)
    f, g = seq[5], irr[5]
    np.testing.assert_allclose(g.image, f.image / np.float32(f.exposure_ms), rtol=1e-6)
    # unrectified: U(I) / V on the raw grid, as the inverse response and vignette give it
    raw = monovo.Sequence(synth_sequence)[5].image
    u = monovo.InverseResponse.from_file(synth_sequence / "pcalib.txt")
    v = monovo.Vignette.from_file(synth_sequence / "vignette.png")
    want = (u(raw).astype(np.float32) / v.values).astype(np.float32)
    got = monovo.Sequence(synth_sequence, photometric=True)[5].image
    np.testing.assert_allclose(got, want, rtol=1e-6)


def test_every_layout(layouts, tmp_path):
    for name, (d, frames, ns, exposures) in layouts.items():
        seq = monovo.Sequence(d)
        info = cli_json("info", d)
        assert seq.layout == name == info["layout"], d
        assert len(seq) == len(frames) == info["frames"]
        assert list(seq.timestamps_ns) == ns
        assert info["timestamps_ns"] == [ns[0], ns[-1]]  # info gives the first and the last
        if exposures is None:
            assert np.isnan(seq.exposures_ms).all()
        else:
            np.testing.assert_array_equal(seq.exposures_ms, exposures)
        for f, want in zip(seq, frames):
            assert f.image.dtype == want.dtype
            np.testing.assert_array_equal(f.image, want)
            assert f.timestamp_ns == ns[f.index]
            assert f.exposure_ms == (None if exposures is None else exposures[f.index])
        # rectified as `monovo rectify` does, to the last bit
        out = tmp_path / f"{name}.rect"
        cli("rectify", d, "-o", out, "--pinhole", "0.5 0.6 0.5 0.5 0", "--size", "160x120",
            "--compression", "none")
        rect = monovo.Sequence(d, pinhole="0.5 0.6 0.5 0.5 0", size=(160, 120))
        for f, want in zip(rect, folder_frames(out)):
            np.testing.assert_array_equal(f.image, want)
    tumvi = monovo.Sequence(layouts["tum-vi-dso"][0])
    assert tumvi.dtype == "uint16" and tumvi.camera.model == "equidistant"


def test_pickling_reopens_by_path(synth_sequence):
    seq = monovo.Sequence(synth_sequence, pinhole="full", size=(160, 128), photometric=True)
    back = pickle.loads(pickle.dumps(seq))
    assert back.path == seq.path and back.size == (160, 128) and back.dtype == "float32"
    np.testing.assert_array_equal(back[3].image, seq[3].image)
    cam = pickle.loads(pickle.dumps(seq.camera))
    assert cam == seq.camera


def test_errors(synth_sequence, tmp_path):
    with pytest.raises(monovo.FileError):
        monovo.Sequence(tmp_path / "nothing")
    bad = tmp_path / "bad"
    bad.mkdir()
    for f in ["images.zip", "camera.txt"]:
        (bad / f).write_bytes((synth_sequence / f).read_bytes())
    rows = (synth_sequence / "times.txt").read_text().splitlines()
    (bad / "times.txt").write_text("\n".join(rows[:-1]) + "\n")
    with pytest.raises(monovo.FormatError) as e:
        monovo.Sequence(bad)
    assert str(e.value) == cli_error("info", bad)
    with pytest.raises(monovo.FormatError, match="pcalib"):
        monovo.Sequence(_without_pcalib(synth_sequence, tmp_path), photometric=True)


def _without_pcalib(seq: Path, tmp: Path) -> Path:
    d = tmp / "nopcalib"
    d.mkdir()
    for f in ["images.zip", "camera.txt", "times.txt"]:
        (d / f).write_bytes((seq / f).read_bytes())
    return d


def test_torch_dataset_without_torch_installed(synth_sequence, monkeypatch):
    """monovo.torch with a stand-in torch module (torch itself is no dependency)."""
    fake = types.ModuleType("torch")
    fake.from_numpy = lambda a: ("tensor", a)
    utils = types.ModuleType("torch.utils")
    data = types.ModuleType("torch.utils.data")
    data.Dataset = object
    fake.utils = utils
    utils.data = data
    monkeypatch.setitem(sys.modules, "torch", fake)
    monkeypatch.setitem(sys.modules, "torch.utils", utils)
    monkeypatch.setitem(sys.modules, "torch.utils.data", data)
    monkeypatch.delitem(sys.modules, "monovo.torch", raising=False)
    from monovo.torch import FrameDataset

    ds = FrameDataset(synth_sequence, rectify=True)
    assert len(ds) == 12
    item = ds[2]
    assert item["image"][0] == "tensor" and item["image"][1].shape == ds.sequence.size[::-1]
    assert item["index"] == 2 and item["exposure_ms"] > 0
    np.testing.assert_array_equal(item["K"][1], ds.sequence.camera.K)
    back = pickle.loads(pickle.dumps(ds))
    np.testing.assert_array_equal(back[2]["image"][1], item["image"][1])


def test_ground_truth_of_a_sequence(synth_sequence):
    seq = monovo.Sequence(synth_sequence)
    gt = seq.ground_truth()
    rows = np.loadtxt(synth_sequence / "groundtruthSync.txt")
    np.testing.assert_array_equal(gt, rows[:, :4])
    assert seq.files["ground_truth"] == synth_sequence / "groundtruthSync.txt"
