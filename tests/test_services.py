from __future__ import annotations

import pytest

from overbound.services import K_H_NPA, K_H_PA, K_V_PA, SERVICES, parse_service, resolve_services


@pytest.mark.parametrize(
    ("name", "hal", "val"),
    [
        ("NPA", 556, None),
        ("APV-I", 40, 50),
        ("APV-II", 40, 20),
        ("LPV", 40, 50),
        ("LPV-200", 40, 35),
        ("CAT-I", 40, 15),
    ],
)
def test_alert_limits(name, hal, val):
    s = SERVICES[name]
    assert (s.hal, s.val) == (hal, val)
    assert s.source


def test_approach_requirements():
    for name in ("APV-I", "APV-II", "LPV", "LPV-200", "CAT-I"):
        s = SERVICES[name]
        assert (s.integrity_risk, s.integrity_exposure_s, s.continuity_risk, s.continuity_window_s) == (
            2e-7,
            150.0,
            8e-6,
            15.0,
        )
    assert SERVICES["APV-I"].tta_s == 10 and SERVICES["LPV-200"].tta_s == 6
    assert (K_V_PA, K_H_PA, K_H_NPA) == (5.33, 6.0, 6.18)


@pytest.mark.parametrize("spec", ["lpv200", "LPV-200", "lpv_200"])
def test_names_parse_loosely(spec):
    assert parse_service(spec) is SERVICES["LPV-200"]


def test_user_defined():
    s = parse_service("GLS:16:10")
    assert (s.name, s.hal, s.val, s.continuity_window_s) == ("GLS", 16.0, 10.0, 15.0)
    assert parse_service("HONLY:100:-").val is None


@pytest.mark.parametrize("bad", ["FOO", "X:1", "X:a:b", "X:-1:5", ":1:2"])
def test_bad_specs(bad):
    with pytest.raises(ValueError, match="service"):
        parse_service(bad)


def test_resolve_default_and_duplicates():
    assert [s.name for s in resolve_services(None)] == list(SERVICES)
    with pytest.raises(ValueError, match="twice"):
        resolve_services(["LPV", "lpv"])
