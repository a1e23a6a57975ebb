"""The summary line: a run's headline figures read from its metrics into a typed record, each named in the line as
in ``metrics.json``."""
from pathlib import Path

from nerif.io.headline import Headline, StageChoice, summary_line
from nerif.physics import Ambient
from nerif.units import stage_key


def line_of(m: dict, unit: str = "rad") -> str:
    return summary_line(Headline.of(m, unit), Path("out"))


def test_the_summary_line_names_each_held_out_figure_as_metrics_json_does():
    m = {"deflection_rmse": 1e-5, "heldout_deflection_rmse": 2e-5, "heldout_psnr_db": 19.5,
         "heldout_displacement_rmse_px": 0.3, "heldout_displacement_psnr_db": 17.8, "iterations": 10,
         "wall_time_s": 1.0, "total_time_s": 54.0, "ms_per_iteration": 100.0}
    line = line_of(m)
    assert "deflection RMSE 2e-05 rad, PSNR 19.5 dB; displacement RMSE 0.3 px, PSNR 17.8 dB" in line
    assert "10 it: 1 s training (100.0 ms/it), 54 s in all" in line
    m.update(wall_time_s=7.0, total_time_s=6.0, heldout_psnr_db=float("nan"))  # issue 28: a resumed frame
    line = line_of(m)
    assert "10 it: 7 s training over every session (100.0 ms/it), 6 s in all this session" in line
    assert "PSNR undefined (no deflection seen)" in line  # not "PSNR -inf dB"
    assert "distances to the background" not in line  # deflections not measured from images: no lever arm given
    m["measurement"] = {"camera 00": {"noise": 0.01}}  # issue 69: a wrong background distance is a silent scale
    assert "deflection RMSE 1e-05 rad (its scale and the temperatures' set by the rig's distances to the background" \
        in line_of(m)


def test_the_summary_line_names_the_peak_temperature_the_true_one_and_the_flames_volume():
    """Issue 50: the temperatures a researcher reports, beside the RMSE that hides the tip."""
    m = {"temperature_rmse_K": 18.8, "deflection_rmse": 1e-5, "iterations": 10, "wall_time_s": 1.0,
         "total_time_s": 2.0, "ms_per_iteration": 100.0, "T_peak_K": 1542.4, "T_peak_position_mm": [0.5, 31.5, -0.5],
         "flame_volume_cm3": 12.34, "flame_volume_above_K": 1000.0}
    line = line_of(m)
    assert "T RMSE 18.8 K | peak T 1542 K at (0.5, 31.5, -0.5) mm, 12.3 cm3 above 1000 K |" in line
    m.update(T_peak_true_K=1861.0, T_peak_error_K=-318.6, flame_volume_true_cm3=15.1, T_std_at_peak_K=112.0)
    assert "peak T 1542 +- 112 K at (0.5, 31.5, -0.5) mm (true 1861 K, -319 K), 12.3 cm3 above 1000 K (true 15.1)" in \
        line_of(m)
    m.update(T_peak_interval_K=[1446.2, 2806.4], flame_volume_interval_cm3=[10.14, 16.9])  # issue 59: intervals
    assert ("peak T 1542 K (2 std: 1446-2806) at (0.5, 31.5, -0.5) mm (true 1861 K, -319 K), 12.3 cm3 "
            "(2 std: 10.1-16.9) above 1000 K (true 15.1)") in line_of(m)
    m.update(T_peak_field_K=1433.0, resolution_mm=0.771)  # issue 66: the peak read through the run's resolution
    assert "peak T 1542 K (2 std: 1446-2806) read through 0.77 mm of resolution (the field's 1433 K) at (0.5" in \
        line_of(m)


def test_the_share_of_the_held_out_displacements_explained_falls_with_the_fit_and_leads_the_summary():
    """Issue 38: a quality figure without a truth: 1 - (fit RMSE / no-flame RMSE)^2 of the held-out view, 0.75 for
    an RMSE half the displacements' own, negative for a fit worse than no flame; first of the held-out figures."""
    from nerif.metrics import explained_share

    assert explained_share(0.05, 0.1) == 0.75
    assert explained_share(0.12, 0.1) < 0
    line = line_of({"deflection_rmse": 1e-5, "heldout_deflection_rmse": 2e-5, "heldout_psnr_db": 19.5,
                    "heldout_explained": 0.75, "iterations": 10, "wall_time_s": 1.0, "total_time_s": 2.0,
                    "ms_per_iteration": 100.0})
    assert "held out: 75 % of its displacements explained; deflection RMSE 2e-05 rad" in line


def test_the_deflections_unit_is_the_ambients_and_the_stage_choice_is_typed():
    """The unit comes from the run's ambient gas (sigma where no temperature is inferred), not from which keys the
    metrics hold; the held-out views' choice between the flow's field and the images' is read into one record."""
    assert Ambient(296.15, 1.000277, 2000.0).deflection_unit == "rad"
    assert Ambient(296.15, 1.000277, None).deflection_unit == "sigma"
    m = {"deflection_rmse": 0.01, "heldout_deflection_rmse": 0.02, "heldout_psnr_db": 20.0, "iterations": 10,
         "wall_time_s": 1.0, "total_time_s": 2.0, "ms_per_iteration": 100.0, "data_term_kept": "flow",
         stage_key("flow"): {"heldout_misfit": 0.11}, stage_key("images"): {"heldout_misfit": 0.12}}
    h = Headline.of(m, "sigma")
    assert h.stages == StageChoice("flow", 0.12, 0.11, "sigma")
    line = summary_line(h, Path("out"))
    assert "deflection RMSE 0.01 sigma |" in line and "deflection RMSE 0.02 sigma, PSNR 20.0 dB" in line
    assert "kept the flow's field (held out: images 0.12, flow 0.11 sigma)" in line
    assert Headline.of(m, "rad").stages.unit == "px"  # physical deflections: the held-out displacements' px
    m[stage_key("flow")]["heldout_image_misfit"], m[stage_key("images")]["heldout_image_misfit"] = 0.021, 0.019
    assert "kept the flow's field (held-out image residual: images 1.9, flow 2.1 % of full range)" in line_of(m)
    assert "field kept: flow 2, images 1" in line_of({**{k: v for k, v in m.items() if not k.endswith("_stage")},
                                                       "data_term_kept": "flow 2, images 1"})
