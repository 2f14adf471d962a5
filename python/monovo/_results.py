"""Results given as the library serialises them, with attribute access."""

from __future__ import annotations

from typing import Any

import numpy as _np

from ._monovo import InverseResponse


class _Result:
    """A result as the library serialises it, with attribute access: lists of numbers are
    numpy arrays, images (``width``, ``height``, ``data``) H x W arrays."""

    def __init__(self, data: dict):
        self._data = data
        for k, v in data.items():
            setattr(self, k, _convert(v))

    def __getattr__(self, name: str) -> Any:  # the fields, set in __init__
        raise AttributeError(f"{type(self).__name__} has no field `{name}` (keys() lists them)")

    def to_dict(self) -> dict:
        """The result as the library serialises it (JSON types; ``None`` for non-finite)."""
        return self._data

    def keys(self) -> "list[str]":
        """The result's fields."""
        return list(self._data)

    def __repr__(self) -> str:
        fields = ", ".join(
            f"{k}={v!r}" for k, v in self._data.items() if isinstance(v, (bool, int, float, str))
        )
        return f"{type(self).__name__}({fields})"


def _convert(v: Any) -> Any:
    if isinstance(v, list) and v and all(isinstance(x, (int, float)) or x is None for x in v):
        if all(isinstance(x, int) and not isinstance(x, bool) for x in v):
            return _np.asarray(v)
        return _np.asarray([_np.nan if x is None else x for x in v], dtype=_np.float64)
    if isinstance(v, dict):
        if set(v) == {"width", "height", "data"}:
            a = _np.asarray([_np.nan if x is None else x for x in v["data"]])
            if a.dtype == _np.float64:
                a = a.astype(_np.float32)
            return a.reshape(v["height"], v["width"])
        if set(v) == {"table"}:
            return InverseResponse(v["table"])
        return _Result(v)
    return v
