"""A PyTorch map-style dataset of a monovo :class:`~monovo.Sequence` (needs torch, which
monovo itself does not depend on).

Each item is a dict: ``image`` (a tensor sharing the frame's numpy buffer: uint8, uint16 or
float32, H x W), ``timestamp`` (s), ``exposure_ms`` (NaN where unknown), ``index``,
``name`` and ``K`` (3 x 3 float64, the camera of the returned frames). The dataset pickles
by path and options, so that DataLoader workers each open the sequence themselves::

    from torch.utils.data import DataLoader
    from monovo.torch import FrameDataset

    data = FrameDataset("sequence_01", rectify=True, photometric=True)
    for batch in DataLoader(data, batch_size=8, num_workers=2):
        batch["image"]  # 8 x 480 x 640 float32
"""

from __future__ import annotations

import math
from typing import Any, Union

import numpy as np
import torch  # type: ignore[import-not-found, unused-ignore]
from torch.utils.data import Dataset  # type: ignore[import-not-found, unused-ignore]

from . import Sequence

__all__ = ["FrameDataset"]


class FrameDataset(Dataset):
    """The frames of ``sequence`` (a :class:`~monovo.Sequence`, or a path opened with the
    keyword ``options`` of :class:`~monovo.Sequence`) as dicts of tensors."""

    def __init__(self, sequence: Union[str, "Sequence", Any], **options: Any):
        if isinstance(sequence, Sequence):
            if options:
                raise TypeError("options apply to a path; this Sequence is already open")
            self.sequence = sequence
        else:
            self.sequence = Sequence(sequence, **options)
        cam = self.sequence.camera
        self._k = None if cam is None else np.asarray(cam.K, dtype=np.float64)

    def __len__(self) -> int:
        return len(self.sequence)

    def __getitem__(self, k: int) -> dict:
        f = self.sequence[k]
        item = {
            "image": torch.from_numpy(f.image),
            "timestamp": f.timestamp,
            "exposure_ms": math.nan if f.exposure_ms is None else f.exposure_ms,
            "index": f.index,
            "name": f.name,
        }
        if self._k is not None:
            item["K"] = torch.from_numpy(self._k.copy())
        return item
