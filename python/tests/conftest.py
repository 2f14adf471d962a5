"""Fixtures of the Python package's tests: the `monovo` command built from the same crates
(MONOVO_BIN, default target/release/monovo) writes the inputs and the reference outputs,
so that every test compares the package with the command on the same files."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "tests" / "fixtures" / "datasets"


def monovo_bin() -> str:
    b = os.environ.get("MONOVO_BIN") or str(ROOT / "target" / "release" / "monovo")
    if not Path(b).is_file():
        pytest.fail(f"the monovo command is not built: {b} (cargo build --release -p monovo)")
    return b


def cli(*args, check=True) -> subprocess.CompletedProcess:
    """Runs `monovo ARGS`; its stdout, stderr and exit code."""
    p = subprocess.run([monovo_bin(), *map(str, args)], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError(f"monovo {' '.join(map(str, args))} failed:\n{p.stderr}")
    return p


def cli_json(*args) -> dict:
    return json.loads(cli(*args, "--json").stdout)


def cli_error(*args) -> str:
    """The message `monovo ARGS` prints for an error, without its `error: ` prefix."""
    p = cli(*args, check=False)
    assert p.returncode != 0, p.stdout
    line = p.stderr.strip().splitlines()[-1]
    prefix = "monovo: error: "
    assert line.startswith(prefix), line
    return line[len(prefix) :]


@pytest.fixture(scope="session")
def synth_results(tmp_path_factory) -> Path:
    """3 sequences x 2 methods x 2 directions x 3 runs of synthetic VO with known drift
    (the `feature` method fails sometimes and writes `2e9 - t` backwards)."""
    d = tmp_path_factory.mktemp("results") / "synth"
    cli("synth", "results", "-o", d, "--sequences", 3, "--runs", 3, "--frames", 600, "--seed", 4)
    return d


@pytest.fixture(scope="session")
def synth_sequence(tmp_path_factory) -> Path:
    """A benchmark-like sequence: JPEG frames in images.zip, FOV camera, pcalib, vignette."""
    d = tmp_path_factory.mktemp("seq") / "sequence_01"
    cli("synth", "sequence", "-o", d, "--size", "320x256", "--frames", 12, "--seed", 3)
    return d


@pytest.fixture(scope="session")
def synth_png_sequence(tmp_path_factory) -> Path:
    """The same as PNG frames in images.zip."""
    d = tmp_path_factory.mktemp("seqpng") / "sequence_02"
    cli("synth", "sequence", "-o", d, "--size", "320x256", "--frames", 6, "--seed", 5, "--png")
    return d


def write_png(path: Path, a: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(a).save(path)


def noise_frames(n: int, w: int, h: int, sixteen: bool, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    top = 65535 if sixteen else 255
    dtype = np.uint16 if sixteen else np.uint8
    return [rng.integers(0, top + 1, size=(h, w)).astype(dtype) for _ in range(n)]


def copy_fixture(rel: str, to: Path) -> None:
    to.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(FIXTURES / rel, to)


@pytest.fixture(scope="session")
def layouts(tmp_path_factory) -> dict:
    """Small folders in each layout monovo reads besides its own (as the CLI's tests write
    them, with the real calibration files of tests/fixtures/datasets): name -> (folder,
    frames written, timestamps in ns, exposures in ms or None)."""
    root = tmp_path_factory.mktemp("layouts")
    out = {}

    # TUM-VI's dso/camN export: 16-bit PNG, times.txt `ns t_s exposure_ms`, camchain.yaml
    d = root / "tumvi"
    ns = [1520530308199447626, 1520530308249448626, 1520530308299449626]
    exp = [1.462315, 1.5, 1.75]
    frames = noise_frames(3, 512, 512, True, 1)
    cam = d / "dso" / "cam0"
    cam.mkdir(parents=True)
    (cam / "times.txt").write_text(
        "# timestamp[ns] timestamp[s] exposure_time[ms]\n"
        + "".join(f"{n} {n // 10**9}.{n % 10**9:09d} {e}\n" for n, e in zip(ns, exp))
    )
    copy_fixture("calib/dm-vio__tumvi_calib__camera02.txt", cam / "camera.txt")
    copy_fixture("calib/dm-vio__tumvi_calib__camchain.yaml", d / "dso" / "camchain.yaml")
    for n, f in zip(ns, frames):
        write_png(cam / "images" / f"{n}.png", f)
    out["tum-vi-dso"] = (d, frames, ns, exp)

    # EuRoC / ASL: mav0/cam0/data/<ns>.png, data.csv, sensor.yaml, exposure.csv
    d = root / "euroc"
    ns = [1403636579763555584, 1403636579813555456, 1403636579863555584]
    exp = [5.0, 5.25, 5.5]
    frames = noise_frames(3, 752, 480, False, 2)
    c = d / "mav0" / "cam0"
    for n, f in zip(ns, frames):
        write_png(c / "data" / f"{n}.png", f)
    (c / "data.csv").write_text(
        "#timestamp [ns],filename\n" + "".join(f"{n},{n}.png\n" for n in ns)
    )
    (c / "exposure.csv").write_text(
        "#timestamp [ns],exposure [ns]\n"
        + "".join(f"{n},{int(e * 1e6)}\n" for n, e in zip(ns, exp))
    )
    copy_fixture("calib/scratch_slam__mav0__cam0__sensor.yaml", c / "sensor.yaml")
    out["euroc-asl"] = (d, frames, ns, exp)

    # 4Seasons: undistorted_images/cam0/<ns>.png, times.txt with more rows than images
    d = root / "4seasons"
    copy_fixture(
        "heads/dm-vio-python-tools__4seasons_office_2020-03-24_17-36-22__times.head.txt",
        d / "times.txt",
    )
    copy_fixture(
        "calib/dm-vio__4seasons_calib__undistorted_calib304.txt",
        d / "calibration" / "undistorted_calib_0.txt",
    )
    rows = {
        int(line.split()[0]): float(line.split()[2])
        for line in (d / "times.txt").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    }
    ns = [1585067782140857088, 1585067782206857216]
    frames = noise_frames(2, 800, 400, False, 3)
    for n, f in zip(ns, frames):
        write_png(d / "undistorted_images" / "cam0" / f"{n}.png", f)
    out["4seasons"] = (d, frames, ns, [rows[n] for n in ns])

    # KITTI odometry: sequences/XX/image_0/%06d.png, times.txt in seconds, calib.txt
    d = root / "kitti" / "sequences" / "00"
    copy_fixture("heads/kitti__sequences_00__calib.head.txt", d / "calib.txt")
    frames = noise_frames(2, 1241, 376, False, 4)
    for i, f in enumerate(frames):
        write_png(d / "image_0" / f"{i:06d}.png", f)
    (d / "times.txt").write_text("0.000000e+00\n1.037359e-01\n")
    out["kitti"] = (d, frames, [0, 103_735_900], None)

    # TUM RGB-D / ETH3D: rgb.txt, rgb/<t>.png, calibration.txt
    d = root / "tumrgbd"
    d.mkdir()
    names = ["1305031102.175304", "1305031102.211214"]
    (d / "rgb.txt").write_text(
        "# color images\n# timestamp filename\n"
        + "".join(f"{n} rgb/{n}.png\n" for n in names)
    )
    (d / "calibration.txt").write_text("726.28741455078 726.28741455078 354.6496887207 186.46566772461\n")
    frames = noise_frames(2, 739, 458, False, 5)
    for n, f in zip(names, frames):
        write_png(d / "rgb" / f"{n}.png", f)
    out["tum-rgbd"] = (d, frames, [1305031102175304000, 1305031102211214000], None)
    return out
