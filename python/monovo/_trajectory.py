"""Trajectories given to monovo: paths, N x 8 arrays ``t x y z qx qy qz qw``, and evo's
``PoseTrajectory3D`` (converted to arrays)."""

from __future__ import annotations

import os as _os
from typing import Any, Union

import numpy as _np

from ._errors import FormatError
from ._monovo import read_trajectory

PathLike = Union[str, "_os.PathLike[str]"]
TrajectoryLike = Union[PathLike, _np.ndarray, Any]


def _is_evo(x: Any) -> bool:
    return hasattr(x, "orientations_quat_wxyz") and hasattr(x, "timestamps")


def from_evo(trajectory: Any) -> _np.ndarray:
    """An evo ``PoseTrajectory3D`` as an N x 8 array ``t x y z qx qy qz qw``.

    evo stores quaternions w first (``orientations_quat_wxyz``); monovo, like the TUM format,
    w last.
    """
    q = _np.asarray(trajectory.orientations_quat_wxyz, dtype=_np.float64)
    return _np.column_stack(
        [
            _np.asarray(trajectory.timestamps, dtype=_np.float64),
            _np.asarray(trajectory.positions_xyz, dtype=_np.float64),
            q[:, [1, 2, 3, 0]],
        ]
    )


def to_evo(trajectory: TrajectoryLike) -> Any:
    """An N x 8 array ``t x y z qx qy qz qw`` (or a trajectory file, read as
    :func:`read_trajectory` reads it) as an evo ``PoseTrajectory3D`` (needs evo)."""
    from evo.core.trajectory import PoseTrajectory3D  # type: ignore[import-untyped, unused-ignore]

    if isinstance(trajectory, (str, _os.PathLike)):
        trajectory = read_trajectory(trajectory)
    a = _np.asarray(trajectory, dtype=_np.float64)
    if a.ndim != 2 or a.shape[1] != 8:
        raise FormatError(f"expected an N x 8 array `t x y z qx qy qz qw`, got shape {a.shape}")
    return PoseTrajectory3D(
        positions_xyz=a[:, 1:4].copy(),
        orientations_quat_wxyz=a[:, [7, 4, 5, 6]].copy(),
        timestamps=a[:, 0].copy(),
    )


def _trajectory_arg(x: Any) -> Any:
    return from_evo(x) if _is_evo(x) else x
