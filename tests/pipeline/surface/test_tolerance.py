"""The ISO 10110-5 form tolerance notation: what is read, what is refused and why."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wavestack.pipeline.surface import DEFAULT_TEST_WAVELENGTH_NM, FormTolerance, ToleranceError, fringe_nm
from wavestack.pipeline.surface import parse_form_tolerance


@pytest.mark.parametrize(("text", "expected"), [
    ("3/2(0.5/0.2)", dict(sag=2.0, irr=0.5, rsi=0.2)),
    ("3/5(1)", dict(sag=5.0, irr=1.0)),
    ("3/3", dict(sag=3.0)),
    ("3/-(-/-; RMSi < 0.05)", dict(rmsi=0.05)),
    ("3/-(0.5/-; RMSt<0.1; RMSa <= 0.02)", dict(irr=0.5, rmst=0.1, rmsa=0.02)),
    (" 3 / 1.5 ( 0.25 / 0.1 ) ", dict(sag=1.5, irr=0.25, rsi=0.1)),
    ("3/\u22121(0.3)".replace("\u22121", "-"), dict(irr=0.3)),  # the unicode minus as '-'
    ("3/2(0.5/0.2; RMSI < 0.1)", dict(sag=2.0, irr=0.5, rsi=0.2, rmsi=0.1)),
    ("3/1e0(5e-1)", dict(sag=1.0, irr=0.5)),
])
def test_reads_the_drawing_notation_in_fringes_at_546_nm(text: str, expected: dict[str, float]) -> None:
    tolerance = parse_form_tolerance(text)
    assert tolerance.wavelength_nm == DEFAULT_TEST_WAVELENGTH_NM
    for name in ("sag", "irr", "rsi", "rmst", "rmsi", "rmsa"):
        assert getattr(tolerance, name) == expected.get(name), name


@pytest.mark.parametrize("text", ["3/2(0.5/0.2) lambda = 632.8 nm", "3/2(0.5/0.2); \u03bb=632.8nm",
                                  "3/2(0.5/0.2; lambda = 632.8 nm)", "3/2(0.5/0.2) LAMBDA=632.8"])
def test_a_stated_wavelength_is_the_fringes_wavelength(text: str) -> None:
    tolerance = parse_form_tolerance(text)
    assert tolerance.wavelength_nm == 632.8
    # the limits in nm use it: one fringe is half a wavelength of surface
    assert tolerance.limits_nm()["IRR"] == pytest.approx(0.5 * 632.8 / 2)


def test_values_in_nm_become_fringes_at_the_drawing_wavelength() -> None:
    tolerance = parse_form_tolerance("3/-(100 nm/-; RMSi < 20nm) lambda = 632.8 nm")
    assert tolerance.irr == pytest.approx(100 / 316.4)
    assert tolerance.limits_nm() == pytest.approx({"IRR": 100.0, "RMSi": 20.0})


@pytest.mark.parametrize(("text", "where", "what"), [
    ("2(0.5/0.2)", "character 1", "'3/'"),
    ("3/2(x)", "character 5", "irregularity (IRR)"),
    ("3/2(0.5/0.2", "the end of the text", "')'"),
    ("3/2(0.5/0.2; RMSq < 1)", "character 13", "RMS limit"),
    ("3/2(0.5/0.2; RMSi < 0.1; RMSi < 0.2)", "character 26", "RMSi is given again"),
    ("3/0(0.5)", "character 3", "zero tolerance"),
    ("3/-2(0.5)", "character 3", "sagitta error (SAG)"),
    ("3/2(0.5) lambda = 5 nm", "character 19", "between 100 and 20000"),
    ("3/2(0.5) extra", "character 10", "the end of the tolerance or a wavelength"),
])
def test_refuses_what_it_cannot_read_with_the_place_and_the_reason(text: str, where: str, what: str) -> None:
    with pytest.raises(ToleranceError) as caught:
        parse_form_tolerance(text)
    message = str(caught.value)
    assert message.startswith(f"tolerance {text!r}:")
    assert where in message and what in message
    assert "\n" not in message


def test_a_tolerance_of_dashes_only_tolerances_nothing() -> None:
    with pytest.raises(ToleranceError, match="nothing is toleranced"):
        parse_form_tolerance("3/-(-/-)")


def test_a_non_string_is_refused() -> None:
    with pytest.raises(ToleranceError, match="expected text"):
        parse_form_tolerance(3.5)  # type: ignore[arg-type]


_limits = st.one_of(st.none(), st.floats(min_value=0.001, max_value=1000, allow_nan=False).map(lambda v: round(v, 4)))


@given(sag=_limits, irr=_limits, rsi=_limits, rms=st.sampled_from(["", "t", "i", "a"]),
       rms_value=st.floats(min_value=0.001, max_value=10).map(lambda v: round(v, 4)),
       wavelength=st.one_of(st.none(), st.floats(min_value=100, max_value=20000).map(lambda v: round(v, 2))))
def test_written_and_read_back(sag: float | None, irr: float | None, rsi: float | None, rms: str,
                               rms_value: float, wavelength: float | None) -> None:
    def write(value: float | None) -> str:
        return "-" if value is None else repr(value)
    clause = f"; RMS{rms} < {rms_value!r}" if rms else ""
    text = f"3/{write(sag)}({write(irr)}/{write(rsi)}{clause})" + (f" lambda = {wavelength!r} nm" if wavelength else "")
    if sag is None and irr is None and rsi is None and not rms:
        with pytest.raises(ToleranceError):
            parse_form_tolerance(text)
        return
    tolerance = parse_form_tolerance(text)
    assert (tolerance.sag, tolerance.irr, tolerance.rsi) == (sag, irr, rsi)
    assert getattr(tolerance, f"rms{rms}", None) == (rms_value if rms else None) if rms else True
    assert tolerance.wavelength_nm == (wavelength or DEFAULT_TEST_WAVELENGTH_NM)
    scale = fringe_nm(tolerance.wavelength_nm)
    assert tolerance.limits_nm() == pytest.approx({k: v * scale for k, v in tolerance.limits().items()})


@given(st.text(max_size=30))
def test_any_text_is_read_or_refused_with_a_tolerance_error(text: str) -> None:
    try:
        result = parse_form_tolerance(text)
    except ToleranceError as error:
        assert str(error).startswith("tolerance ")
    else:
        assert isinstance(result, FormTolerance) and result.limits()
