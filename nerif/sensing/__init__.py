"""BOS sensing: what a rig measures of a field (``SENSING``: ideal, perpendicular, realistic), background
patterns (``PATTERNS``), finite-aperture optics, deflection <-> displacement, image formation and optical flow
(``FLOW``)."""
from nerif.sensing.flow import FLOW
from nerif.sensing.models import SENSING
from nerif.sensing.patterns import PATTERNS

__all__ = ["FLOW", "PATTERNS", "SENSING"]
