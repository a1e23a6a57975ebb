"""What the measurement stage found in one view: one typed record (:class:`Findings`), made by
:func:`nerif.sensing.measurement.measure_view`, held by each :class:`nerif.data.scene.View`, read by the checks of
:mod:`nerif.data.diagnostics`, the data terms' noise weights and the run's report (``metrics.json``'s
``measurement``, by camera name: :meth:`Findings.report`)."""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Optional

from nerif.units import SHARE, declare

declare(occluded=SHARE, valid_fraction=SHARE, clipped=SHARE, saturated=SHARE, rejected=SHARE, unmeasured=SHARE,
        noise="1 (share of full scale, each exposure)", image_noise="1 (share of full scale, each exposure)",
        reference_noise="1 (share of full scale)", difference_rms="1 (share of full scale)",
        texture_ratio="1 (ratio)", flow_factor="1 (factor)", exposures="exposures",
        from_cache="text (true: read from the cache)")


@dataclass
class Findings:
    """One view's measurement findings; a field is None where the view's data did not give it.

    Attributes:
        difference_rms: RMS of the two exposures' difference [share of full scale] (0: the same image).
        texture_ratio: the distorted exposure's median local contrast over the reference's (about 1: the same
            background; near 0: black, flat or overexposed).
        flow_factor: the flow and the texture's detectors read the images made this many times smaller.
        clipped: share of the pixels at full scale in either exposure, as recorded.
        saturated, occluded, unmeasured, rejected: shares of the ray grid left out, each for its cause (the
            exposures at the top of their range; no texture in the reference; no estimate from the flow; an outlier
            vector).
        normalise_px: the width over which the flow normalised the images [px of the images as recorded]; None: it
            did not.
        shake_px: (column, row) the camera's rigid shift between the exposures as the flow read it (with its gain,
            1.1-1.2x on sub-pixel shifts), taken off its displacements and added back by the image terms [px of the
            full sensor].
        shake_images_px: the same shift read from the images themselves where the view sees no flame
            (:func:`nerif.sensing.shake.photometric_shift`, 0.98-1.00x): the noise is read through it. The image
            terms keep the flow's reading: with this one the shared dirty capture's sigma error was 0.1140 against
            0.1110 (issue 70), though its shakes are found 10x more exactly.
        displacement_max_px: the largest displacement kept [px of the full sensor].
        valid_fraction: share of the ray grid kept.
        outside_px: the 99th percentile of the displacements' size where the view sees no flame [px of the full
            sensor]; None where too few pixels do.
        noise: one exposure's noise [share of full scale] where the view sees no flame; None where too few pixels
            are usable.
        from_cache: the measurement was read from the cache (a capture's).
        exposures: (distorted, reference) exposures averaged into each image (a capture's).
        image_noise, reference_noise: the noise of those averages [share of full scale], None where one exposure
            (a capture's).
    """

    difference_rms: Optional[float] = None
    texture_ratio: Optional[float] = None
    flow_factor: Optional[int] = None
    clipped: Optional[float] = None
    saturated: Optional[float] = None
    occluded: Optional[float] = None
    normalise_px: Optional[float] = None
    unmeasured: Optional[float] = None
    shake_px: Optional[list] = None
    shake_images_px: Optional[list] = None
    rejected: Optional[float] = None
    displacement_max_px: Optional[float] = None
    valid_fraction: Optional[float] = None
    outside_px: Optional[float] = None
    noise: Optional[float] = None
    from_cache: Optional[bool] = None
    exposures: Optional[list] = None
    image_noise: Optional[float] = None
    reference_noise: Optional[float] = None

    # a capture's own findings, set together (from_cache never None then): reported only where a capture set them
    CAPTURE = ("from_cache", "exposures", "image_noise", "reference_noise")

    @classmethod
    def read(cls, values: dict) -> "Findings":
        """The record of ``values`` (name -> value, as :meth:`report` or a cached measurement wrote them); names it
        does not hold are left out (a cache written by another nerif)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in values.items() if k in names})

    def report(self) -> dict:
        """Name -> value, for ``metrics.json`` and the measurement cache: every finding of the measurement stage,
        and a capture's own where a capture set them (``from_cache`` not None)."""
        return {k: v for k, v in asdict(self).items() if k not in self.CAPTURE or self.from_cache is not None}
