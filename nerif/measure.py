"""Measure one BOS image pair without a rig: check a camera and a background before building one.

    python -m nerif.measure REFERENCE DISTORTED                 # rays of 8 x 8 px, written to DISTORTED's stem
    python -m nerif.measure REFERENCE DISTORTED --ray-px 16 --out checks/pair1 --flow dis

Runs the measurement stage a capture's every view goes through (:func:`nerif.sensing.measurement.measure_view`:
saturation, occlusion, the optical flow, the shake, outliers) on the pair and writes, under ``--out``:
``measured.png`` (the reference with what was left out coloured by cause and each cause's share, beside the
displacement magnitude in px with pixel axes), ``measured.json`` (the shares, the vectors' noise floor, the
shake, the images' noise, the texture's scale, the time) and ``measured.npz`` (on the ray grid, rows first:
``displacement_px`` (h, w, 2) (column, row) [image px], NaN where left out; ``valid`` (h, w); ``left_out`` (h, w),
an index into ``causes``), and prints one line. Bad input is one sentence.
"""
from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

log = logging.getLogger("nerif.measure")


def measure_pair(reference: Path, distorted: Path, ray_px: int = 8, flow: str = "farneback", shake: bool = True):
    """The measurement of the pair (:class:`~nerif.sensing.measurement.ViewMeasurement`, on a grid of rays
    ``ray_px`` image pixels across), the reference image (H, W) in [0, 1], and the figures :func:`main` writes."""
    import cv2

    from nerif.data.capture_images import read_images
    from nerif.sensing.measurement import CAUSES, measure_view
    from nerif.sensing.texture import texture_scale_px
    from nerif.sensing.vectors import vector_noise

    for p in (reference, distorted):
        if not p.is_file():
            raise ValueError(f"{p} does not exist")
    shapes = []
    for p in (reference, distorted):
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"{p} is not a readable image")
        shapes.append(img.shape[:2])
    if shapes[0] != shapes[1]:
        raise ValueError(f"{distorted} is {shapes[1][1]} x {shapes[1][0]} px but {reference} is {shapes[0][1]} x "
                         f"{shapes[0][0]}: a pair is two exposures of one camera")
    H, W = shapes[0]
    if not isinstance(ray_px, int) or not 1 <= ray_px <= min(H, W) // 4:
        raise ValueError(f"--ray-px {ray_px}: a whole number of image pixels a ray, 1 to {min(H, W) // 4} for "
                         f"these {W} x {H} px images")
    ref, dist = read_images([reference, distorted], (W, H))
    t = time.perf_counter()
    m = measure_view(dist, ref, {"name": flow}, (H // ray_px, W // ray_px), shake=shake, name=distorted.name)
    seconds = time.perf_counter() - t
    figures = {"reference": str(reference), "distorted": str(distorted), "image_px": [W, H],
               "ray_px": ray_px, "rays": [W // ray_px, H // ray_px],
               "kept": float(m.valid.mean()),
               **{f"left_out_{c.replace(' ', '_')}": float(np.mean(m.left_out == k)) for k, c in enumerate(CAUSES) if k},
               "vector_noise_px": vector_noise(m.displacement, m.valid),
               "displacement_max_px": m.found.displacement_max_px, "shake_px": m.found.shake_px,
               "image_noise": m.found.noise, "texture_scale_px": texture_scale_px(ref),
               "flow_normalise_px": m.found.normalise_px, "flow_factor": m.found.flow_factor,
               "measure_time_s": seconds,
               "units": "px: image pixels of the pair; shares: of the ray grid; image_noise: of full scale"}
    return m, ref, figures


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m nerif.measure", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("reference", type=Path, help="the background without the flame (8- or 16-bit greyscale)")
    ap.add_argument("distorted", type=Path, help="the background seen through it, by the same camera")
    ap.add_argument("--ray-px", type=int, default=8, help="image pixels a ray is across (default 8)")
    ap.add_argument("--flow", default="farneback", help="the optical flow (farneback, dis, ...; default farneback)")
    ap.add_argument("--no-shake", action="store_true",
                    help="keep a rigid shift of the whole view (without a rig, the shake is read from the whole view, "
                         "where a flow that moves every pixel alike reads as shake)")
    ap.add_argument("--out", type=Path, default=None, help="folder to write (default: DISTORTED's stem + _measured)")
    ap.add_argument("--debug", action="store_true", help="an unexpected error's traceback (else one sentence)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = args.out or Path(f"{args.distorted.stem}_measured")
    try:
        from nerif.export import write_json, write_npz
        from nerif.io.plots import measured_figure, save_figure
        from nerif.sensing.flow import FLOW
        from nerif.sensing.measurement import CAUSES

        FLOW.get(args.flow)
        m, ref, figures = measure_pair(args.reference, args.distorted, args.ray_px, args.flow, not args.no_shake)
        out.mkdir(parents=True, exist_ok=True)
        write_json(figures, out / "measured.json")
        write_npz(out / "measured.npz", displacement_px=m.displacement, valid=m.valid, left_out=m.left_out,
                  causes=np.array(CAUSES))
        save_figure(measured_figure(ref, m.displacement, m.left_out, CAUSES,
                                    f"{args.distorted.name} against {args.reference.name}"), out / "measured.png")
    except (ValueError, OSError) as e:
        message = f"{e.filename}: {e.strerror}" if isinstance(e, OSError) and e.strerror else str(e).splitlines()[0]
        print(f"nerif.measure: error: {message}", file=sys.stderr, flush=True)
        sys.exit(2)
    except KeyboardInterrupt:
        print("nerif.measure: interrupted", file=sys.stderr, flush=True)
        sys.exit(130)
    except Exception as e:  # anything else is one sentence too (OpenCV's, a value of the wrong kind)
        if args.debug:
            raise
        from nerif.app import unexpected

        print(f"nerif.measure: error: {unexpected(e, '--debug')}", file=sys.stderr, flush=True)
        sys.exit(2)
    left = ", ".join(f"{100 * v:.1f} % {k[len('left_out_'):].replace('_', ' ')}" for k, v in figures.items()
                     if k.startswith("left_out_") and v > 0)
    print(f"nerif.measure: kept {100 * figures['kept']:.1f} % of {figures['rays'][0]} x {figures['rays'][1]} rays"
          f"{' (left out: ' + left + ')' if left else ''}; vectors' noise {figures['vector_noise_px']:.3f} px, "
          f"displacement up to {figures['displacement_max_px']:.2f} px, shake ({figures['shake_px'][0]:+.2f}, "
          f"{figures['shake_px'][1]:+.2f}) px; {figures['measure_time_s']:.1f} s | {out}", flush=True)
    return figures


if __name__ == "__main__":
    main()
