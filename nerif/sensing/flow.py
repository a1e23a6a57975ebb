"""Displacement estimation between a distorted and a reference BOS image (OpenCV optical flow).

Every estimator is ``fn(distorted, reference, **params) -> (H, W, 2) float32 [px]`` (column, row) with
``distorted(x) ~ reference(x + u(x))``, the convention of :mod:`nerif.sensing.imaging`, registered in
:data:`FLOW`.
"""
from __future__ import annotations

import inspect
from typing import Optional

import cv2
import numpy as np

from nerif.registry import Registry
from nerif.sensing.flame_light import LIGHT_SEEN, light_structure
from nerif.export import to_uint8
from nerif.sensing.texture import AUTO_WIDTH_RANGE_PX, texture_width

FLOW = Registry("optical flow", package="nerif.sensing")


def warped(reference: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(H, W) ``reference`` seen through the flow ``u`` (H, W, 2) [px]: ``reference(x + u(x))`` (cubic), what the
    distorted exposure shows where the flow is right."""
    h, w = reference.shape
    cols, rows = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    u = np.nan_to_num(np.asarray(u, dtype=np.float32))
    return cv2.remap(np.float32(reference), cols + u[..., 0], rows + u[..., 1], cv2.INTER_CUBIC,
                     borderMode=cv2.BORDER_REFLECT)


def misfit(distorted: np.ndarray, reference: np.ndarray, u: np.ndarray, width_px: float) -> float:
    """How badly the flow ``u`` (H, W, 2) [px] explains ``distorted`` (H, W) from ``reference`` (H, W): the RMS
    difference of the two, both :func:`normalised` over ``width_px``, the reference seen through ``u``
    (:func:`warped`); a common yardstick for flows estimated over different widths (the RMS, not the median: a flow
    thrown off where the flame shines fails over a small part of the view)."""
    e = normalised(distorted, width_px) - normalised(warped(reference, u), width_px)
    return float(np.sqrt(np.mean(e * e)))


def estimate(flow: dict, distorted: np.ndarray, reference: np.ndarray, texture_px: Optional[float] = None
             ) -> tuple[np.ndarray, Optional[float]]:
    """The flow of ``flow`` (a :data:`FLOW` config) from ``reference`` (H, W) to ``distorted`` (H, W), and the width
    [px] both were normalised over (:func:`normalised`; None: not at all).

    ``normalise_px: auto`` is resolved here. The flow is first estimated over the widest window,
    :data:`AUTO_WIDTH_RANGE_PX`'s upper end, which measures a clean pair best (the shared clean capture: T RMSE
    12.5 K over 8 px, 13.3 K over 2 px). Where the distorted exposure then still differs from the reference seen
    through that flow by light with structure (:func:`nerif.sensing.flame_light.light_structure` above
    :data:`~nerif.sensing.flame_light.LIGHT_SEEN`: the flame's own light; comparing through the flow keeps a flame's
    own displacements, which move the texture's local means, from reading as light), it is estimated again over the
    texture's own width (:func:`texture_width`; ``texture_px`` where the caller has it), where light defocused over a
    few pixels drops out with the illumination, and the flow that explains the images better (:func:`misfit` over
    the texture's width) is kept. Light blurred over 2 px throws the 8 px flow off (the shared dirty capture: 3.4 px
    of error, 0.061 px over 2 px; the narrow flow's misfit 20 % lower); light blurred over 3 px does not, and the
    narrow flow is worse there (the default rig's chain: 0.037 px over 8 px, 0.129 px over 2 px; its misfit 11-40 %
    higher)."""
    setting = flow.get("normalise_px")
    if setting != "auto":
        return FLOW.build(flow, distorted=distorted, reference=reference), setting
    wide = AUTO_WIDTH_RANGE_PX[1]
    u = FLOW.build({**flow, "normalise_px": wide}, distorted=distorted, reference=reference)
    width = texture_px or texture_width(reference)
    seen = warped(reference, u)
    unknown = ~np.isfinite(u).all(-1)
    seen[unknown] = np.float32(distorted)[unknown]  # where the flow gave no estimate, no light is read
    if light_structure(distorted, seen, width) <= LIGHT_SEEN:
        return u, wide
    narrow = FLOW.build({**flow, "normalise_px": width}, distorted=distorted, reference=reference)
    if misfit(distorted, reference, narrow, width) < misfit(distorted, reference, u, width):
        return narrow, width
    return u, wide


def _auto(name: str, args: dict) -> np.ndarray:
    """A registered flow called with ``normalise_px=auto`` (its ``args``, the call's locals): :func:`estimate`'s."""
    params = {k: v for k, v in args.items() if k not in ("distorted", "reference")}
    return estimate({"name": name, **params}, args["distorted"], args["reference"])[0]


def _width(normalise_px) -> Optional[float]:
    """A registered flow's ``normalise_px``: a width [px] or None (``auto`` is :func:`estimate`'s to resolve)."""
    if normalise_px is None or isinstance(normalise_px, (int, float)) and normalise_px > 0:
        return normalise_px
    raise ValueError(f"flow.normalise_px={normalise_px!r} must be a positive width [px], null or auto")


def normalised(image: np.ndarray, width_px: Optional[float]) -> np.ndarray:
    """``image`` (H, W) in [0, 1] locally normalised: less its Gaussian blur of ``width_px`` [px], over its local
    RMS contrast there, mapped back about 0.5 (contrast 0.15): a smooth brightness change between the exposures
    drops out, additive (the flame's own light) and multiplicative (an illumination drift) alike. None: as it is."""
    if not width_px:
        return image
    img = np.float32(image)
    detail = img - cv2.GaussianBlur(img, (0, 0), float(width_px))
    contrast = np.sqrt(cv2.GaussianBlur(detail * detail, (0, 0), float(width_px))) + 1e-6
    return np.clip(0.5 + 0.15 * detail / contrast, 0.0, 1.0)


@FLOW.register("farneback")
def farneback(distorted: np.ndarray, reference: np.ndarray, pyr_scale: float = 0.5, levels: int = 5,
              winsize: int = 7, iterations: int = 5, poly_n: int = 5, poly_sigma: float = 1.1,
              normalise_px="auto") -> np.ndarray:
    """Farneback's polynomial-expansion flow (defaults: the paper's parameters), on float32 images scaled to
    0-255 (its thresholds assume 8-bit intensities: on [0, 1] images it returns ~zero flow), each first
    :func:`normalised` over ``normalise_px`` [px] where given (``auto``: see :func:`estimate`)."""
    if normalise_px == "auto":
        return _auto("farneback", locals())
    width = _width(normalise_px)
    d, r = (normalised(x, width) for x in (distorted, reference))
    return cv2.calcOpticalFlowFarneback(np.float32(d) * 255, np.float32(r) * 255, None,
                                        pyr_scale, levels, winsize, iterations, poly_n, poly_sigma, 0)


@FLOW.register("dis")
def dis(distorted: np.ndarray, reference: np.ndarray, preset: str = "medium", patch_size: int = 8,
        patch_stride: int = 3, refinement_iterations: int = 5, normalise_px: Optional[float] = None) -> np.ndarray:
    """Dense inverse search (Kroeger et al. 2016) with variational refinement, on 8-bit images, each first
    :func:`normalised` over ``normalise_px`` [px] where given (``auto``: see :func:`estimate`)."""
    if normalise_px == "auto":
        return _auto("dis", locals())
    width = _width(normalise_px)
    distorted, reference = (normalised(x, width) for x in (distorted, reference))
    presets = {"ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
               "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}
    if preset not in presets:
        raise ValueError(f"DIS preset '{preset}' unknown; choose one of: {', '.join(presets)}")
    for key, value, least in (("patch_size", patch_size, 2), ("patch_stride", patch_stride, 1),
                              ("refinement_iterations", refinement_iterations, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:  # OpenCV would crash the process
            raise ValueError(f"flow.{key}={value!r} must be a whole number, at least {least}")
    if patch_stride > patch_size:
        raise ValueError(f"flow.patch_stride={patch_stride} must not exceed flow.patch_size={patch_size}")
    est = cv2.DISOpticalFlow_create(presets[preset])
    est.setPatchSize(patch_size)
    est.setPatchStride(patch_stride)
    est.setVariationalRefinementIterations(refinement_iterations)
    return est.calc(to_uint8(distorted), to_uint8(reference), None)


TEST_SHIFT_PX = (0.6, -0.4)  # the known shift of :func:`check_flow`'s test pair (column, row) [px]
TEST_TOLERANCE_PX = 0.2  # the median error a flow may make on it


def check_flow(flow: dict) -> None:
    """One sentence, before the flow runs on any view, where the settings of ``flow`` (a :data:`FLOW` config) cannot
    measure: the flow must find a known shift (:data:`TEST_SHIFT_PX`) of a random texture (128 x 128 px, blurred
    over 1.5 px) within :data:`TEST_TOLERANCE_PX` in the median. Settings OpenCV refuses, and settings it takes but
    that measure nothing (a window of 0 or 1 px, no iteration), both say so here rather than as an empty view each."""
    rng = np.random.default_rng(0)
    reference = cv2.GaussianBlur(rng.random((128, 128)).astype(np.float32), (0, 0), 1.5)
    reference = 0.5 + 0.35 * (reference - reference.mean()) / reference.std()
    u_true = np.broadcast_to(np.float32(TEST_SHIFT_PX), (128, 128, 2))
    distorted = warped(reference, u_true)
    defaults = {k: p.default for k, p in inspect.signature(FLOW.get(flow["name"])).parameters.items()}
    changed = {k: v for k, v in flow.items() if k != "name" and defaults.get(k, object()) != v}
    settings = ", ".join(f"flow.{k}={v}" for k, v in (changed or flow).items() if k != "name") or "its defaults"
    try:
        u, _ = estimate(flow, distorted, reference)
    except cv2.error as e:
        said = (e.err or str(e)).strip().splitlines()[0]
        raise ValueError(f"flow={flow['name']} cannot run with {settings}: OpenCV says \"{said}\"") from None
    centre = np.asarray(u)[16:-16, 16:-16] - np.float32(TEST_SHIFT_PX)
    error = np.linalg.norm(centre, axis=-1)
    median = float(np.nanmedian(error)) if np.isfinite(error).any() else float("inf")
    if not median <= TEST_TOLERANCE_PX:
        found = "no estimate" if not np.isfinite(median) else f"an error of {median:.2f} px"
        raise ValueError(f"flow={flow['name']} with {settings} cannot measure a known shift of "
                         f"({TEST_SHIFT_PX[0]}, {TEST_SHIFT_PX[1]}) px on a test texture ({found}): look at the "
                         "flow.* settings (config group flow)")
