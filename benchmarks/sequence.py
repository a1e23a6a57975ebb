"""Time series: warm start against cold start, per frame, on a synthetic sequence of a flickering flame.

    python benchmarks/sequence.py                          # 8 frames of phantom=flicker at 250 frames/s, CPU
    python benchmarks/sequence.py --frames 12 --set data.frame_rate_hz=100 data.sensing=perpendicular
    python benchmarks/sequence.py --warm "sequence.lr=5e-3" --warm "sequence.iterations=200"   # more warm variants
    python benchmarks/sequence.py --keep --warm "sequence.lr=1e-3"   # add a variant; finished series are kept
    python benchmarks/sequence.py --set data=capture data.root=/tmp/flicker --metric heldout_displacement_rmse_px

Runs the whole series twice or more, side by side (one process each, ``threads`` split between them, as
``python -m nerif`` would be run): every frame from scratch (``sequence.warm_start=false``, ``train.iterations``
each) and every frame warm-started from the previous one (the defaults: ``sequence.iterations`` at
``sequence.lr``), with evaluations every ``train.eval_every=50`` iterations. For each warm frame after the
first: the iterations and training time until its error (``--metric``, default the temperature RMSE) first
reaches the cold start's final error on the same frame (read at the evaluation resolution; '-' where it never
does), and its own final error.
Writes ``sequence.json`` and ``sequence.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def launch(name: str, settings: list[str], folder: Path, threads: int) -> subprocess.Popen:
    log = open(folder.parent / f"{name}.log", "w")
    cmd = [sys.executable, "-m", "nerif", *settings, f"threads={threads}", "train.progress=false",
           f"hydra.run.dir={folder}"]
    print(" ".join(cmd[1:]), flush=True)
    return subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)


def frames(folder: Path) -> list[dict]:
    """Every frame's metrics.json of a finished series, in frame order."""
    series = json.loads((folder / "metrics.json").read_text())
    return [json.loads((folder / r["folder"] / "metrics.json").read_text()) for r in series["frames"]]


def reach(history: list[dict], metric: str, target: float):
    """(iterations, training seconds) of the first evaluation at or below ``target``, else (None, None)."""
    for h in history:
        if h.get(metric) is not None and h[metric] <= target:
            return h["iteration"], h["wall_time_s"]
    return None, None


def compare(cold: list[dict], warm: list[dict], metric: str) -> list[dict]:
    """Per frame: the cold start's final error (its last evaluation) and when the warm start first reaches it."""
    rows = []
    for c, w in zip(cold, warm):
        target = c["history"][-1][metric]
        it, s = reach(w["history"], metric, target) if w["warm_start"] else (None, None)
        rows.append({"frame": c["frame"], "time_s": c["time_s"], "cold_iterations": c["iterations"],
                     "cold_error": target, "cold_wall_s": c["wall_time_s"], "warm": w["warm_start"],
                     "warm_iterations": w["iterations"], "warm_error": w["history"][-1][metric],
                     "warm_wall_s": w["wall_time_s"], "warm_iterations_to_cold": it, "warm_seconds_to_cold": s,
                     "iteration_ratio": None if it is None else it / c["iterations"]})
    return rows


def table(name: str, rows: list[dict], metric: str) -> str:
    heads = ["frame", "t [ms]", "cold: it", f"cold: {metric}", "cold: s", "warm: it", f"warm: {metric}", "warm: s",
             "warm: it to cold's error", "warm: s to cold's error", "iteration ratio"]
    lines = [f"### {name}", "", "| " + " | ".join(heads) + " |", "|---" * len(heads) + "|"]
    for r in rows:
        to = "-" if r["warm_iterations_to_cold"] is None else str(r["warm_iterations_to_cold"])
        tos = "-" if r["warm_seconds_to_cold"] is None else f"{r['warm_seconds_to_cold']:.1f}"
        ratio = "-" if r["iteration_ratio"] is None else f"{r['iteration_ratio']:.2f}"
        lines.append(f"| {r['frame']}{'' if r['warm'] else ' (cold)'} | {1e3 * r['time_s']:.1f} | "
                     f"{r['cold_iterations']} | {r['cold_error']:.4g} | {r['cold_wall_s']:.0f} | {r['warm_iterations']} | "
                     f"{r['warm_error']:.4g} | {r['warm_wall_s']:.0f} | {to} | {tos} | {ratio} |")
    warm = [r for r in rows if r["warm"]]
    if warm:
        met = sum(r["warm_iterations_to_cold"] is not None and r["iteration_ratio"] <= 1 / 3 for r in warm)
        lines += ["", f"Warm frames reaching the cold start's final error within a third of its iterations: {met} of "
                  f"{len(warm)}; mean {metric} warm {sum(r['warm_error'] for r in warm) / len(warm):.4g}, cold "
                  f"{sum(r['cold_error'] for r in warm) / len(warm):.4g}; training time warm "
                  f"{sum(r['warm_wall_s'] for r in warm):.0f} s, cold {sum(r['cold_wall_s'] for r in warm):.0f} s."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--set", nargs="*", default=[], help="overrides for every run")
    ap.add_argument("--warm", action="append", default=[], help="a further warm-start variant: its overrides")
    ap.add_argument("--jobs", type=int, default=2, help="series running at once")
    ap.add_argument("--out", default="benchmarks/results/sequence")
    ap.add_argument("--keep", action="store_true", help="keep the series already finished under --out")
    ap.add_argument("--metric", default="temperature_rmse_K",
                    help="error compared (of the evaluations): e.g. heldout_displacement_rmse_px for a capture")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    base = ["phantom=flicker", f"data.frames={args.frames}", "train.eval_every=50", *args.set]
    runs = {"cold": ["sequence.warm_start=false"], "warm (defaults)": []}
    runs.update({f"warm, {w}": w.split() for w in args.warm})
    threads = max(1, (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()) // args.jobs)
    todo, running = list(runs.items()), []
    folders = {name: out / re.sub(r"[^\w.-]+", "_", name).strip("_") for name in runs}
    if args.keep:  # series already finished under --out (with the same settings) are not run again
        todo = [(n, e) for n, e in todo if not (folders[n] / "metrics.json").is_file()]
    while todo or running:
        while todo and len(running) < args.jobs:
            name, extra = todo.pop(0)
            running.append((name, launch(folders[name].name, base + extra, folders[name], threads)))
        if not running:
            break
        name, proc = running.pop(0)
        if proc.wait() != 0:
            raise SystemExit(f"{name} failed: see {out / (folders[name].name + '.log')}")
    cold = frames(folders["cold"])
    result = {"settings": base, "metric": args.metric, "runs": {}}
    text = [f"Sequence benchmark: {' '.join(base)}; {threads} thread(s) per series, {args.jobs} at once", ""]
    for name in runs:
        if name == "cold":
            continue
        rows = compare(cold, frames(folders[name]), args.metric)
        result["runs"][name] = rows
        text.append(table(name, rows, args.metric))
    md = "\n".join(text)
    print(md)
    (out / "sequence.md").write_text(md)
    (out / "sequence.json").write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
