import numpy as np
import pytest

from nerif.physics import Ambient, check_temperature, delta_from_n, n_from_temperature, temperature_from_n

AIR = dict(T0=296.15, n0=1.00027)


def test_n_temperature_round_trip():
    T = np.linspace(250.0, 2500.0, 50)
    n = n_from_temperature(T, **AIR)
    np.testing.assert_allclose(temperature_from_n(n, **AIR), T, rtol=1e-9)
    assert n_from_temperature(AIR["T0"], **AIR) == pytest.approx(AIR["n0"], abs=1e-15)
    # hotter gas is optically thinner
    assert np.all(np.diff(n) < 0)


def test_normalised_field_scale_and_round_trip():
    amb = Ambient(T_max=2000.0, **AIR)
    # delta_thre by hand: (n0 - 1)(1 - T0 / T_max) / n0
    assert amb.delta_thre == pytest.approx(0.00027 * (1 - 296.15 / 2000.0) / 1.00027, rel=1e-12)
    assert amb.sigma_from_temperature(2000.0) == pytest.approx(-1.0, abs=1e-9)
    assert amb.sigma_from_temperature(AIR["T0"]) == pytest.approx(0.0, abs=1e-12)
    T = np.array([300.0, 800.0, 1500.0, 1999.0])
    np.testing.assert_allclose(amb.temperature_from_sigma(amb.sigma_from_temperature(T)), T, rtol=1e-7)
    assert delta_from_n(amb.n_from_sigma(-0.5), AIR["n0"]) == pytest.approx(-0.5 * amb.delta_thre, rel=1e-7)


@pytest.mark.parametrize("bad", [dict(T0=0.5, n0=1.0003, T_max=2000), dict(T0=296, n0=0.99, T_max=2000),
                                 dict(T0=296, n0=1.0003, T_max=200)])
def test_ambient_rejects_unphysical_states(bad):
    with pytest.raises(ValueError):
        Ambient(**bad)


def test_check_temperature_errors():
    with pytest.raises(ValueError, match="NaN"):
        check_temperature(np.array([300.0, np.nan]), "volume")
    with pytest.raises(ValueError, match="below 1 K"):
        check_temperature(np.array([300.0, 0.5]), "volume")


def test_unknown_hottest_temperature_keeps_sigma_units():
    amb = Ambient(1100.0, 1.00007253, None)
    assert not amb.temperature_known and amb.delta_thre == 1.0
    assert Ambient(296.15, 1.00027, 2000.0).temperature_known
