"""monovo: the TUM monoVO benchmark's toolkit from Python.

The same crates as the ``monovo`` command, so the same exact numbers:

* :func:`evaluate`, :func:`evaluate_many`: the paper's loop-closure metrics (``e_align``,
  ``e_s``, ``e_r``, ...) of trajectory files or N x 8 arrays ``t x y z qx qy qz qw`` (also
  evo's ``PoseTrajectory3D``), as ``monovo eval --json`` computes them;
* :func:`ape`, :func:`rpe`, :func:`kitti`: the field's other metrics (APE and RPE as evo or
  the TUM RGB-D scripts compute them, the KITTI devkit's segment errors), as ``monovo ape``,
  ``monovo rpe`` and ``monovo kitti`` compute them, with their options under evo's names;
* :class:`Sequence`: a sequence folder of any layout monovo reads (monoVO/DSO, TUM-VI,
  EuRoC/ASL, 4Seasons, KITTI, TUM RGB-D) as numpy frames, raw, rectified to a pinhole, or
  photometrically corrected to float32 irradiance;
* :class:`Camera`, :class:`Rectifier`: the camera models with vectorised ``project`` and
  ``unproject``, and the rectification of ``monovo rectify``;
* :class:`InverseResponse`, :class:`Vignette`, :func:`calibrate_response`,
  :func:`calibrate_vignette`: photometric calibration with standard errors.

Errors are :class:`FormatError` (a ``ValueError``) or :class:`FileError` (an ``OSError``)
with the command's messages. docs/python.md is the guide.
"""

from __future__ import annotations

import json as _json
import os as _os
from typing import Any, Iterable, Optional, Sequence as _Seq, Tuple, Union

import numpy as _np

from ._errors import Error, FileError, FormatError
from . import _monovo
from ._monovo import (
    JPEG_DECODER,
    Camera,
    Evaluation,
    Frame,
    FrameIterator,
    InverseResponse,
    Rectifier,
    Sequence,
    Vignette,
    __version__,
    read_trajectory,
)
from ._metrics import (
    Alignment,
    ErrorStats,
    KittiLength,
    KittiResult,
    MetricResult,
    ape,
    kitti,
    rpe,
)
from ._results import _Result
from ._trajectory import PathLike, TrajectoryLike, _trajectory_arg, from_evo, to_evo

__all__ = [
    "Alignment",
    "Camera",
    "Error",
    "ErrorStats",
    "Evaluation",
    "FileError",
    "FormatError",
    "Frame",
    "FrameIterator",
    "InverseResponse",
    "JPEG_DECODER",
    "KittiLength",
    "KittiResult",
    "MetricResult",
    "Rectifier",
    "ResponseCalibration",
    "Sequence",
    "VignetteCalibration",
    "Vignette",
    "ape",
    "calibrate_response",
    "calibrate_vignette",
    "evaluate",
    "evaluate_many",
    "from_evo",
    "kitti",
    "read_trajectory",
    "response_options",
    "rpe",
    "to_evo",
    "vignette_options",
]

def evaluate(
    estimate: TrajectoryLike,
    groundtruth: TrajectoryLike,
    *,
    format: Optional[str] = None,
    times: Optional[PathLike] = None,
    cam: int = 0,
) -> Evaluation:
    """The loop-closure metrics of one run, exactly as ``monovo eval`` computes them.

    ``estimate``: a trajectory file (TUM ``t x y z qx qy qz qw``, KITTI with ``times``, EuRoC
    csv; ``format`` is guessed unless given: ``"tum"``, ``"kitti"``, ``"euroc"``), an N x 8
    array ``t x y z qx qy qz qw`` (camera-to-world), or an evo ``PoseTrajectory3D``.
    ``groundtruth``: groundtruthSync.txt or any file ``monovo eval --gt`` reads, a sequence
    folder of any layout (camera ``cam``), an N x 8 array (NaN rows outside the segments), or
    an evo trajectory.

    A run that cannot be evaluated (empty, NaN, poses without ground truth, a degenerate
    segment) is a result with ``status == "failed"``, a ``reason`` and infinite metrics;
    unusable input raises :class:`FormatError` or :class:`FileError`. The GIL is released
    while the files are read and the run is evaluated.
    """
    return _monovo.evaluate(
        _trajectory_arg(estimate), _trajectory_arg(groundtruth), format, times, cam
    )


def evaluate_many(
    pairs: Iterable[Tuple[TrajectoryLike, TrajectoryLike]],
    threads: Optional[int] = None,
    *,
    format: Optional[str] = None,
    cam: int = 0,
) -> "list[Evaluation]":
    """Evaluates many ``(estimate, groundtruth)`` pairs in parallel on ``threads`` threads
    (all cores by default) with the GIL released; each ground-truth file is read once. The
    results are in the order of ``pairs``; the first unusable input (in that order) raises,
    its message prefixed with ``pairs[i]``."""
    prepared = [(_trajectory_arg(e), _trajectory_arg(g)) for e, g in pairs]
    return _monovo.evaluate_many(prepared, threads, format, cam)


class ResponseCalibration(_Result):
    """The result of :func:`calibrate_response`: ``response`` (an :class:`InverseResponse`,
    ``U(255) = 255``), ``std_error`` (the standard error of every ``U(k)`` on that scale),
    and every other field of the library's result (iterations, convergence, the noise
    model, ... : ``keys()`` lists them). ``frames`` is the number of frames used."""

    frames: int


class VignetteCalibration(_Result):
    """The result of :func:`calibrate_vignette`: ``vignette`` (the map recommended for
    correction, H x W float32, max 1), ``raw`` (the paper's unregularised map),
    ``std_error`` and ``raw_std_error`` (per pixel), ``counts``, and every other field of the
    library's result (``keys()`` lists them). ``frames_used`` and ``frames`` count the frames
    with a plane pose and in the sequence."""

    frames_used: int
    frames: int


def response_options() -> dict:
    """The options of :func:`calibrate_response` with their defaults (data/calib.toml's
    ``[response]`` table documents them)."""
    return _json.loads(_monovo._default_options("response"))


def vignette_options() -> dict:
    """The options of :func:`calibrate_vignette` with their defaults (data/calib.toml's
    ``[vignette]`` table documents them)."""
    return _json.loads(_monovo._default_options("vignette"))


def _options_json(options: Optional[dict]) -> Optional[str]:
    if options is None:
        return None
    if not isinstance(options, dict):
        raise FormatError(f"options: expected a dict, got {type(options).__name__}")
    return _json.dumps(options)


def calibrate_response(
    sweep: Union[PathLike, _Seq[_np.ndarray]],
    exposures_ms: Optional[_Seq[float]] = None,
    *,
    options: Optional[dict] = None,
    bit_depth: Optional[int] = None,
) -> ResponseCalibration:
    """Calibrates the inverse response, as ``monovo calib response`` does.

    ``sweep``: a sequence folder of a static scene with exposures in times.txt, or a list of
    H x W frames (uint8; uint16 of ``bit_depth`` bits) with their ``exposures_ms``.
    ``options``: a dict of the library's options (:func:`response_options` lists them with
    their defaults); an unknown option is a :class:`FormatError` naming it. The GIL is
    released while the frames are read and the response is fitted.
    """
    opts = _options_json(options)
    if isinstance(sweep, (str, _os.PathLike)):
        if exposures_ms is not None:
            raise FormatError("exposures_ms: a sweep folder has its exposures in times.txt")
        text, n = _monovo._calibrate_response(_os.fspath(sweep), None, None, opts, bit_depth)
    else:
        if exposures_ms is None:
            raise FormatError("exposures_ms: frames need their exposure times (ms)")
        frames = [_np.ascontiguousarray(f) for f in sweep]
        e = _np.ascontiguousarray(exposures_ms, dtype=_np.float64)
        text, n = _monovo._calibrate_response(None, frames, e, opts, bit_depth)
    r = ResponseCalibration(_json.loads(text))
    r.frames = n
    return r


def calibrate_vignette(
    sequence: PathLike,
    *,
    pcalib: Optional[PathLike] = None,
    poses: Optional[PathLike] = None,
    marker_id: int = 213,
    bit_depth: Optional[int] = None,
    options: Optional[dict] = None,
) -> VignetteCalibration:
    """Calibrates the vignette of a sequence folder (frames of a plane with an ArUco marker,
    camera.txt, exposures), as ``monovo calib vignette`` does: plane poses from marker
    ``marker_id`` (or ``poses``, a file of ``id r11 .. r33 tx ty tz`` lines), the inverse
    response from ``pcalib`` (default: the sequence's pcalib.txt). ``options``: a dict of the
    library's options (:func:`vignette_options`)."""
    text, used, total = _monovo._calibrate_vignette(
        _os.fspath(sequence),
        None if pcalib is None else _os.fspath(pcalib),
        None if poses is None else _os.fspath(poses),
        marker_id,
        bit_depth,
        _options_json(options),
    )
    r = VignetteCalibration(_json.loads(text))
    r.frames_used = used
    r.frames = total
    return r
