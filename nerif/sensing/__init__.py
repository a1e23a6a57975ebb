"""BOS sensing: what a rig measures of a field (``SENSING``: ideal, perpendicular, realistic), background
patterns (``PATTERNS``), finite-aperture optics, deflection <-> displacement, image formation, optical flow
(``FLOW``) and the measurement stage of each view's images (``MEASUREMENT``)."""
from nerif.sensing.flow import FLOW
from nerif.sensing.measurement import MEASUREMENT
from nerif.sensing.models import SENSING
from nerif.sensing.patterns import PATTERNS

__all__ = ["FLOW", "MEASUREMENT", "PATTERNS", "SENSING"]
