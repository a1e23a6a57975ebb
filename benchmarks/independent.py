"""Every default on every independent capture: the captures another program made (``../shared/data/
independent_capture_*``: the bunsen flame ideal, dirty and through a calibrated multi-camera rig; the lifted flame at
the shared pixels and at 4x finer ones), each run with every default by this checkout and by each ``--against``
checkout, side by side in one run, against the capture's truth.

    python benchmarks/independent.py --against 579c785                 # this checkout against that commit
    python benchmarks/independent.py --variant flow:data_term=flow     # and this checkout with other settings
    python benchmarks/independent.py --captures lifted lifted_fine --resume

A default changes only where it loses on no capture by more than 2 % (the ``worst`` column: the largest ratio of a
row's sigma error to the first row's over the captures). Rays are one voxel apart at the probe centre (4 image
pixels, 16 on the fine capture: what ``data.binning=auto`` picks, set explicitly for older checkouts). Each run is ``python -m nerif`` in a subprocess with that
checkout's code (``same_figures.run``); ``--resume`` reads back the runs an earlier call finished. Prints one table
(sigma relative error, and T RMSE [K], held-out share explained, wall time [s] per capture) and writes
``independent.json`` and ``independent.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
import time
from contextlib import ExitStack
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from same_figures import REPO, SHARED, output_folder, run  # noqa: E402
from speed import checkout  # noqa: E402

CAPTURES = ("bunsen", "bunsen_dirty", "bunsen_multicam", "lifted", "lifted_fine")
KEYS = ("sigma_relative_error", "temperature_rmse_K", "heldout_explained", "data_term", "data_term_kept",
        "flow_stage", "images_stage")


def capture_overrides(name: str, out: Path) -> list[str]:
    """``python -m nerif`` overrides of capture ``name`` (the multicam capture through the version-3 rig file of
    ``benchmarks/calibrated.py``, made under ``out``), scored against its truth."""
    root = SHARED / f"independent_capture_{name}"
    if name == "bunsen_multicam":
        from calibrated import multicam_folder

        folder = multicam_folder(out / "multicam", ideal=False)
    else:
        folder = root
    # rays one voxel apart at the probe centre, what data.binning=auto picks (older checkouts' default was 8)
    binning = 16 if name.endswith("_fine") else 4
    return ["data=capture", f"data.root={folder.resolve()}", f"data.truth={root / 'volume.npz'}",
            f"data.binning={binning}"]


def one(tree: Path, overrides: list[str], folder: Path, resume: bool) -> dict:
    """One run's figures (``KEYS``, wall time, exit status), read back from ``folder`` with ``resume``."""
    record = folder / "independent_row.json"
    if resume and record.is_file():
        return json.loads(record.read_text())
    shutil.rmtree(folder, ignore_errors=True)  # a run an earlier call left unfinished starts afresh
    t = time.perf_counter()
    r = run(tree, overrides, folder)
    metrics = folder / "metrics.json"
    m = json.loads(metrics.read_text()) if metrics.is_file() and not r["exit"] else {}
    row = {**{k: m.get(k) for k in KEYS}, "exit": r["exit"], "wall_s": time.perf_counter() - t, "message": r["message"]}
    if not r["exit"]:  # a failed run is tried again by the next --resume
        record.write_text(json.dumps(row))
    return row


def report(table: dict, rows: list[str], captures: list[str]) -> str:
    """The markdown table: a row per checkout or variant, a column per capture, and the worst ratio to the first row."""
    def cell(r):
        if not r or r.get("sigma_relative_error") is None:
            return f"exit {r.get('exit') if r else '-'}"
        ex = r.get("heldout_explained")
        return (f"**{r['sigma_relative_error']:.4f}** / {r['temperature_rmse_K']:.1f} K / "
                f"{'-' if ex is None else f'{ex:.3f}'} / {r['wall_s']:.0f} s")

    first = rows[0]
    lines = ["| checkout or variant | " + " | ".join(captures) + f" | worst ratio to {first} |",
             "|---|" + "---|" * (len(captures) + 1)]
    for name in rows:
        ratios = [table[c][name]["sigma_relative_error"] / table[c][first]["sigma_relative_error"]
                  for c in captures if (table[c][name] or {}).get("sigma_relative_error")
                  and (table[c][first] or {}).get("sigma_relative_error")]
        worst = f"{max(ratios):.3f}" if ratios else "-"
        lines.append(f"| {name} | " + " | ".join(cell(table[c][name]) for c in captures) + f" | {worst} |")
    lines.append("")
    lines.append("Each cell: sigma relative error / T RMSE / held-out share explained / wall time of the run.")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", nargs="*", default=[], help="git refs or folders of other checkouts (every default)")
    ap.add_argument("--variant", nargs="*", default=[], metavar="NAME:OVERRIDES",
                    help="this checkout with other settings, e.g. 'flow:data_term=flow' (overrides space-separated)")
    ap.add_argument("--variant-tree", default=None, help="the checkout the variants run (default: this one)")
    ap.add_argument("--captures", nargs="*", choices=CAPTURES, default=list(CAPTURES))
    ap.add_argument("--no-defaults", action="store_true", help="leave out this checkout's own row")
    ap.add_argument("--resume", action="store_true", help="read back the runs an earlier call finished")
    ap.add_argument("--out", default="benchmarks/results/independent")
    args = ap.parse_args(argv)
    out = output_folder(args.out)
    variants = {}
    for v in args.variant:
        name, sep, settings = v.partition(":")
        if not sep or not name:
            raise SystemExit(f"--variant {v!r}: NAME:OVERRIDES, e.g. 'flow:data_term=flow'")
        variants[name] = settings.split()
    table: dict = {c: {} for c in args.captures}
    with ExitStack() as stack:
        trees = {} if args.no_defaults else {"this checkout": (REPO, [])}
        trees.update({ref: (checkout(ref, stack), []) for ref in args.against})
        tree = checkout(args.variant_tree, stack) if args.variant_tree else REPO
        trees.update({name: (tree, settings) for name, settings in variants.items()})
        if not trees:
            raise SystemExit("nothing to run: give --against or --variant, or leave out --no-defaults")
        for c in args.captures:
            for name, (tree, settings) in trees.items():
                slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
                r = one(tree, [*capture_overrides(c, out), *settings], out / c / slug, args.resume)
                table[c][name] = r
                print(f"{c} @ {name}: {r}", flush=True)
    text = report(table, list(trees), args.captures)
    print(text)
    result = {"table": table, "rows": {n: {"tree": str(t), "settings": s} for n, (t, s) in trees.items()}}
    (out / "independent.json").write_text(json.dumps(result, indent=1))
    (out / "independent.md").write_text(text)
    return result


if __name__ == "__main__":
    main()
