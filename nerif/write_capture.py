"""Write a capture folder (images + ``rig.yaml``) from a synthetic scene sensed realistically.

    python -m nerif.write_capture PATH [config overrides]
    python -m nerif.write_capture /tmp/capture phantom=axisymmetric rig.n_cameras=8

The folder is what ``python -m nerif data=capture data.root=PATH`` reads: the same loop as a real experiment.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from nerif.configs import compose, group
from nerif.data import DATASETS
from nerif.data.capture import write_capture


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("path", help="the capture folder to write (created)")
    ap.add_argument("overrides", nargs="*", help="config overrides of the synthetic scene (data.sensing is realistic)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cfg = compose(["data=synthetic", "data.sensing=realistic"] + list(args.overrides))
    scene = DATASETS.build(group(cfg, "data"), device="cpu")
    root = write_capture(scene, Path(args.path))
    print(f"capture of {scene.n_views} views written to {root}; reconstruct it with: "
          f"python -m nerif data=capture data.root={root}")
    return root


if __name__ == "__main__":
    main()
