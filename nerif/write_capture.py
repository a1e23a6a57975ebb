"""Write a capture folder (images + ``rig.yaml``) from a synthetic scene sensed realistically.

    python -m nerif.write_capture PATH [config overrides]
    python -m nerif.write_capture /tmp/capture phantom=axisymmetric rig.n_cameras=8
    python -m nerif.write_capture /tmp/sequence phantom=flicker data.frames=8   # a time series, 250 frames/s
    python -m nerif.write_capture /tmp/capture --overwrite                      # replace an earlier capture whole

The folder is what ``python -m nerif data=capture data.root=PATH`` reads: the same loop as a real experiment.
"""
from __future__ import annotations

import argparse
import logging
import shutil
import sys
from pathlib import Path

from hydra.errors import HydraException

from nerif.configs import check_complete, compose, group
from nerif.data import DATASETS
from nerif.data.capture import read_rig, write_capture
from nerif.data.frames import frames_of

log = logging.getLogger("nerif")


def target_folder(path: Path, overwrite: bool) -> None:
    """One sentence when ``path`` cannot take a new capture: a file, or a folder with something in it (unless
    ``overwrite``: then it is replaced whole, once the new capture is complete)."""
    if path.exists() and not path.is_dir():
        raise ValueError(f"{path} is a file: give the folder to write the capture to")
    if path.is_dir() and any(path.iterdir()) and not overwrite:
        raise ValueError(f"{path} is not empty: choose a new folder, or add --overwrite to replace it whole")


def write(path: Path, overrides: list[str], overwrite: bool = False) -> Path:
    """Render the scene of ``overrides`` and write it as a capture to ``path``, atomically: into a sibling
    folder first, which then takes the place of ``path`` (an interrupted write leaves ``path`` as it was)."""
    target_folder(path, overwrite)
    cfg = compose(["data=synthetic", "data.sensing=realistic"] + list(overrides))
    check_complete(cfg)
    data = group(cfg, "data")
    frames = frames_of(data)
    staging = path.parent / f".{path.name}.writing"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        if frames is None:
            write_capture(DATASETS.build(data, device="cpu"), staging)
        else:
            def scenes():
                for j, f in enumerate(frames):
                    log.info("frame %d of %d (t = %.4g s): rendering", j + 1, len(frames), f.time_s)
                    yield DATASETS.build(data, frame=f.index, device="cpu")

            write_capture(scenes(), staging, times=[f.time_s for f in frames])
        if path.exists():
            old = path.parent / f".{path.name}.replaced"
            shutil.rmtree(old, ignore_errors=True)
            path.rename(old)
            staging.rename(path)
            shutil.rmtree(old)
        else:
            staging.rename(path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return path


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("path", help="the capture folder to write (created; it must be new or empty)")
    ap.add_argument("overrides", nargs="*", help="config overrides of the synthetic scene (data.sensing is realistic)")
    ap.add_argument("--overwrite", action="store_true", help="replace a folder that holds something, whole")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        root = write(Path(args.path), args.overrides, args.overwrite)
    except (ValueError, FileNotFoundError, OSError, HydraException) as e:  # one sentence, as python -m nerif
        message = str(e.args[0] if e.args else e).splitlines()[0]
        print(f"nerif.write_capture: error: {message}", file=sys.stderr, flush=True)
        sys.exit(2)
    except KeyboardInterrupt:
        print(f"nerif.write_capture: interrupted; {args.path} is as it was", file=sys.stderr, flush=True)
        sys.exit(130)
    rig = read_rig(root)
    views = len(rig["views"]["angles_deg"])
    n = len(rig.get("frames", []))
    what = f"{n} frame{'s' * (n != 1)} of {views} views" if n else f"{views} views"
    print(f"capture of {what} written to {root}; reconstruct it with: python -m nerif data=capture data.root={root}")
    return root


if __name__ == "__main__":
    main()
