"""The background patterns' time to draw, this checkout beside ``--against`` checkouts, side by side in one run.

    python benchmarks/patterns.py --against 39b1537 --out /tmp/patterns

Each pattern of :data:`nerif.sensing.patterns.PATTERNS` at the image sizes of :data:`SIZES` (a binned camera, the
shared captures', a full 2-megapixel sensor), ``--repeats`` times each in a fresh Python per checkout (the
checkouts alternate, so that a change in the machine's load falls on both); the median seconds, and whether every
checkout drew the same pattern (the images' SHA-256). Prints one table and writes ``patterns.json`` and
``patterns.md`` under ``--out``. Times are this machine's: compare rows of one run.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from contextlib import ExitStack
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402
from speed import checkout  # noqa: E402

SIZES = ((240, 320), (640, 480), (1200, 1600))
REPO = Path(__file__).resolve().parents[1]

TIMER = """
import hashlib, json, sys, time
from nerif.sensing.patterns import PATTERNS
name, h, w = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
t = time.perf_counter()
image = PATTERNS.build({"name": name}, height=h, width=w, seed=0)
print(json.dumps({"s": time.perf_counter() - t, "sha": hashlib.sha256(image.tobytes()).hexdigest()}))
"""


def time_once(tree: Path, code: str, *args: str) -> dict:
    """Run the timer ``code`` with ``args`` in a fresh Python on the code of ``tree`` (one thread) and return the
    JSON it prints last; one sentence where it fails."""
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", code, *args], cwd=tree, env=env, capture_output=True, text=True)
    if done.returncode:
        said = done.stderr.strip().splitlines() or [f"exit status {done.returncode}"]
        raise SystemExit(f"{tree}: {' '.join(args)} failed: {said[-1]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def alternating_runs(trees: dict, repeats: int, code: str, *args: str) -> dict:
    """The timer ``code`` with ``args`` (:func:`time_once`) run ``repeats`` times on each of ``trees`` (label ->
    checkout), the checkouts alternating so that a change in the machine's load falls on all: label -> the JSON of
    each run."""
    runs = {label: [] for label in trees}
    for _ in range(repeats):
        for label, tree in trees.items():
            runs[label].append(time_once(tree, code, *args))
    return runs


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", nargs="*", default=[], help="git refs or folders to time beside this checkout")
    ap.add_argument("--patterns", nargs="*", default=None, help="patterns to time (default: every registered one)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/patterns"))
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO))
    from nerif.sensing.patterns import PATTERNS

    names = args.patterns or sorted(PATTERNS.names())
    rows = {}
    with ExitStack() as stack:
        trees = {"this checkout": REPO, **{ref: checkout(ref, stack) for ref in args.against}}
        for name in names:
            for size in SIZES:
                runs = alternating_runs(trees, args.repeats, TIMER, name, *map(str, size))
                rows[f"{name} {size[0]} x {size[1]}"] = {
                    label: {"median_s": sorted(r["s"] for r in got)[len(got) // 2], "sha256": got[0]["sha"]}
                    for label, got in runs.items()}
    labels = list(trees)
    lines = ["| pattern, image px | " + " | ".join(f"{lab} [s]" for lab in labels) + " | same image |",
             "|---|" + "---|" * (len(labels) + 1)]
    for key, row in rows.items():
        same = len({row[lab]["sha256"] for lab in labels}) == 1
        lines.append(f"| {key} | " + " | ".join(f"{row[lab]['median_s']:.3f}" for lab in labels)
                     + f" | {'yes' if same else 'no'} |")
    write_report(args.out, "patterns", {"table": rows, "repeats": args.repeats}, "\n".join(lines) + "\n")
    return rows


if __name__ == "__main__":
    main()
