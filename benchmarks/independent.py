"""Every default on every independent capture: the captures another program made, with their truths (the bunsen
flame ideal, dirty and through a calibrated multi-camera rig; the lifted flame at the shared pixels and at 4x finer
ones; the six random flames of ``independent_family``; the lifted and bunsen flames in front of real photographed
backgrounds), each run with every default by this checkout and by each ``--against`` checkout, side by side in one
run, against the capture's truth; and beside them CGLS-TV at the weight the held-out view picks.

    python benchmarks/independent.py --against bb33d96 --seeds 0 1 --tv        # the judgement of a default
    python benchmarks/independent.py --variant flow:data_term=flow             # this checkout with other settings
    python benchmarks/independent.py --captures lifted family-113 --resume

A default changes only where the geometric mean of its ratios to the first row improves and no capture loses by
more than its run-to-run spread (``--seeds``: each row run with each seed; a capture's spread is the largest relative
difference between two seeds of one row). Rays are one voxel apart at the probe centre (4 image pixels, 16 on the fine
capture: what ``data.binning=auto`` picks, set explicitly for older checkouts). Each run is ``python -m nerif`` in a
subprocess with that checkout's code (``same_figures.run``); ``--resume`` reads back the runs an earlier call
finished. ``--tv``: CGLS with total variation (the variants' checkout) at each weight of :data:`TV_WEIGHTS`, the one whose
held-out deflections are best (:func:`nerif.metrics.select_by_heldout`: no truth) reported beside nerif. Prints one
table (sigma relative error per capture, the mean over the seeds; the ratios' geometric mean and worst; nerif over
TV), the peak's error and whether its interval holds the truth, and where each run's time went (set-up, training,
the uncertainty's members, the rest: the results written; beside CGLS-TV's one solve and its sweep over the weights,
and the sigma error along each run's wall time in ``independent.json``, ``curve``), and writes ``independent.json``
and ``independent.md`` under ``--out``. Times are the runs' own (``metrics.json``): compare rows run in one call on a
machine left alone.
"""
from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import sys
import time
from contextlib import ExitStack
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from same_figures import REPO, SHARED, output_folder, run  # noqa: E402
from speed import checkout  # noqa: E402

FAMILY = ("family-101", "family-102", "family-103", "family-104", "family-111", "family-113")
REAL = ("real_lifted_jet", "real_bunsen_blowtorch")
CAPTURES = ("bunsen", "bunsen_dirty", "bunsen_multicam", "lifted", "lifted_fine", *FAMILY, *REAL)
KEYS = ("sigma_relative_error", "temperature_rmse_K", "heldout_explained", "heldout_deflection_rmse", "data_term",
        "data_term_kept", "flow_stage", "images_stage", "wall_time_s", "total_time_s", "T_peak_K", "T_peak_field_K",
        "T_peak_true_K", "T_peak_interval_K", "T_peak_in_interval", "resolution_mm", "T_peak_resolved",
        "setup_time_s", "uncertainty_time_s")
TV_WEIGHTS = (1e-3, 1e-2, 1e-1, 3e-1)
CGLS_TV = ["solver=cgls", "solver.regularizer=tv"]


def capture_root(name: str) -> Path:
    """The shared folder of capture ``name``."""
    if name in FAMILY:
        return SHARED / "independent_family" / name
    if name in REAL:
        return SHARED / f"real_background_{name[len('real_'):]}"
    return SHARED / f"independent_capture_{name}"


def capture_overrides(name: str, out: Path) -> list[str]:
    """``python -m nerif`` overrides of capture ``name`` (the multicam capture through the version-3 rig file of
    ``benchmarks/calibrated.py``, made under ``out``), scored against its truth."""
    root = capture_root(name)
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
    row = {**{k: m.get(k) for k in KEYS}, "exit": r["exit"], "wall_s": time.perf_counter() - t, "message": r["message"],
           "curve": [[h["wall_time_s"], h.get("sigma_relative_error")] for h in m.get("history", [])
                     if "wall_time_s" in h]}
    if not r["exit"]:  # a failed run is tried again by the next --resume
        record.write_text(json.dumps(row))
    return row


def error(runs: list[dict]) -> float | None:
    """The mean sigma error of a row's runs of one capture (one per seed); None where none finished."""
    e = [r["sigma_relative_error"] for r in runs if r and r.get("sigma_relative_error") is not None]
    return sum(e) / len(e) if e else None


def spread(runs: list[dict]) -> float:
    """The run-to-run spread of a row on one capture: the largest relative difference between two of its seeds."""
    e = [r["sigma_relative_error"] for r in runs if r and r.get("sigma_relative_error") is not None]
    return (max(e) - min(e)) / (sum(e) / len(e)) if len(e) > 1 else 0.0


def tv_pick(runs: dict) -> tuple[str, dict] | None:
    """The TV weight (key) whose run predicts the held-out rays best, and that run; None where none finished."""
    from nerif.metrics import select_by_heldout

    done = {k: r for k, r in runs.items() if r and r.get("heldout_deflection_rmse") is not None}
    if not done:
        return None
    k = select_by_heldout(done)
    return k, done[k]


def summary(table: dict, rows: list[str], captures: list[str]) -> dict:
    """Per row: each capture's mean error, the ratio to the first row and whether it loses beyond the capture's
    spread (the larger of the two rows'), the ratios' geometric mean and worst; and nerif over TV per capture."""
    first = rows[0]
    out = {}
    for name in rows:
        per, logs = {}, []
        for c in captures:
            e, e0 = error(table[c][name]), error(table[c][first])
            if e is None or e0 is None:
                per[c] = {"error": e}
                continue
            s = max(spread(table[c][name]), spread(table[c][first]))
            per[c] = {"error": e, "ratio": e / e0, "spread": s, "beyond_spread": e / e0 > 1 + s}
            logs.append(math.log(e / e0))
        out[name] = {"captures": per, "geometric_mean": math.exp(sum(logs) / len(logs)) if logs else None,
                     "worst": max((p["ratio"] for p in per.values() if "ratio" in p), default=None),
                     "losses_beyond_spread": [c for c, p in per.items() if p.get("beyond_spread")]}
        if table.get("tv"):
            out[name]["over_tv"] = {c: per[c]["error"] / table["tv"][c]["pick"]["sigma_relative_error"]
                                    for c in captures if per[c].get("error") and (table["tv"].get(c) or {}).get("pick")}
    return out


def report(table: dict, rows: list[str], captures: list[str], sums: dict) -> str:
    """The markdown table: a row per checkout or variant, a column per capture (sigma error, the mean over the seeds,
    and the spread between them), the geometric mean and worst of the ratios to the first row."""
    first = rows[0]

    def cell(name, c):
        p = sums[name]["captures"][c]
        if p.get("error") is None:
            r = (table[c][name] or [{}])[0] or {}
            return f"exit {r.get('exit', '-')}"
        s = f" +-{100 * p['spread'] / 2:.1f}%" if p.get("spread") else ""
        flag = " (!)" if p.get("beyond_spread") else ""
        return f"**{p['error']:.4f}**{s}{flag}"

    lines = ["| checkout or variant | " + " | ".join(captures) + f" | geometric mean of ratios to {first} | worst |",
             "|---|" + "---|" * (len(captures) + 2)]
    for name in rows:
        gm, worst = sums[name]["geometric_mean"], sums[name]["worst"]
        lines.append(f"| {name} | " + " | ".join(cell(name, c) for c in captures) +
                     f" | {'-' if gm is None else f'{gm:.3f}'} | {'-' if worst is None else f'{worst:.3f}'} |")
    if table.get("tv"):
        tv = table["tv"]
        lines.append("| CGLS-TV, weight by the held-out view | " + " | ".join(
            f"{tv[c]['pick']['sigma_relative_error']:.4f} ({tv[c]['lam']})" if (tv.get(c) or {}).get("pick") else "-"
            for c in captures) + " | | |")
        for name in rows:
            ov = sums[name].get("over_tv", {})
            lines.append(f"| {name} / TV | " + " | ".join(f"{ov[c]:.2f}" if c in ov else "-" for c in captures) +
                         " | | |")
    lines.append("")
    lines.append("Each cell: sigma relative error against the truth, the mean over the seeds, +- half the spread "
                 "between them; (!) where it loses to the first row by more than the spread.")
    return "\n".join(lines) + "\n\n" + peak_report(table, rows, captures) + "\n" + time_report(table, rows, captures)


def parts_s(run: dict) -> dict | None:
    """Where a finished run's time went [s]: ``start`` (the interpreter, imports and the config, before the run's own
    clock), ``setup`` (to its first step: data, measurement or its cache, masks, the solver), ``training``,
    ``members`` (the uncertainty's), ``rest`` (the evaluations after training, the results written), and
    ``command`` (command to prompt); None where the run did not record them."""
    if not run or run.get("total_time_s") is None or run.get("wall_time_s") is None or run.get("wall_s") is None:
        return None
    setup, members = run.get("setup_time_s") or 0.0, run.get("uncertainty_time_s") or 0.0
    return {"start": run["wall_s"] - run["total_time_s"], "setup": setup, "training": run["wall_time_s"],
            "members": members, "rest": run["total_time_s"] - setup - run["wall_time_s"] - members,
            "command": run["wall_s"]}


def time_report(table: dict, rows: list[str], captures: list[str]) -> str:
    """Where each row's time went on each capture (its first seed's run), and its command-to-prompt time over CGLS-TV's
    sweep over :data:`TV_WEIGHTS` (``--tv``: one solve at each weight, each a command)."""
    tv = table.get("tv") or {}
    lines = ["Time, command to prompt [s] (start-up, set-up, training, members, the rest, as parts_s in benchmarks/independent.py reads them; the sweep: "
             f"CGLS-TV at each of {len(TV_WEIGHTS)} weights, each a command):", "",
             "| capture | checkout or variant | start-up | set-up | training | members | the rest | command | TV: one "
             "solve (picked) | TV: the sweep | command / sweep |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in captures:
        runs = (tv.get(c) or {}).get("runs", {})
        solves = [r.get("wall_s") for r in runs.values() if r and not r.get("exit") and r.get("wall_s")]
        sweep = sum(solves) if runs and len(solves) == len(runs) else None
        solve = ((tv.get(c) or {}).get("pick") or {}).get("wall_s")
        for name in rows:
            p = parts_s((table[c][name] or [{}])[0] or {})
            if p is None:
                continue
            cells = [f"{p[k]:.1f}" for k in ("start", "setup", "training", "members", "rest", "command")]
            cells += ["-" if v is None else f"{v:.1f}" for v in (solve, sweep)]
            cells.append(f"{p['command'] / sweep:.2f}" if sweep else "-")
            lines.append(f"| {c} | {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def peak_error(run: dict, key: str = "T_peak_K") -> float | None:
    """A run's peak temperature error [%] against its truth (``key``: the reported peak, or ``T_peak_field_K``, the
    field's hottest voxel); None where either is unknown."""
    if not run or run.get(key) is None or not run.get("T_peak_true_K"):
        return None
    return 100.0 * (run[key] / run["T_peak_true_K"] - 1.0)


def peak_report(table: dict, rows: list[str], captures: list[str]) -> str:
    """The peak temperature of each run against its truth (issue 66): the reported peak's error (the field's hottest
    voxel's where the run reports both), whether the truth lies in the 2-std interval and the interval's half width
    [% of the reported peak]; per row, how many captures are within 10 % and 5 % and hold the truth."""
    def cell(r):
        e, f = peak_error(r), peak_error(r, "T_peak_field_K")
        if e is None:
            return "-"
        iv, inside = r.get("T_peak_interval_K"), r.get("T_peak_in_interval")
        width = f", +-{50 * (iv[1] - iv[0]) / r['T_peak_K']:.0f} %" if iv else ""
        held = "" if inside is None else (" in" if inside else " **out**")
        field = f" (field {f:+.1f})" if f is not None and r.get("T_peak_field_K") != r.get("T_peak_K") else ""
        return f"{e:+.1f} %{field}{held}{width}"

    lines = ["Peak temperature error (the reported peak; the field's hottest voxel; the truth in the 2-std interval, "
             "its half width):", "", "| checkout or variant | " + " | ".join(captures) +
             " | within 10 % | within 5 % | in interval |", "|---|" + "---|" * (len(captures) + 3)]
    for name in rows:
        runs = [(table[c][name] or [{}])[0] or {} for c in captures]
        errs = [peak_error(r) for r in runs]
        known = [e for e in errs if e is not None]
        inside = [r.get("T_peak_in_interval") for r in runs if r.get("T_peak_in_interval") is not None]
        lines.append(f"| {name} | " + " | ".join(cell(r) for r in runs) +
                     f" | {sum(abs(e) <= 10 for e in known)} of {len(known)} | {sum(abs(e) <= 5 for e in known)} of "
                     f"{len(known)} | {int(sum(inside))} of {len(inside)} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", nargs="*", default=[], help="git refs or folders of other checkouts (every default)")
    ap.add_argument("--variant", nargs="*", default=[], metavar="NAME:OVERRIDES",
                    help="this checkout with other settings, e.g. 'flow:data_term=flow' (overrides space-separated)")
    ap.add_argument("--variant-tree", default=None, help="the checkout the variants run (default: this one)")
    ap.add_argument("--captures", nargs="*", choices=CAPTURES, default=list(CAPTURES))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0], help="each row run with each seed (the spread)")
    ap.add_argument("--tv", action="store_true",
                    help="also CGLS-TV at the held-out view's weight (the variants' checkout: this one by default)")
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
    missing = [c for c in args.captures if not capture_root(c).is_dir()]
    if missing:
        raise SystemExit(f"no shared capture for {', '.join(missing)} under {SHARED}")
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
                table[c][name] = []
                for seed in args.seeds:
                    folder = out / c / (slug if seed == 0 else f"{slug}-seed{seed}")
                    r = one(tree, [*capture_overrides(c, out), *settings, f"seed={seed}"], folder, args.resume)
                    table[c][name].append(r)
                    print(f"{c} @ {name}, seed {seed}: {r}", flush=True)
        if args.tv:
            table["tv"] = {}
            for c in args.captures:
                runs = {}
                for lam in TV_WEIGHTS:
                    runs[f"{lam:g}"] = one(tree, [*capture_overrides(c, out), *CGLS_TV, f"solver.lam={lam:g}"],
                                           out / c / f"cgls-tv-{lam:g}", args.resume)
                    print(f"{c} @ cgls-tv {lam:g}: {runs[f'{lam:g}']}", flush=True)
                pick = tv_pick(runs)
                table["tv"][c] = {"runs": runs, "lam": pick[0] if pick else None, "pick": pick[1] if pick else None}
    sums = summary(table, list(trees), args.captures)
    text = report(table, list(trees), args.captures, sums)
    print(text)
    result = {"table": table, "summary": sums, "seeds": args.seeds,
              "rows": {n: {"tree": str(t), "settings": s} for n, (t, s) in trees.items()}}
    (out / "independent.json").write_text(json.dumps(result, indent=1))
    (out / "independent.md").write_text(text)
    return result


if __name__ == "__main__":
    main()
