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


def test_an_entry_declares_what_it_allocates_and_one_that_does_not_declares_nothing():
    """The memory a run needs is summed from what its components declare (:mod:`nerif.memory`): a function entry
    through ``register(allocations=...)``, a class through its static method, nothing where it says nothing."""
    r = Registry("thing")
    r.register("grid", allocations=lambda cfg: [("the grid", "thing.cells", 4.0 * cfg["thing"]["cells"] ** 3)])(
        lambda cells: None)

    @r.register("table")
    class Table:
        @staticmethod
        def allocations(cfg):
            return [("the table", "thing.rows", 8.0 * cfg["thing"]["rows"])]

    r.register("plain")(object)
    assert r.allocations({"thing": {"name": "grid", "cells": 10}}, "thing") == [("the grid", "thing.cells", 4000.0)]
    assert r.allocations({"thing": {"name": "table", "rows": 5}}, "thing") == [("the table", "thing.rows", 40.0)]
    assert r.allocations({"thing": {"name": "plain"}}, "thing") == []
