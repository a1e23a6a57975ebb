"""The unit of every number nerif writes: ``metrics.json``'s keys (its ``units`` entry) and the volumes' arrays
(``reconstruction.npz``'s ``units``, the ``.vti``'s field data). ``1`` is a dimensionless number; ``text`` a name
or a sentence. The physics behind each: ``docs/physics.md``.

Each module that reports a figure declares its unit where it computes it (:func:`declare`, at import); here stand
only the convention of the names' endings (``_K`` kelvin, ``_px`` pixels, ...), the units shared by many modules
and the volumes' arrays, which several writers share.
"""
from __future__ import annotations

from typing import Mapping, Optional, Sequence

SIGMA = "1 (sigma = delta / delta_thre)"
SHARE = "1 (a share, 0 to 1)"
DEFLECTION = "rad (sigma where metrics.json has deflection_unit: the data are deflections of sigma)"

# the volumes of reconstruction.npz and .vti, on the probe grid (nx, ny, nz), and the grid's own numbers
VOLUMES = {"T": "K", "T_std": "K", "T_true": "K", "n": "1 (refractive index)", "delta": "1 (n / n0 - 1)",
           "sigma": SIGMA, "sigma_std": SIGMA, "views_seeing": "views", "mask": "1 (inside: 1)",
           "voxel_mm": "mm", "origin_mm": "mm (the first voxel's centre, x y z)", "T0": "K", "n0": "1 (refractive index)",
           "delta_thre": "1 (|delta| at T_max)"}

# a key whose name ends so has this unit, unless its module declares another
ENDINGS = (("_K", "K"), ("_px", "px"), ("_px_none", "px"), ("_px_per_view", "px"), ("_time_s", "s"), ("_s", "s"),
           ("_mm", "mm"), ("_true_mm", "mm"), ("_cm3", "cm^3"), ("_db", "dB"), ("_gib", "GiB"))


def stage_key(stage: str, figure: str = "stage") -> str:
    """``metrics.json``'s key of a training stage's ``figure`` (stage ``flow``: ``flow_stage``, its figures of the
    field it left; stage ``images``: ``images_from_iteration``, where it began), one spelling for the writer and
    every reader."""
    return f"{stage}_{figure}"


_KEYS: dict[str, str] = {}
_CONTAINERS: dict[str, str] = {}


def declare(*, text: Sequence[str] = (), containers: Optional[Mapping[str, str]] = None, **units: str) -> None:
    """Declare the units of the figures a module reports in ``metrics.json``: ``units``, key -> unit; ``text``, the
    keys that hold a name or a sentence; ``containers``, the keys that hold nested figures -> what they hold (each
    nested figure then by its own name). A key declared twice must mean the same."""
    for k, unit in {**units, **{k: "text" for k in text}}.items():
        if _KEYS.setdefault(k, unit) != unit:
            raise ValueError(f"the unit of {k} is declared twice: {_KEYS[k]!r} and {unit!r}")
    _CONTAINERS.update(containers or {})


def unit_of(key: str) -> Optional[str]:
    """The unit of ``metrics.json``'s ``key``: as its module declared it, else by the ending of its name; None for a
    key nothing declares."""
    if key in _KEYS:
        return _KEYS[key]
    for ending, unit in sorted(ENDINGS, key=lambda e: -len(e[0])):
        if key.endswith(ending):
            return unit
    return None


def metric_units(metrics: dict) -> dict:
    """The ``units`` entry of ``metrics``: every key's unit, nested keys (a camera's findings, an evaluation of
    ``history``, a stage, a frame) by their own name; ``?`` where nothing declares one (a test of a real run keeps
    it complete)."""
    names: set = set()

    def walk(obj, keyed_by_name: bool) -> None:
        if isinstance(obj, dict):
            for k, v in obj.items():
                if not keyed_by_name:
                    names.add(k)
                walk(v, k == "measurement")  # the measurement is keyed by camera names
        elif isinstance(obj, list):
            for v in obj:
                walk(v, False)

    walk(metrics, False)
    return {k: _CONTAINERS.get(k) or unit_of(k) or "?" for k in sorted(names)}
