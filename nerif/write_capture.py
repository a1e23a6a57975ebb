"""Write a capture folder (images + ``rig.yaml``) from a synthetic scene sensed realistically.

    python -m nerif.write_capture PATH [config overrides]
    python -m nerif.write_capture /tmp/capture phantom=axisymmetric rig.n_cameras=8
    python -m nerif.write_capture /tmp/sequence phantom=flicker data.frames=8   # a time series, 250 frames/s

The folder is what ``python -m nerif data=capture data.root=PATH`` reads: the same loop as a real experiment.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from nerif.configs import compose, group
from nerif.data import DATASETS
from nerif.data.capture import read_rig, write_capture
from nerif.data.frames import frames_of

log = logging.getLogger("nerif")


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("path", help="the capture folder to write (created)")
    ap.add_argument("overrides", nargs="*", help="config overrides of the synthetic scene (data.sensing is realistic)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cfg = compose(["data=synthetic", "data.sensing=realistic"] + list(args.overrides))
    data = group(cfg, "data")
    frames = frames_of(data)
    if frames is None:
        root = write_capture(DATASETS.build(data, device="cpu"), Path(args.path))
    else:
        def scenes():
            for j, f in enumerate(frames):
                log.info("frame %d of %d (t = %.4g s): rendering", j + 1, len(frames), f.time_s)
                yield DATASETS.build(data, frame=f.index, device="cpu")

        root = write_capture(scenes(), Path(args.path), times=[f.time_s for f in frames])
    views = len(read_rig(root)["views"]["angles_deg"])
    what = f"{len(frames)} frame{'s' * (len(frames) != 1)} of {views} views" if frames else f"{views} views"
    print(f"capture of {what} written to {root}; reconstruct it with: python -m nerif data=capture data.root={root}")
    return root


if __name__ == "__main__":
    main()
