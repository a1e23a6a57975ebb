"""The unit of every number nerif writes: ``metrics.json``'s keys (its ``units`` entry) and the volumes' arrays
(``reconstruction.npz``'s ``units``, the ``.vti``'s field data). ``1`` is a dimensionless number; ``text`` a name
or a sentence. The physics behind each: ``docs/physics.md``."""
from __future__ import annotations

from typing import Optional

SIGMA = "1 (sigma = delta / delta_thre)"
SHARE = "1 (a share, 0 to 1)"
DEFLECTION = "rad (sigma where metrics.json has deflection_unit: the data are deflections of sigma)"

# the volumes of reconstruction.npz and .vti, on the probe grid (nx, ny, nz), and the grid's own numbers
VOLUMES = {"T": "K", "T_std": "K", "T_true": "K", "n": "1 (refractive index)", "delta": "1 (n / n0 - 1)",
           "sigma": SIGMA, "sigma_std": SIGMA, "views_seeing": "views", "mask": "1 (inside: 1)",
           "voxel_mm": "mm", "origin_mm": "mm (the first voxel's centre, x y z)", "T0": "K", "n0": "1 (refractive index)",
           "delta_thre": "1 (|delta| at T_max)"}

# metrics.json: keys by name, then by the ending of the name
KEYS = {
    "deflection_rmse": DEFLECTION, "deflection_rmse_auto": DEFLECTION, "deflection_rmse_discrete": DEFLECTION,
    "heldout_deflection_rmse": DEFLECTION, "sigma_rmse": SIGMA, "sigma_std_median_flame": SIGMA,
    "sigma_relative_error": "1 (RMS of sigma - sigma_true over RMS of sigma_true, the whole box)",
    "heldout_explained": "1 (share of the held-out displacements' mean square the fit explains; 1 perfect, below 0 "
                         "worse than no flame)",
    "heldout_photometric_rmse": "1 (share of the images' full range)",
    "heldout_photometric_rmse_flow": "1 (share of the images' full range)",
    "heldout_photometric_rmse_none": "1 (share of the images' full range)",
    "heldout_misfit": "px (the held-out displacement RMSE; sigma where there is no temperature)",
    "heldout_image_misfit": "1 (share of the images' full range: the held-out image residual, both images band-passed "
                            "and the reference read as the image term compares them)",
    "chosen_by": "(what chose the field kept: held-out images or held-out displacements)",
    "ms_per_iteration": "ms", "ms_per_iteration_mean": "ms", "samples_per_second": "1/s",
    "samples_per_ray_mean": "samples", "samples_per_ray_max": "samples", "field_evaluations_per_sample": "evaluations",
    "iterations": "iterations", "iteration": "iterations", "images_from_iteration": "iterations",
    "uncertainty_member_iterations": "iterations", "uncertainty_members": "fields",
    "ray_binning": "px (sensor pixels across a ray)", "cpu_threads": "threads",
    "cpu_threads_chosen": "[iteration, threads]", "rays": "rays", "unknowns": "voxels", "frames": "(one row a frame)",
    "n_frames": "frames", "frames_finished": "frames", "time_s": "s", "frame": "(index)",
    "box_at_cold_bound": SHARE, "flame_at_prior_bound": SHARE, "rays_skipped_fraction": SHARE,
    "uncertainty_coverage_1sigma": SHARE, "uncertainty_coverage_2sigma": SHARE,
    "uncertainty_coverage_2sigma_core": SHARE, "uncertainty_spearman": "1 (rank correlation)",
    "uncertainty_ause": "1 (area under the sparsification error, of sigma)", "uncertainty_scale": "1 (factor)",
    "uncertainty_spread_median": SIGMA, "relative_residual": "1 (|r| / |b|)", "lam": "1 (weight)",
    "occluded_true": SHARE, "valid_fraction": SHARE, "clipped": SHARE, "saturated": SHARE, "occluded": SHARE,
    "rejected": SHARE, "unmeasured": SHARE, "noise": "1 (share of full scale, each exposure)",
    "image_noise": "1 (share of full scale, each exposure)", "reference_noise": "1 (share of full scale)",
    "difference_rms": "1 (share of full scale)", "texture_ratio": "1 (ratio)", "flow_factor": "1 (factor)",
    "exposures": "exposures", "from_cache": "text (true: read from the cache)",
    "flame_volume_cm3": "cm^3", "flame_volume_true_cm3": "cm^3", "shake_px_max": "px (of the full sensor)",
}
ENDINGS = (("_K", "K"), ("_px", "px"), ("_px_none", "px"), ("_px_per_view", "px"), ("_time_s", "s"), ("_s", "s"),
           ("_mm", "mm"), ("_true_mm", "mm"), ("_cm3", "cm^3"), ("_db", "dB"), ("_gib", "GiB"))
TEXT = ("solver", "encoder", "grad", "device", "data_term", "data_term_kept", "temperature_note", "deflection_unit",
        "warnings", "ambient_faces", "flame_crosses_faces", "projector", "regularizer", "uncertainty",
        "uncertainty_scale_from", "note", "history_note", "folder", "warm_start", "sampler", "mask", "error", "frame_folder")


def unit_of(key: str) -> Optional[str]:
    """The unit of ``metrics.json``'s ``key``, or None for a key this table does not know."""
    if key in KEYS:
        return KEYS[key]
    if key in TEXT:
        return "text"
    for ending, unit in sorted(ENDINGS, key=lambda e: -len(e[0])):
        if key.endswith(ending):
            return unit
    return None


CONTAINERS = {"measurement": "(per camera name: its findings, each unit by its name here)",
              "history": "(the evaluations during training, each unit by its name here)",
              "flow_stage": "(the flow's field, each unit by its name here)",
              "images_stage": "(the images' field, each unit by its name here)",
              "frames": "(one row a frame, each unit by its name here)"}


def metric_units(metrics: dict) -> dict:
    """The ``units`` entry of ``metrics``: every key's unit, nested keys (a camera's findings, an evaluation of
    ``history``, a stage, a frame) by their own name; ``?`` where this table does not know one (a test keeps it
    complete)."""
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
    return {k: CONTAINERS.get(k) or unit_of(k) or "?" for k in sorted(names)}
