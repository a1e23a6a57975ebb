"""A user's mistakes, made from the command line as a user makes them, with tiny settings (issue 28).

    python benchmarks/misuse.py                     # every case, a few minutes on 2 cores
    python benchmarks/misuse.py --cases resume_other_scene swapped_images

Each case runs ``python -m nerif ...`` (or ``python -m nerif.write_capture ...``) in a subprocess on fixtures
made first (a finished tiny run, a tiny capture, copies of the paper's Phantom 1 files with one key edited).
A verdict is OK only when the output holds no traceback, the message names the key or file (the expected
fragment), the exit code is what the case calls for (a refusal: not 0; a warning: 0) and nothing is lost (the
files a case must not touch are unchanged). Prints the table (case, exit code, first line of the message,
verdict) and writes ``misuse.json`` and ``misuse.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PHANTOM1 = Path(os.environ.get("NERIF_SHARED", ROOT.parent / "shared")) / "data" / "nirbos_phantom1"
TINY = ["device=cpu", "phantom=gaussian_blob", "phantom.shape=[16,16,16]", "phantom.voxel_mm=3.0",
        "phantom.width_mm=7.0", "rig.n_cameras=6", "rig.binning=40", "sampler.samples_per_ray=16",
        "train.iterations=20", "train.rays_per_batch=64", "train.eval_every=10", "metrics.eval_rays_per_view=32",
        "train.progress=false", "data.cache_dir=null", "data.render_supersample=1", "field.finest_resolution=32",
        "field.log2_table_size=12"]
CAPTURE = ["rig.width_px=240", "rig.height_px=320", "rig.binning=8", "rig.n_cameras=5", "phantom=gaussian_blob",
           "phantom.shape=[16,16,16]", "phantom.voxel_mm=2.0", "phantom.width_mm=6.0", "data.sensor.aperture_rays=4",
           "data.render_supersample=1", "data.cache_dir=null"]
SOLVER = [o for o in TINY if not o.startswith(("phantom", "rig.", "data."))]


@dataclass
class Case:
    name: str
    args: list[str]             # after ``python -m``
    expect: str                 # refuse | warn
    fragment: str               # what the message must say (the key or the file)
    keep: list[Path] = field(default_factory=list)  # files the case must leave as they were
    env: dict = field(default_factory=dict)
    during: Optional[Callable[[], subprocess.Popen]] = None  # a process running while the case runs
    interrupt_after: Optional[float] = None  # Ctrl-C (SIGINT) after so many seconds


def digest(paths: list[Path]) -> dict:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None for p in paths}


def nerif(*args: str) -> list[str]:
    return ["nerif", *args]


def fixtures(work: Path) -> dict:
    """A finished tiny run, a tiny capture and its edited copies, Phantom 1 with edited json files."""
    fx = {"run": work / "run", "capture": work / "capture"}
    if not (fx["run"] / "metrics.json").is_file():
        shutil.rmtree(fx["run"], ignore_errors=True)
        subprocess.run([sys.executable, "-m", "nerif", *TINY, f"hydra.run.dir={fx['run']}"], cwd=ROOT, check=True,
                       capture_output=True)
    if not (fx["capture"] / "rig.yaml").is_file():
        shutil.rmtree(fx["capture"], ignore_errors=True)
        subprocess.run([sys.executable, "-m", "nerif.write_capture", str(fx["capture"]), *CAPTURE], cwd=ROOT,
                       check=True, capture_output=True)

    def capture_variant(name: str, edit=None, text: Optional[str] = None) -> Path:
        dst = work / name
        shutil.rmtree(dst, ignore_errors=True)
        shutil.copytree(fx["capture"], dst)
        rig = yaml.safe_load((dst / "rig.yaml").read_text())
        if edit is not None:
            edit(rig)
        (dst / "rig.yaml").write_text(text if text is not None else yaml.safe_dump(rig))
        return dst

    def swap(rig):
        v = rig["views"]
        v["images"], v["references"] = v["references"], v["images"]

    fx["swapped"] = capture_variant("swapped", swap)
    fx["background_near"] = capture_variant("background_near", lambda r: r["camera"].update(camera_to_background_mm=500))
    fx["focal_abc"] = capture_variant("focal_abc", lambda r: r["camera"].update(focal_mm="abc"))
    fx["rig_syntax"] = capture_variant("rig_syntax", text="format: nerif-capture\nversion: [1\n")
    fx["radians"] = capture_variant("radians", lambda r: r["views"].update(
        angles_deg=[float(np.deg2rad(a)) for a in r["views"]["angles_deg"]]))
    def deepen(d: Path) -> None:
        import cv2

        for f in sorted(d.glob("distorted_*.png")):
            cv2.imwrite(str(f), cv2.imread(str(f), cv2.IMREAD_UNCHANGED).astype(np.uint16) * 257)

    fx["mixed_depth"] = capture_variant("mixed_depth")
    deepen(fx["mixed_depth"])

    def one_view(name: str, edit) -> None:  # issue 38: one view's images spoilt, the rig file as it was
        import cv2

        fx[name] = capture_variant(name)
        d, r = fx[name] / "distorted_01.png", fx[name] / "reference_01.png"
        dist, ref = (cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in (d, r))
        for path, img in zip((d, r), edit(dist, ref)):
            cv2.imwrite(str(path), img)

    def every_image(name: str, edit) -> None:  # issue 38: every image of the capture edited alike
        import cv2

        fx[name] = capture_variant(name)
        for f in sorted(fx[name].glob("*.png")):
            cv2.imwrite(str(f), edit(cv2.imread(str(f), cv2.IMREAD_UNCHANGED)))

    every_image("gain_clipped", lambda img: np.clip(img.astype(np.float32) * 2, 0, 255).astype(img.dtype))
    fx["no_flame"] = capture_variant("no_flame")  # every distorted image taken without the flame
    for f in sorted(fx["no_flame"].glob("reference_*.png")):
        shutil.copyfile(f, f.with_name(f.name.replace("reference", "distorted")))
    for name, edit in (("sensor_swapped", lambda r: r["camera"].update(sensor_px=r["camera"]["sensor_px"][::-1])),
                       ("focal_metres", lambda r: r["camera"].update(focal_mm=r["camera"]["focal_mm"] / 1e3)),
                       ("pitch_nm", lambda r: r["camera"].update(pitch_um=r["camera"]["pitch_um"] * 1e3)),
                       ("probe_huge", lambda r: r["probe"].update(shape=[600, 1000, 600])),
                       ("probe_small", lambda r: r["probe"].update(shape=[6, 16, 6]))):
        fx[name] = capture_variant(name, edit)
    one_view("view_black", lambda dist, ref: (np.zeros_like(dist), ref))
    one_view("view_saturated", lambda dist, ref: (np.full_like(dist, 255), ref))
    one_view("view_copy", lambda dist, ref: (ref, ref))
    one_view("view_swapped", lambda dist, ref: (ref, dist))
    T = np.load(fx["run"] / "reconstruction.npz")["T"]
    np.save(work / "T.npy", T)
    for name, edit in (("fl_x_negative", {"fl_x": -5618.7}), ("image_range_zero", {"image_max": -16.8897858}),
                       ("truncated_json", "{\"fl_x\": 56"), ("frames_dict", {"frames": {"a": 1}}),
                       ("no_file_path", {"frames": [{"transform_matrix": [[1, 0, 0, 0]] * 4}]}), ("w_wrong", {"w": 721})):
        dst = work / name
        shutil.rmtree(dst, ignore_errors=True)
        dst.mkdir()
        for split in ("train", "val", "test"):
            meta = json.loads((PHANTOM1 / f"transforms_{split}.json").read_text())
            (dst / f"transforms_{split}.json").write_text(edit if isinstance(edit, str) else json.dumps({**meta, **edit}))
            (dst / split).symlink_to(PHANTOM1 / split)
        (dst / "3Dmask.mat").symlink_to(PHANTOM1 / "3Dmask.mat")
        fx[name] = dst
    cut = work / "cut.pt"
    data = (fx["run"] / "checkpoint.pt").read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    fx["cut"] = cut
    corrupt = work / "cache"
    shutil.rmtree(corrupt, ignore_errors=True)
    subprocess.run([sys.executable, "-m", "nerif", *TINY, "data.cache_dir=" + str(corrupt), "train.iterations=1",
                    f"hydra.run.dir={work / 'cache_run'}", "train.resume=auto"], cwd=ROOT, capture_output=True)
    for entry in corrupt.glob("*.npz"):
        entry.write_bytes(entry.read_bytes()[:64])
    fx["cache"] = corrupt
    return fx


def cases(work: Path, fx: dict) -> list[Case]:
    run = fx["run"]
    kept = [run / "metrics.json", run / "checkpoint.pt", run / "reconstruction.npz"]
    tr = lambda root: ["data=transforms", f"data.root={root}", "data.binning=8", *SOLVER]  # noqa: E731
    cap = lambda root, *more: ["data=capture", f"data.root={root}", "data.binning=8", *SOLVER, *more]  # noqa: E731
    out = lambda name: f"hydra.run.dir={work / 'runs' / name}"  # noqa: E731
    lock_dir = work / "runs" / "locked"

    def long_run() -> subprocess.Popen:
        shutil.rmtree(lock_dir, ignore_errors=True)
        p = subprocess.Popen([sys.executable, "-m", "nerif", *TINY, "train.iterations=100000", f"hydra.run.dir={lock_dir}"],
                             cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(600):
            if (lock_dir / ".nerif.lock").is_file() and (lock_dir / ".nerif.lock").read_text():
                break
            time.sleep(0.1)
        return p

    return [
        # silent wrong results
        Case("resume_other_scene", nerif(*TINY, "phantom.width_mm=9.0", f"train.resume={run / 'checkpoint.pt'}",
                                         out("resume_other")), "refuse", "made by another run", kept),
        Case("swapped_images", nerif(*cap(fx["swapped"]), out("swapped")), "refuse", "look swapped"),
        *[Case(f"one_{k}", nerif(*cap(fx[k]), out(k)), "warn", "camera 01 (41.2 deg) is left out") for k in
          ("view_black", "view_saturated", "view_copy", "view_swapped")],
        Case("background_before_probe", nerif(*cap(fx["background_near"]), out("bg")), "refuse",
             "camera.camera_to_background_mm"),
        Case("negative_focal_length", nerif(*TINY, "rig.focal_mm=-105", out("focal")), "refuse", "rig.focal_mm"),
        Case("negative_distance", nerif(*TINY, "rig.distance_mm=-800", out("distance")), "refuse", "rig.distance_mm"),
        Case("transforms_negative_fl_x", nerif(*tr(fx["fl_x_negative"]), out("flx")), "refuse", "fl_x"),
        Case("angles_in_radians", nerif(*cap(fx["radians"]), out("radians")), "warn", "radians"),
        Case("two_runs_one_folder", nerif(*TINY, f"hydra.run.dir={lock_dir}", "train.resume=auto"), "refuse",
             "another nerif run", during=long_run),
        Case("init_volume_temperature", nerif(*TINY, f"train.init_volume={work / 'T.npy'}", out("init")), "refuse",
             "T.npy holds values"),
        Case("transforms_constant_range", nerif(*tr(fx["image_range_zero"]), out("range")), "refuse", "image_max"),
        Case("stray_key_plain_block", nerif(*TINY, "+train.iteration=5", out("stray")), "refuse",
             "did you mean train.iterations"),
        # lost work
        Case("new_run_into_run_folder", nerif(*TINY, f"hydra.run.dir={run}"), "refuse", "holds an earlier run", kept),
        Case("write_capture_into_capture", ["nerif.write_capture", str(fx["capture"]), *CAPTURE, "rig.n_cameras=3"],
             "refuse", "is not empty", [fx["capture"] / "rig.yaml", fx["capture"] / "distorted_00.png"]),
        Case("write_capture_onto_file", ["nerif.write_capture", str(work / "T.npy"), *CAPTURE], "refuse", "is a file",
             [work / "T.npy"]),
        Case("write_capture_typo", ["nerif.write_capture", str(work / "typo"), *CAPTURE, "rig.n_camera=3"], "refuse",
             "rig.n_camera"),
        # sizes
        Case("occupancy_2000", nerif(*TINY, "field.occupancy_resolution=2000", out("occ")), "refuse",
             "field.occupancy_resolution"),
        Case("hidden_1e5", nerif(*TINY, "field.hidden=[100000,100000]", out("hidden")), "refuse", "field.hidden"),
        Case("supersample_32", nerif(*TINY, "phantom.shape=[64,64,64]", "data.render_supersample=32", out("ss")),
             "refuse", "data.render_supersample"),
        Case("rays_5e6", nerif(*TINY, "train.rays_per_batch=5000000", out("rays")), "refuse", "train.rays_per_batch"),
        Case("samples_2e5", nerif(*TINY, "sampler.samples_per_ray=200000", out("samples")), "refuse",
             "sampler.samples_per_ray"),
        Case("threads_1000", nerif(*TINY, "threads=1000", "train.iterations=2", out("threads")), "warn", "threads=1000"),
        # one sentence
        Case("rig_yaml_syntax", nerif(*cap(fx["rig_syntax"]), out("syntax")), "refuse", "rig.yaml is not valid YAML"),
        Case("rig_focal_abc", nerif(*cap(fx["focal_abc"]), out("abc")), "refuse", "camera.focal_mm"),
        Case("iterations_abc", nerif(*TINY, "train.iterations=abc", out("itabc")), "refuse", "train.iterations"),
        Case("seed_abc", nerif(*TINY, "seed=abc", out("seed")), "refuse", "seed="),
        Case("lr_zero", nerif(*TINY, "train.lr=0", out("lr0")), "refuse", "train.lr"),
        Case("lr_negative", nerif(*TINY, "train.lr=-1", out("lrneg")), "refuse", "train.lr"),
        Case("betas_out_of_range", nerif(*TINY, "train.betas=[1.5,0.9]", out("betas")), "refuse", "train.betas"),
        Case("lr_min_above_lr", nerif(*TINY, "train.lr_min=1", out("lrmin")), "refuse", "train.lr_min"),
        Case("eps_zero", nerif(*TINY, "train.eps=0", out("eps")), "refuse", "train.eps"),
        Case("checkpoint_every_zero", nerif(*TINY, "train.checkpoint_every=0", out("ck0")), "refuse",
             "train.checkpoint_every"),
        Case("image_every_zero", nerif(*TINY, "train.image_every=0", out("im0")), "refuse", "train.image_every"),
        Case("truncated_checkpoint", nerif(*TINY, f"train.resume={fx['cut']}", out("cut")), "refuse",
             "cut.pt is not a readable checkpoint"),
        Case("nerif_checkpoint_into_cgls", nerif(*TINY, "solver=cgls", f"train.resume={run / 'checkpoint.pt'}",
                                                 out("cgls")), "refuse", "made by another run"),
        Case("resume_run_folder", nerif(*TINY, "train.iterations=25", f"train.resume={run}", out("folder")), "warn",
             "resumed from"),
        Case("mixed_bit_depths", nerif(*cap(fx["mixed_depth"]), out("depth")), "refuse", "same bit depth"),
        Case("no_heldout_view", nerif(*cap(fx["capture"], "data.heldout=[]"), out("noheld")), "warn", "nerif:"),
        Case("rig_binning_for_capture", nerif(*cap(fx["capture"], "rig.binning=4"), out("rigbin")), "refuse",
             "data.binning"),
        Case("prior_reversed", nerif(*TINY, "field.prior=[0.05,-1.05]", out("prior")), "refuse", "field.prior"),
        Case("phantom_colder_than_T0", nerif(*TINY, "phantom.T_peak=150", out("cold")), "refuse",
             "colder than ambient"),
        Case("transforms_truncated_json", nerif(*tr(fx["truncated_json"]), out("json")), "refuse",
             "transforms_train.json is not valid JSON"),
        Case("transforms_frames_dict", nerif(*tr(fx["frames_dict"]), out("fdict")), "refuse", "frames must be a list"),
        Case("transforms_no_file_path", nerif(*tr(fx["no_file_path"]), out("nofp")), "refuse", "lacks file_path"),
        Case("transforms_w_wrong", nerif(*tr(fx["w_wrong"]), out("w")), "refuse", "the json's w and h"),
        Case("cache_in_proc", nerif(*TINY, "data.cache_dir=/proc/nerif", out("proc")), "refuse",
             "the cache folder /proc/nerif"),
        Case("cache_is_a_file", nerif(*TINY, f"data.cache_dir={work / 'T.npy'}", out("cfile")), "refuse",
             "T.npy (data.cache_dir"),
        Case("write_capture_static_series", ["nerif.write_capture", str(work / "static"), *CAPTURE, "data.frames=3"],
             "refuse", "data.frames"),
        Case("ctrl_c_while_rendering", nerif("device=cpu", "data.cache_dir=null", "data.render_supersample=6",
                                             out("ctrlc")), "refuse", "interrupted before training",
             interrupt_after=8.0),
        # issue 38: the capture path's classes of slips, each failing first
        Case("heldout_a_number", nerif(*cap(fx["capture"], "data.heldout=3"), out("held3")), "refuse",
             "data.heldout=3 must be a list of view indices"),
        Case("binning_as_float", nerif(*cap(fx["capture"], "data.binning=8.0"), out("bin8f")), "warn", "nerif:"),
        Case("binning_coarse", nerif(*cap(fx["capture"], "data.binning=40"), out("bin40")), "warn",
             "data.binning=40: a ray spans"),
        Case("flow_winsize_zero", nerif(*cap(fx["capture"], "flow.winsize=0"), out("win0")), "refuse",
             "flow=farneback with flow.winsize=0 cannot measure"),
        Case("sensor_px_swapped", nerif(*cap(fx["sensor_swapped"]), out("swaphw")), "refuse", "swap its two numbers"),
        Case("focal_in_metres", nerif(*cap(fx["focal_metres"]), out("focalm")), "refuse", "a focal length in metres"),
        Case("pitch_in_nanometres", nerif(*cap(fx["pitch_nm"]), out("pitchnm")), "refuse", "a pitch in nanometres"),
        Case("probe_grid_a_zero_too_many", nerif(*cap(fx["probe_huge"]), out("huge")), "refuse", "lower probe.shape"),
        Case("probe_smaller_than_flame", nerif(*cap(fx["probe_small"]), out("small")), "warn",
             "see the flame outside the probe box's image"),
        Case("gain_clipped", nerif(*cap(fx["gain_clipped"]), out("gain2")), "warn", "(clipped)"),
        Case("no_flame_in_any_view", nerif(*cap(fx["no_flame"]), out("noflame")), "refuse",
             "its distorted image equals its reference"),
        Case("run_into_its_capture", nerif(*cap(fx["capture"]), f"hydra.run.dir={fx['capture']}"), "refuse",
             "inside the capture folder", [fx["capture"] / "rig.yaml"]),
        Case("path_needs_quotes", nerif(*TINY, f"hydra.run.dir={work / 'runs' / 'a (b)'}"), "refuse",
             "quote it for Hydra"),
        Case("hash_levels_zero", nerif(*TINY, "field.hash_levels=0", out("lev0")), "refuse", "field.hash_levels=0"),
        Case("flow_factor_zero", nerif(*cap(fx["capture"]), "measure.flow_factor=0", out("ff0")), "refuse",
             "measure.flow_factor=0: a whole number"),
        Case("pixels_per_cell_zero", nerif(*cap(fx["capture"]), "data_term.pixels_per_cell=0", out("ppc0")), "refuse",
             "data_term.pixels_per_cell=0"),
        Case("interpolation_unknown", nerif(*cap(fx["capture"]), "data_term.interpolation=lanczos", out("interp")),
             "refuse", "data_term.interpolation=lanczos"),
        Case("render_at_unknown", nerif(*cap(fx["capture"]), "data_term.render_at=centre", out("renderat")),
             "refuse", "data_term.render_at must be corners or pixels"),
        Case("threshold_a_word", nerif(*TINY, "mask.threshold=abc", out("thrabc")), "refuse",
             "mask.threshold=abc: a number"),
        Case("write_capture_overwrite_first", ["nerif.write_capture", str(work / "wc_first"), "--overwrite", *CAPTURE],
             "warn", "written to"),
        Case("corrupt_cache_entry", nerif(*TINY, f"data.cache_dir={fx['cache']}", "train.iterations=2", out("cache")),
             "warn", "is damaged"),
    ]


def first_line(text: str, fragment: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    hit = [ln for ln in lines if fragment in ln]
    line = hit[0] if hit else (lines[-1] if lines else "")
    return line if len(line) <= 160 else line[:157] + "..."


def run_case(case: Case) -> dict:
    before = digest(case.keep)
    other = case.during() if case.during else None
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", *case.args], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env={**os.environ, **case.env})
    try:
        if case.interrupt_after is not None:
            time.sleep(case.interrupt_after)
            proc.send_signal(signal.SIGINT)
        text = proc.communicate(timeout=300)[0]
        rc = proc.returncode
    except subprocess.TimeoutExpired:
        proc.kill()
        rc, text = None, "timed out after 300 s"
    finally:
        if other is not None:
            other.kill()
            other.wait()
    lost = digest(case.keep) != before
    traceback = "Traceback" in text
    named = case.fragment in text
    code_ok = rc is not None and ((rc != 0) if case.expect == "refuse" else (rc == 0))
    verdict = "OK" if named and code_ok and not traceback and not lost else (
        "traceback" if traceback else "lost work" if lost else "unnamed" if not named else "exit code")
    return {"case": case.name, "expect": case.expect, "exit": rc, "message": first_line(text, case.fragment),
            "verdict": verdict, "seconds": round(time.perf_counter() - t0, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=None, help="names of the cases to run (all by default)")
    ap.add_argument("--out", default="benchmarks/results/misuse", help="output folder")
    args = ap.parse_args()
    out = Path(args.out).resolve()
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    fx = fixtures(work)
    shutil.rmtree(work / "runs", ignore_errors=True)  # each case's own run folder starts empty
    todo = [c for c in cases(work, fx) if args.cases is None or c.name in args.cases]
    rows = []
    for i, case in enumerate(todo):
        rows.append(run_case(case))
        print(f"[{i + 1}/{len(todo)}] {case.name}: {rows[-1]['verdict']}", flush=True)
    ok = sum(r["verdict"] == "OK" for r in rows)
    lines = [f"# Misuse: {ok} of {len(rows)} cases OK", "", "| case | expected | exit | first line of the message | verdict |",
             "|---|---|---|---|---|"]
    lines += [f"| {r['case']} | {r['expect']} | {r['exit']} | {r['message'].replace('|', '/')} | {r['verdict']} |"
              for r in rows]
    counts = {v: sum(r["verdict"] == v for r in rows) for v in sorted({r["verdict"] for r in rows})}
    lines += ["", "Verdicts: " + ", ".join(f"{k} {v}" for k, v in counts.items())]
    write_report(out, "misuse", {"rows": rows, "counts": counts}, "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
