import pytest

from nerif.encoders import ENCODERS
from nerif.registry import Registry
from nerif.renderers import GRADIENTS, SAMPLERS


def test_registries_hold_the_paper_variants():
    assert ENCODERS.names() == ["frequency", "hash", "none"]
    assert {"auto", "discrete"} <= set(GRADIENTS.names())
    assert "uniform" in SAMPLERS


def test_unknown_name_lists_registered_ones():
    with pytest.raises(ValueError, match="registered encoders: frequency, hash, none"):
        ENCODERS.build({"name": "fourier"})


def test_register_twice_is_an_error():
    r = Registry("thing")
    r.register("a")(object)
    with pytest.raises(ValueError, match="twice"):
        r.register("a")(object)
