"""Encoder x gradient ablation on one scene: temperature RMSE, wall time and throughput per cell.

    python benchmarks/ablation.py                          # the 9 cells on the default scene
    python benchmarks/ablation.py --set device=cuda +experiment=paper_phantom5 --cells "encoder=hash grad=discrete"

Every cell runs through ``nerif.app.run`` (the same code as ``python -m nerif``) in one process, one after
the other, so ratios between cells are measured side by side. Writes ``ablation.json``, ``ablation.md`` and
``ablation.csv`` (plus each cell's full run folder) under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import platform
import shutil
import time
from pathlib import Path

import torch

from nerif.app import run
from nerif.configs import compose
from nerif.export import atomic_write, write_json
from nerif.io.summary import COLUMNS, write_tables

DEFAULT_CELLS = [f"encoder={e} grad={g}" for e in ("none", "frequency", "hash") for g in ("auto", "discrete", "hybrid")]


def progress_table(rows: list[dict], out: Path) -> str:
    """Temperature RMSE [K] against training progress: a row per evaluation, a column per cell."""
    its = sorted({h["iteration"] for r in rows for h in r["history"]})
    cols = [{h["iteration"]: h.get("temperature_rmse_K") for h in r["history"]} for r in rows]
    lines = ["| iteration | " + " | ".join(r["config"] for r in rows) + " |", "|---" * (len(rows) + 1) + "|"]
    for it in its:
        lines.append(f"| {it} | " + " | ".join("" if c.get(it) is None else f"{c[it]:.1f}" for c in cols) + " |")
    text = "\n".join(lines) + "\n"
    atomic_write(out / "progress.md", lambda t: Path(t).write_text(text))
    return text


def cell_folder(out: Path, i: int, cell: str) -> Path:
    """The run folder of the ``i``-th cell (its overrides ``cell``) under ``out``."""
    return out / f"{i}_{cell.replace(' ', '_').replace('=', '-')}"


def run_cells(cells: list[str], settings: list[str], out: Path, resume: bool = False) -> list[dict]:
    """Each cell (a string of overrides, plus ``settings``) through :func:`nerif.app.run`, one after the other in
    this process; returns one row per cell: its metrics, total time and evaluation history. ``resume``: a cell
    whose folder already holds a ``metrics.json`` (a finished run of an interrupted benchmark) is read back, not
    run again, an unfinished one continues from its checkpoint; without ``resume`` every cell starts afresh (its
    folder's earlier contents removed)."""
    rows = []
    for i, cell in enumerate(cells):
        folder = cell_folder(out, i, cell)
        if folder.exists() and not resume:
            shutil.rmtree(folder)
        again = ["train.resume=auto"] if resume and folder.exists() else []
        cfg = compose(list(settings) + cell.split() + ["train.progress=false"] + again)
        t0 = time.perf_counter()
        if resume and (folder / "metrics.json").is_file():
            m = json.loads((folder / "metrics.json").read_text())
            m.setdefault("total_time_s", m.get("wall_time_s", 0.0))
            t0 = time.perf_counter() - m["total_time_s"]
        else:
            m = run(cfg, folder)
        row = {"config": cell, "total_time_s": time.perf_counter() - t0,
               **{k: m[k] for k, _, _ in COLUMNS if k in m}, "device": m["device"], "history": m["history"],
               **{k: m[k] for k in ("encoder", "grad", "gpu_peak_memory_gib", "field_evaluations_per_sample") if k in m}}
        rows.append(row)
        print(f"[{i + 1}/{len(cells)}] {cell}: " + ", ".join(
            f"{h} {f.format(row[k])}" for k, h, f in COLUMNS if k in row), flush=True)
    return rows


def time_to(history: list[dict], target: float, key: str = "temperature_rmse_K"):
    """Training seconds at a run's first evaluation whose ``key`` is at or below ``target`` (None if never)."""
    for h in history:
        if h.get(key) is not None and h[key] <= target:
            return h["wall_time_s"]
    return None


def write_report(out: Path, stem: str, payload: dict, text: str) -> None:
    """``<stem>.json`` (the payload) and ``<stem>.md`` (the text) in ``out``, atomically; the text printed."""
    write_json(payload, out / f"{stem}.json")
    atomic_write(out / f"{stem}.md", lambda t: Path(t).write_text(text))
    print(text, flush=True)


def run_arguments(ap: argparse.ArgumentParser, out: str) -> None:
    """The options every benchmark of runs takes: ``--set`` (overrides of every run), ``--out`` (its folder, default
    ``out``) and ``--resume`` (finished runs read back)."""
    ap.add_argument("--set", nargs="*", default=[], help="overrides applied to every run")
    ap.add_argument("--out", default=out, help="output folder")
    ap.add_argument("--resume", action="store_true", help="read back the runs an interrupted benchmark finished")


def run_named(runs: dict, args: argparse.Namespace) -> dict:
    """Each named run (name -> overrides) through :func:`run_cells` with the options of :func:`run_arguments`:
    name -> its row."""
    return dict(zip(runs, run_cells(list(runs.values()), args.set, Path(args.out), resume=args.resume)))


def header(settings: list[str], rows: list[dict]) -> str:
    return (f"`{' '.join(settings) or 'default scene'}`; device {rows[0]['device']}, torch {torch.__version__}, "
            f"{platform.processor() or platform.machine()}, {torch.get_num_threads()} CPU threads")


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cells", nargs="+", default=DEFAULT_CELLS, help="override sets, one per cell (quoted)")
    ap.add_argument("--set", nargs="*", default=[], help="overrides applied to every cell")
    ap.add_argument("--out", default="benchmarks/results/ablation", help="output folder")
    args = ap.parse_args(argv)
    out = Path(args.out)
    rows = run_cells(args.cells, args.set, out)
    write_json({"settings": args.set, "rows": rows}, out / "ablation.json")
    print(write_tables(rows, out, "ablation", "Ablation on " + header(args.set, rows)))
    print(progress_table(rows, out))
    return rows


if __name__ == "__main__":
    main()
