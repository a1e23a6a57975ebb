"""How well the per-voxel uncertainty (the default ``uncertainty=auto``: an ensemble where a view is held out; or
``--method ensemble|laplace``) and the intervals of the peak, its position and the flame volume describe the error,
on scenes it was not tuned on (issues 48, 57, 59).

    python benchmarks/uncertainty.py                                      # the 13 shared captures
    python benchmarks/uncertainty.py --captures bunsen --families plumes --seeds 0 --noise 0
    python benchmarks/uncertainty.py --set uncertainty.members=6          # other settings of the estimator
    python benchmarks/uncertainty.py --resume                             # read back the runs already finished
    python benchmarks/uncertainty.py --method laplace                     # the Laplace approximation instead

Scenes: the shared independent captures (``benchmarks/independent.py``'s ``CAPTURES`` and overrides, rays one voxel
apart) and, where named, the analytic flame families of :mod:`nerif.data.families` (each ``--seeds`` draw, clean
and with ``--noise``: ``benchmarks/families.py``'s datasets). Each scene is one ``python -m nerif`` with every
default and ``uncertainty=<--method>``; the members (or the drawn fields) leave the trained field as it was (the
reconstruction and its error are the run's without uncertainty: a test checks it), so the run's time less the
members' (``uncertainty_time_s``) is the single run's. Columns, over the truth's flame voxels (|sigma| above 5 % of
its peak): coverage at 1 and 2 standard deviations, at 2 in the hot core (the hottest 5 %), AUSE and a random
order's AUSE, the calibration error (the mean gap between nominal and observed coverage at 10 levels), Spearman's
rank correlation of sigma_std and |error|, the sigma error, the calibration's scale, whether the true peak, its
position and the flame volume lie in their reported intervals (1 or 0), and the wall time over the single run's.
Writes ``uncertainty.json`` and ``uncertainty.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402
from independent import CAPTURES, capture_overrides  # noqa: E402
from same_figures import REPO  # noqa: E402

from nerif.data.families import FAMILIES, write_dataset  # noqa: E402
from nerif.export import write_json  # noqa: E402

KEYS = ("uncertainty_coverage_1sigma", "uncertainty_coverage_2sigma", "uncertainty_coverage_2sigma_core",
        "uncertainty_ause", "uncertainty_ause_random", "uncertainty_calibration_error", "uncertainty_spearman",
        "sigma_relative_error", "uncertainty_scale",
        "uncertainty_scale_from", "T_std_median_flame_K", "T_peak_K", "T_std_at_peak_K", "uncertainty_time_s",
        "total_time_s", "T_peak_true_K", "T_peak_interval_K", "T_peak_in_interval", "T_peak_position_in_interval",
        "flame_volume_cm3", "flame_volume_true_cm3", "flame_volume_interval_cm3", "flame_volume_in_interval")
COLUMNS = (("cover 1s", "uncertainty_coverage_1sigma"), ("cover 2s", "uncertainty_coverage_2sigma"),
           ("core 2s", "uncertainty_coverage_2sigma_core"), ("AUSE", "uncertainty_ause"),
           ("AUSE random", "uncertainty_ause_random"), ("calibration error", "uncertainty_calibration_error"),
           ("Spearman", "uncertainty_spearman"), ("sigma error", "sigma_relative_error"),
           ("scale", "uncertainty_scale"), ("peak in", "T_peak_in_interval"),
           ("peak at in", "T_peak_position_in_interval"), ("volume in", "flame_volume_in_interval"),
           ("time x", "time_ratio"))


def run(overrides: list[str], folder: Path, settings: list[str], resume: bool, method: str = "ensemble") -> dict:
    """One run with the uncertainty ``method``: its figures (``KEYS``) and the time over the single run's."""
    import subprocess

    record = folder / "uncertainty_row.json"
    if resume and record.is_file():
        return json.loads(record.read_text())
    shutil.rmtree(folder, ignore_errors=True)
    done = subprocess.run([sys.executable, "-m", "nerif", f"hydra.run.dir={folder.resolve()}", "train.progress=false",
                           f"uncertainty={method}", *overrides, *settings], cwd=REPO, capture_output=True, text=True)
    metrics = folder / "metrics.json"
    if done.returncode or not metrics.is_file():
        return {"exit": done.returncode, "message": (done.stderr.strip().splitlines() or [""])[-1][:200]}
    m = json.loads(metrics.read_text())
    row = {k: m.get(k) for k in KEYS}
    single = row["total_time_s"] - row["uncertainty_time_s"]
    row["time_ratio"] = row["total_time_s"] / single if single > 0 else None
    write_json(row, record)
    return row


def scenes(args, out: Path) -> dict[str, list[str]]:
    """Scene name -> the overrides that reconstruct it."""
    found = {f"capture {c}": capture_overrides(c, out) for c in args.captures}
    for family in args.families:
        for seed in args.seeds:
            for noise in args.noise:
                root = out / "data" / f"{family}_s{seed}_n{noise:g}"
                found[f"{family} seed {seed} noise {noise:g}"] = write_dataset(root, FAMILIES[family](seed),
                                                                                noise=noise, noise_seed=seed)
    return found


def table(rows: dict) -> str:
    lines = ["| scene | " + " | ".join(c for c, _ in COLUMNS) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    for name, row in rows.items():
        if "exit" in row:
            lines.append(f"| {name} | failed: {row['message']} |")
            continue
        cells = [f"{row[k]:.3f}" if isinstance(row.get(k), (int, float)) else "-" for _, k in COLUMNS]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--captures", nargs="*", default=list(CAPTURES), help="shared captures (benchmarks/independent.py)")
    p.add_argument("--families", nargs="*", default=[], help="analytic flame families of nerif.data.families")
    p.add_argument("--seeds", nargs="*", type=int, default=[0, 1])
    p.add_argument("--noise", nargs="*", type=float, default=[0.0, 0.2])
    p.add_argument("--set", nargs="*", default=[], help="further overrides of every run")
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "uncertainty")
    p.add_argument("--resume", action="store_true")
    p.add_argument("--method", default="auto", help="the uncertainty method (auto, ensemble, laplace)")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = {}
    for name, overrides in scenes(args, args.out).items():
        rows[name] = run(overrides, args.out / "runs" / name.replace(" ", "_"), args.set, args.resume, args.method)
        print(name, json.dumps(rows[name]), flush=True)
    text = table(rows)
    write_report(args.out, "uncertainty", rows, "# The per-voxel uncertainty against the truth\n\n"
                 f"Settings: every default, uncertainty={args.method} {' '.join(args.set)}\n\n{text}\n")


if __name__ == "__main__":
    main()
