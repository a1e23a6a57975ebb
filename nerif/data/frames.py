"""Frames of a time-resolved dataset: which states of a changing flame a ``data`` config holds.

A dataset that can hold several frames (a capture folder with a ``frames`` list, a synthetic scene of a phantom
that changes in time) registers a lister in :data:`FRAMES` under its own name: ``(data settings) -> list of
Frame``, or None when the config asks for one steady scene. The dataset itself then builds the scene of one
frame with its ``frame`` argument: ``DATASETS.build(cfg.data, frame=k)``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from nerif.registry import Registry

FRAMES = Registry("time-resolved dataset", package="nerif.data")


@dataclass(frozen=True)
class Frame:
    """One state of the flame: its index in the dataset and its time [s]."""

    index: int
    time_s: float


def pick_frames(setting, available: Optional[int] = None) -> list[int]:
    """``data.frames`` -> frame indices: null = every one of ``available``, N = the first N, a list = those
    (distinct, increasing, each below ``available`` when that is known); one sentence otherwise."""
    if setting is None:
        if available is None:
            raise ValueError("data.frames must say how many frames (a number) or which (a list)")
        return list(range(available))
    if isinstance(setting, int) and not isinstance(setting, bool):
        if setting < 1:
            raise ValueError(f"data.frames={setting}: at least 1 frame")
        picked = list(range(setting))
    elif isinstance(setting, (list, tuple)) and setting and all(
            isinstance(k, int) and not isinstance(k, bool) for k in setting):
        picked = list(setting)
        if picked[0] < 0 or any(b <= a for a, b in zip(picked, picked[1:])):
            raise ValueError(f"data.frames={picked}: frame indices from 0, each once, in increasing order")
    else:
        raise ValueError(f"data.frames={setting}: a number of frames (e.g. 8) or a list of frame indices "
                         "(e.g. [0,1,2,3])")
    if available is not None and picked[-1] >= available:
        raise ValueError(f"data.frames={setting}: the data hold {available} frame(s), numbered 0 to {available - 1}")
    return picked

