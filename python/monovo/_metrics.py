"""The field's other trajectory metrics: APE and RPE as evo computes them (or the TUM RGB-D
scripts, ``tum=True``) and the KITTI devkit's segment errors, exactly as ``monovo ape``,
``monovo rpe`` and ``monovo kitti`` compute them; the keyword arguments are the commands'
options under evo's names, the results' attributes the keys of their ``--json``."""

from __future__ import annotations

import json as _json
from typing import Any, Dict, List, Optional, Union

import numpy as _np

from . import _monovo
from ._results import _Result
from ._trajectory import PathLike, TrajectoryLike, _trajectory_arg

MetricInput = Union[TrajectoryLike, _np.ndarray]


class ErrorStats(_Result):
    """Statistics of errors, as evo computes them (``std`` is the population's)."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    sse: float
    n: int


class Alignment(_Result):
    """The alignment applied to the estimate: ``p -> scale * rotation @ p + translation``."""

    mode: str
    scale: float
    rotation: _np.ndarray
    translation: _np.ndarray


class MetricResult(_Result):
    """The result of :func:`ape` or :func:`rpe`: its attributes are the keys of
    ``monovo ape/rpe --json`` (``to_dict()`` is that object, ``to_json()`` its text): evo's
    statistics at the top level (``rmse``, ``mean``, ``median``, ``std``, ``min``, ``max``,
    ``sse``, ``n``), ``metric``, ``convention`` (``evo`` or ``tum``), ``title``,
    ``pose_relation``, ``unit``, ``compared_pose_pairs``, ``alignment`` (an
    :class:`Alignment` or ``None``), ``reference`` and ``estimate`` (the paths, or
    ``"reference"``/``"estimate"`` for arrays), and with ``rpe(tum=True)``
    ``translational_error`` and ``rotational_error`` (degrees) as :class:`ErrorStats`.

    Beyond the JSON: ``arrays``, evo's result arrays by their names in its result zip
    (``error_array``, ``timestamps``, ``seconds_from_start``, ``distances_from_start``,
    ``distances``, ``alignment_transformation_sim3``, as far as they apply), and ``errors``,
    the error of each compared pose or pair (``arrays["error_array"]``)."""

    metric: str
    convention: str
    title: str
    pose_relation: str
    unit: str
    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    sse: float
    n: int
    compared_pose_pairs: int
    alignment: Optional[Alignment]
    reference: str
    estimate: str
    translational_error: Optional[ErrorStats] = None
    rotational_error: Optional[ErrorStats] = None
    arrays: Dict[str, _np.ndarray]
    errors: _np.ndarray

    def __init__(self, text: str, arrays: Dict[str, _np.ndarray]):
        super().__init__(_json.loads(text))
        self._text = text
        for k in ("translational_error", "rotational_error"):
            if self._data.get(k) is not None:
                setattr(self, k, ErrorStats(self._data[k]))
        a = self._data["alignment"]
        self.alignment = None if a is None else Alignment(a)
        if self.alignment is not None:
            self.alignment.rotation = _np.asarray(a["rotation"], dtype=_np.float64)
        self.arrays = arrays
        self.errors = arrays["error_array"]

    def to_json(self) -> str:
        """The object ``monovo ape/rpe --json`` prints, as its text."""
        return self._text


class KittiLength(_Result):
    """The errors of the segments of one length (the lengths with at least 3 segments)."""

    length: float
    t_err_percent: float
    r_err_deg_per_100m: float
    segments: int


class KittiResult(_Result):
    """The result of :func:`kitti`: its attributes are the keys of ``monovo kitti --json``
    (``to_dict()`` is that object, ``to_json()`` its text): ``t_err_percent`` and
    ``r_err_deg_per_100m`` (the means over all segments), the devkit's own ``t_err`` and
    ``r_err_rad_per_m``, ``segments``, ``lengths`` (a :class:`KittiLength` per segment
    length), ``sequences`` (``[ground truth, estimate]`` names) and ``alignment``."""

    t_err_percent: float
    r_err_deg_per_100m: float
    t_err: float
    r_err_rad_per_m: float
    segments: int
    lengths: List[KittiLength]
    sequences: List[List[str]]
    alignment: str

    def __init__(self, text: str):
        super().__init__(_json.loads(text))
        self._text = text
        self.lengths = [KittiLength(x) for x in self._data["lengths"]]

    def to_json(self) -> str:
        """The object ``monovo kitti --json`` prints, as its text."""
        return self._text


def _inputs(reference: Any, estimate: Any) -> "tuple[Any, Any]":
    return _trajectory_arg(reference), _trajectory_arg(estimate)


def ape(
    reference: MetricInput,
    estimate: MetricInput,
    *,
    format: Optional[str] = None,
    pose_relation: str = "trans_part",
    align: bool = False,
    correct_scale: bool = False,
    n_to_align: int = -1,
    align_origin: bool = False,
    posyaw: bool = False,
    t_max_diff: Optional[float] = None,
    t_offset: float = 0.0,
    sync_method: str = "nearest_time",
    t_start: Optional[float] = None,
    t_end: Optional[float] = None,
    tum: bool = False,
    scale: Optional[float] = None,
) -> MetricResult:
    """The absolute pose error as ``monovo ape`` computes it: evo's ``evo_ape``, or with
    ``tum=True`` the TUM RGB-D ``evaluate_ate.py``.

    ``reference``, ``estimate``: trajectory files (TUM, EuRoC csv, KITTI poses; recognised by
    their first line unless ``format`` is ``"tum"`` or ``"kitti"``; ``"euroc"`` is evo's
    mode, each file recognised), N x 8 arrays ``t x y z qx qy qz qw``, N x 12 arrays of KITTI
    poses (paired by row), or evo ``PoseTrajectory3D``. Note the order: the reference first,
    as evo and the command take them (:func:`evaluate` takes the estimate first).

    The options are the command's, named as evo names them: ``align`` (``-a``, SE(3)),
    ``correct_scale`` (``-s``; with ``align`` Sim(3)), ``n_to_align``, ``align_origin``,
    ``posyaw`` (4-DoF), ``pose_relation`` (``trans_part``, ``rot_part``, ``full``,
    ``angle_deg``, ``angle_rad``, ``point_distance``), ``t_max_diff`` (default 0.01 s; 0.02
    with ``tum``), ``t_offset``, ``sync_method`` (``nearest_time`` or ``interpolation``),
    ``t_start``, ``t_end``; with ``tum``: ``scale``. An option that does not apply raises
    :class:`FormatError`, as the command refuses it. The GIL is released while the files are
    read and the metric computed.
    """
    options = dict(locals())
    del options["reference"], options["estimate"], options["format"]
    text, arrays = _monovo._ape(*_inputs(reference, estimate), format, **options)
    return MetricResult(text, arrays)


def rpe(
    reference: MetricInput,
    estimate: MetricInput,
    *,
    format: Optional[str] = None,
    pose_relation: str = "trans_part",
    delta: float = 1.0,
    delta_unit: Optional[str] = None,
    delta_tol: float = 0.1,
    all_pairs: bool = False,
    pairs_from_reference: bool = False,
    align: bool = False,
    correct_scale: bool = False,
    n_to_align: int = -1,
    align_origin: bool = False,
    posyaw: bool = False,
    t_max_diff: Optional[float] = None,
    t_offset: float = 0.0,
    sync_method: str = "nearest_time",
    t_start: Optional[float] = None,
    t_end: Optional[float] = None,
    tum: bool = False,
    max_pairs: Optional[int] = None,
    scale: Optional[float] = None,
) -> MetricResult:
    """The relative pose error as ``monovo rpe`` computes it: evo's ``evo_rpe``, or with
    ``tum=True`` the TUM RGB-D ``evaluate_rpe.py``.

    The inputs and the options of :func:`ape`, and: ``delta`` (default 1) in ``delta_unit``
    (evo: ``f`` frames, the default, ``m``, ``d``, ``r``; with ``tum`` also ``s``, its
    default), ``delta_tol`` (relative, with ``all_pairs``), ``all_pairs``,
    ``pairs_from_reference``; ``pose_relation`` also ``point_distance_error_ratio``. With
    ``tum``: pairs a fixed delta apart, or every pair (at most ``max_pairs``, 10,000, drawn as
    the script does) with ``all_pairs``; ``translational_error`` and ``rotational_error``
    (degrees) in the result.
    """
    options = dict(locals())
    del options["reference"], options["estimate"], options["format"]
    text, arrays = _monovo._rpe(*_inputs(reference, estimate), format, **options)
    return MetricResult(text, arrays)


def kitti(
    groundtruth: Union[PathLike, _np.ndarray],
    estimate: Union[PathLike, _np.ndarray],
    *,
    align: bool = False,
    correct_scale: bool = False,
    n_to_align: int = -1,
    align_origin: bool = False,
    posyaw: bool = False,
) -> KittiResult:
    """The KITTI odometry devkit's segment errors as ``monovo kitti`` computes them
    (translation in percent, rotation in degrees per 100 m over segments of 100..800 m, in
    the devkit's single precision).

    ``groundtruth``, ``estimate``: KITTI pose files, two folders of ``NN.txt`` (every estimate
    with a ground truth of the same name, pooled), or N x 12 arrays of KITTI poses (N x 8
    ``t x y z qx qy qz qw`` too); poses pair by row. The devkit does not align; ``align``,
    ``correct_scale`` (evo's Umeyama over all poses), ``n_to_align``, ``align_origin`` and
    ``posyaw`` may be given for monocular runs.
    """
    options = dict(locals())
    del options["groundtruth"], options["estimate"]
    return KittiResult(_monovo._kitti(groundtruth, estimate, **options))
