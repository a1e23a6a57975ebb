"""The unit of every number nerif writes (:mod:`nerif.units`): declared by the module that computes it, else by the
ending of its name; nested keys by their own name, and an unknown key said to be unknown (so that a test of a real
run catches a new key)."""
import pytest

import nerif.evaluation  # noqa: F401  (declares the evaluation's figures)
import nerif.results  # noqa: F401  (declares the measurement's container)
import nerif.sensing.findings  # noqa: F401  (declares the measurement's findings)
import nerif.solvers.base  # noqa: F401  (declares the loop's figures and labels)
from nerif.units import DEFLECTION, declare, metric_units, unit_of


def test_units_by_declaration_and_by_ending():
    assert unit_of("deflection_rmse") == DEFLECTION and unit_of("heldout_deflection_rmse").startswith("rad")
    assert unit_of("temperature_rmse_flame_K") == "K" and unit_of("heldout_displacement_rmse_px_none") == "px"
    assert unit_of("setup_time_s") == "s" and unit_of("T_peak_position_mm") == "mm"
    assert unit_of("flame_volume_true_cm3") == "cm^3" and unit_of("heldout_psnr_db") == "dB"
    assert unit_of("solver") == "text" and unit_of("a_new_figure") is None


def test_nested_keys_are_named_by_their_own_name_and_camera_names_are_not_keys():
    m = {"iterations": 5, "history": [{"iteration": 1, "temperature_rmse_K": 3.0}],
         "measurement": {"camera 00 (0.0 deg)": {"noise": 0.01, "shake_px": [0.0, 0.1]}}, "mystery": 1.0}
    units = metric_units(m)
    assert units["noise"].startswith("1 (share of full scale") and units["shake_px"] == "px"
    assert units["iteration"] == "iterations" and units["temperature_rmse_K"] == "K"
    assert units["mystery"] == "?" and not any(k.startswith("camera") for k in units)
    assert units["measurement"].startswith("(per camera name")


def test_a_key_declared_again_must_mean_the_same():
    declare(a_test_figure_px="px (of the full sensor)")
    declare(a_test_figure_px="px (of the full sensor)")  # the same again: fine
    with pytest.raises(ValueError, match="the unit of a_test_figure_px is declared twice"):
        declare(a_test_figure_px="mm")
