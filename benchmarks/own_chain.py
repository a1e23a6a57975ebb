"""Does nerif's own realistic chain rank the images against the flow as images another program made do? (issue 46)

    python benchmarks/own_chain.py                                   # both flames, pixels integrated and not
    python benchmarks/own_chain.py --flames lifted --chains "integrated:" "wavelet:pattern=wavelet_noise pattern.scale_px=8"
    python benchmarks/own_chain.py --resume                          # finished runs read back

Each flame of the independent captures (its ``volume.npz``: ``bunsen``, ``lifted``) is written by
``nerif.write_capture`` at 4x the shared rig's pixels (1440 x 2560 px of 10 um, rays 16 px apart:
``images.finer_capture``) once per chain (``--chains NAME:OVERRIDES``, the write's overrides; the default chain
integrates each pixel over 4 x 4 displaced points, ``data.sensor.pixel_samples=1`` reads the pattern at the
displaced pixel centres by bicubic interpolation), then reconstructed with every default. The two-stage image term
records both fields' errors (``flow_stage``: the flow's converged field; ``images_stage``: the images' refinement
of it), so one run gives the ratio images / flow, which ``--independent`` also reads on
``independent_capture_lifted_fine`` (the lifted flame at the same pixels, made by the other program). Where nerif's
chain gives the images a lead the other program's images do not, nerif's own scenes overrate the image term.
Writes ``own_chain.json`` and ``own_chain.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from images import finer_capture  # noqa: E402
from ablation import write_report  # noqa: E402
from same_figures import REPO, SHARED, output_folder, run  # noqa: E402

FLAMES = {"bunsen": "independent_capture_bunsen", "lifted": "independent_capture_lifted"}
CHAINS = ["integrated:", "centres:data.sensor.pixel_samples=1"]
FINE = "independent_capture_lifted_fine"


def stages(folder: Path, overrides: list[str], resume: bool) -> dict:
    """Both fields' sigma errors and held-out misfits of one run of every default (read back with ``resume``)."""
    metrics = folder / "metrics.json"
    if not (resume and metrics.is_file()):
        r = run(REPO, overrides, folder)
        if r["exit"]:
            return {"exit": r["exit"], "message": r["message"]}
    m = json.loads(metrics.read_text())
    f, i = m["flow_stage"], m["images_stage"]
    return {"flow": f["sigma_relative_error"], "images": i["sigma_relative_error"],
            "ratio": i["sigma_relative_error"] / f["sigma_relative_error"], "kept": m["data_term_kept"],
            "heldout_flow_px": f["heldout_misfit"], "heldout_images_px": i["heldout_misfit"]}


def report(rows: dict) -> str:
    lines = ["| capture | flow's field | images' field | images / flow | held out: flow, images [px] | kept |",
             "|---|---|---|---|---|---|"]
    for name, r in rows.items():
        if "exit" in r:
            lines.append(f"| {name} | exit {r['exit']}: {r['message']} | | | | |")
            continue
        lines.append(f"| {name} | {r['flow']:.4f} | {r['images']:.4f} | **{r['ratio']:.3f}** | "
                     f"{r['heldout_flow_px']:.4f}, {r['heldout_images_px']:.4f} | {r['kept']} |")
    return "\n".join(lines) + "\n\nSigma relative error against the flame's truth; 1440 x 2560 px, rays 16 px apart.\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--flames", nargs="+", choices=list(FLAMES), default=list(FLAMES))
    ap.add_argument("--chains", nargs="+", default=CHAINS, metavar="NAME:OVERRIDES")
    ap.add_argument("--independent", action=argparse.BooleanOptionalAction, default=True,
                    help=f"also run {FINE} (the other program's images of the lifted flame)")
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--out", default="benchmarks/results/own_chain")
    args = ap.parse_args(argv)
    out = output_folder(args.out)
    rows = {}
    for flame in args.flames:
        root = SHARED / FLAMES[flame]
        for chain in args.chains:
            name, sep, settings = chain.partition(":")
            if not sep or not name:
                raise SystemExit(f"--chains {chain!r}: NAME:OVERRIDES, e.g. 'centres:data.sensor.pixel_samples=1'")
            slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{flame}_{name}")
            capture = finer_capture(out / "captures" / slug, 4, flame=root, extra=tuple(settings.split()))
            rows[f"{flame}, nerif's chain ({name})"] = stages(
                out / "runs" / slug, ["data=capture", f"data.root={capture}", "data.binning=16",
                                      f"data.truth={root / 'volume.npz'}"], args.resume)
            print(rows, flush=True)
    if args.independent:
        rows[f"lifted, {FINE} (the other program)"] = stages(
            out / "runs" / "independent_lifted_fine", ["data=capture", f"data.root={SHARED / FINE}", "data.binning=16",
                                                       f"data.truth={SHARED / FINE / 'volume.npz'}"], args.resume)
    text = report(rows)
    write_report(out, "own_chain", rows, text)  # atomically, and printed
    return rows


if __name__ == "__main__":
    main()
