"""The line a run prints last: its headline figures as a typed record (:class:`Headline`), and that record in one
line (:func:`summary_line`), each figure named as in ``metrics.json``."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Optional

from nerif.units import stage_key


@dataclass(frozen=True)
class StageChoice:
    """Which field the held-out views kept where a run fitted the flow's deflections, then the images.

    Attributes:
        kept: ``images`` or ``flow``.
        images, flow: each field's held-out misfit, in ``unit``.
        unit: ``% of full range`` (the held-out images' residual), else that of the held-out deflections or
            displacements (``px`` or ``sigma``).
    """

    kept: str
    images: float
    flow: float
    unit: str


@dataclass(frozen=True)
class Headline:
    """A finished run's headline figures, or a series' means: each named and in the unit of ``metrics.json``
    (:mod:`nerif.units`), None where the run has none (or it is not a number: a PSNR with no deflection seen).

    ``deflection_unit`` is that of ``deflection_rmse`` and ``heldout_deflection_rmse``: ``rad``, or ``sigma`` where
    no temperature is inferred (:attr:`nerif.physics.Ambient.deflection_unit`). ``measured``: deflections measured
    from images, whose scale (and the temperatures') the rig's distances to the background set.
    """

    deflection_unit: str
    deflection_rmse: float
    iterations: int
    wall_time_s: float
    total_time_s: float
    ms_per_iteration: float
    measured: bool = False
    temperature_rmse_K: Optional[float] = None
    temperature_rmse_flame_K: Optional[float] = None
    T_peak_K: Optional[float] = None
    T_std_at_peak_K: Optional[float] = None
    T_peak_interval_K: Optional[tuple] = None
    T_peak_field_K: Optional[float] = None
    resolution_mm: Optional[float] = None
    T_peak_position_mm: Optional[tuple] = None
    T_peak_true_K: Optional[float] = None
    T_peak_error_K: Optional[float] = None
    flame_volume_cm3: Optional[float] = None
    flame_volume_above_K: Optional[float] = None
    flame_volume_interval_cm3: Optional[tuple] = None
    flame_volume_true_cm3: Optional[float] = None
    heldout_explained: Optional[float] = None
    heldout_deflection_rmse: Optional[float] = None
    heldout_psnr_db: Optional[float] = None
    heldout_displacement_rmse_px: Optional[float] = None
    heldout_displacement_psnr_db: Optional[float] = None
    heldout_photometric_rmse: Optional[float] = None
    heldout_photometric_rmse_flow: Optional[float] = None
    heldout_photometric_rmse_none: Optional[float] = None
    stages: Optional[StageChoice] = None
    data_term_kept: Optional[str] = None
    T_std_median_flame_K: Optional[float] = None
    warnings: tuple = ()

    @classmethod
    def of(cls, metrics: dict, deflection_unit: str) -> "Headline":
        """The headline of ``metrics`` (a run's ``metrics.json`` figures, or a series' means), whose deflections
        are in ``deflection_unit``."""
        def value(v):
            if isinstance(v, float) and not math.isfinite(v):
                return None
            return tuple(v) if isinstance(v, list) else v

        named = {f.name for f in fields(cls)} - {"deflection_unit", "measured", "stages", "warnings"}
        out = {k: value(metrics[k]) for k in named if metrics.get(k) is not None}
        return cls(deflection_unit=deflection_unit, measured=bool(metrics.get("measurement")),
                   stages=_stages(metrics, deflection_unit), warnings=tuple(metrics.get("warnings", ())), **out)


def _stages(m: dict, deflection_unit: str) -> Optional[StageChoice]:
    """The held-out views' choice between the flow's field and the images' (``metrics.json``'s stage figures)."""
    flow, images = m.get(stage_key("flow")), m.get(stage_key("images"))
    if not (flow and images):
        return None
    if "heldout_image_misfit" in images and "heldout_image_misfit" in flow:
        return StageChoice(m["data_term_kept"], 100 * images["heldout_image_misfit"],
                           100 * flow["heldout_image_misfit"], "% of full range")
    return StageChoice(m["data_term_kept"], images["heldout_misfit"], flow["heldout_misfit"],
                       "sigma" if deflection_unit == "sigma" else "px")


def temperature_words(h: Headline) -> str:
    """The summary line's temperatures: the peak (+- one standard deviation where estimated) and where it is, the
    true peak and the peak's error where a truth is known, and the flame's volume."""
    std = f" +- {h.T_std_at_peak_K:.0f} K" if h.T_std_at_peak_K is not None else " K"
    if h.T_peak_interval_K is not None:  # the peak's own interval (nerif.metrics.reported_intervals)
        std = " K (2 std: {:.0f}-{:.0f})".format(*h.T_peak_interval_K)
    if h.T_peak_field_K is not None and h.resolution_mm is not None:
        std = f"{std} read through {h.resolution_mm:.2f} mm of resolution (the field's {h.T_peak_field_K:.0f} K)"
    at = f" at ({', '.join(f'{c:.1f}' for c in h.T_peak_position_mm)}) mm" if h.T_peak_position_mm else ""
    true = f" (true {h.T_peak_true_K:.0f} K, {h.T_peak_error_K:+.0f} K)" if h.T_peak_true_K is not None else ""
    volume = ""
    if h.flame_volume_cm3 is not None and h.flame_volume_above_K is not None:
        spread = (" (2 std: {:.3g}-{:.3g})".format(*h.flame_volume_interval_cm3)
                  if h.flame_volume_interval_cm3 is not None else "")
        volume = f", {h.flame_volume_cm3:.3g} cm3{spread} above {h.flame_volume_above_K:.0f} K" + (
            f" (true {h.flame_volume_true_cm3:.3g})" if h.flame_volume_true_cm3 is not None else "")
    return f"peak T {h.T_peak_K:.0f}{std}{at}{true}{volume}"


def heldout_words(h: Headline) -> str:
    """The summary line's held-out figures: the share of its displacements explained, its deflections' and
    displacements' errors and PSNR, and its images' residual."""
    def psnr(db: Optional[float]) -> str:
        return f"PSNR {db:.1f} dB" if db is not None else "PSNR undefined (no deflection seen)"

    held = [f"{100 * h.heldout_explained:.0f} % of its displacements explained"] \
        if h.heldout_explained is not None else []
    held.append(f"deflection RMSE {h.heldout_deflection_rmse:.3g} {h.deflection_unit}, {psnr(h.heldout_psnr_db)}")
    if h.heldout_displacement_rmse_px is not None:
        held.append(f"displacement RMSE {h.heldout_displacement_rmse_px:.3g} px, "
                    f"{psnr(h.heldout_displacement_psnr_db)}")
    if h.heldout_photometric_rmse is not None:
        ref = (f" (the flow's {100 * h.heldout_photometric_rmse_flow:.2f} %, none "
               f"{100 * h.heldout_photometric_rmse_none:.2f} %)" if h.heldout_photometric_rmse_flow is not None else "")
        held.append(f"image residual {100 * h.heldout_photometric_rmse:.2f} % of full range{ref}")
    return "held out: " + "; ".join(held)


def summary_line(h: Headline, out_dir: Path, prefix: str = "") -> str:
    """One line of the run's headline figures ``h``, each named as in ``metrics.json`` (after ``prefix``)."""
    parts = []
    if h.temperature_rmse_K is not None:
        flame = f" (flame {h.temperature_rmse_flame_K:.1f} K)" if h.temperature_rmse_flame_K is not None else ""
        parts.append(f"T RMSE {h.temperature_rmse_K:.1f} K{flame}")
    if h.T_peak_K is not None:
        parts.append(temperature_words(h))
    scale = (" (its scale and the temperatures' set by the rig's distances to the background, which no image checks)"
             if h.deflection_unit == "rad" and h.measured else "")  # measured from images: a lever arm the user gave
    parts.append(f"deflection RMSE {h.deflection_rmse:.3g} {h.deflection_unit}{scale}")
    if h.heldout_deflection_rmse is not None:
        parts.append(heldout_words(h))
    if h.stages is not None:  # the held-out views chose between the flow's field and the images'
        s = h.stages
        whose = "the images'" if s.kept == "images" else "the flow's"
        if s.unit == "% of full range":
            parts.append(f"kept {whose} field (held-out image residual: images {s.images:.3g}, flow {s.flow:.3g} % of "
                         "full range)")
        else:
            parts.append(f"kept {whose} field (held out: images {s.images:.3g}, flow {s.flow:.3g} {s.unit})")
    elif h.data_term_kept:  # a series: how often each was kept
        parts.append(f"field kept: {h.data_term_kept}")
    if h.T_std_median_flame_K is not None:
        parts.append(f"uncertainty in the flame {h.T_std_median_flame_K:.0f} K median (1 std)")
    parts += [f"WARNING: {w}" for w in h.warnings]
    resumed = h.wall_time_s > h.total_time_s  # training of earlier sessions counts, this process's time not
    parts.append(f"{h.iterations} it: {h.wall_time_s:.0f} s training{' over every session' if resumed else ''} "
                 f"({h.ms_per_iteration:.1f} ms/it), {h.total_time_s:.0f} s in all"
                 f"{' this session' if resumed else ''}")
    return "nerif: " + prefix + " | ".join(parts) + f" | {out_dir}"
