"""A plain fix is read without pydantic (``server.advising.parse_fix``, the hot path): whatever the body, the fix read
is GpsFixIn's, value for value and bit for bit, and a body GpsFixIn refuses is never read (it answers the 422, with its
errors). Independent answer: the model itself, on bodies drawn around its edges (ranges, types, names, nulls, repeats)."""

from __future__ import annotations

import json
import struct

import pytest
from hypothesis import given, settings as hsettings, strategies as st
from pydantic import ValidationError

from server.advising import PLAIN_FIX_RANGES, _plain_fix, fix_from_schema, parse_fix
from server.schemas import MS_TIMESTAMP_MIN, GpsFixIn

EDGES = [0.0, -0.0, 1.0, -1.0, 13.9, 70.0, 70.0000001, 90.0, -90.0, 90.0000001, 180.0, -180.00001, 360.0, 1e5, 1e5 + 1, -1000.0, 10_000.0,
         1_714_557_600.123, MS_TIMESTAMP_MIN, MS_TIMESTAMP_MIN - 1, 1e300, 5e-324]  # fmt: skip
NAMES = [*PLAIN_FIX_RANGES, "timestamp", "latitude", "longitude", "speed", "heading", "accuracy", "altitude", "x"]
value = st.one_of(
    st.sampled_from(EDGES), st.floats(allow_nan=False, allow_infinity=False), st.integers(-(2**60), 2**60), st.sampled_from([2**53, 2**53 - 1, -(2**53)]),
    st.none(), st.booleans(), st.text(max_size=3), st.just([1.0]), st.just({"a": 1}),
)  # fmt: skip


def _bits(fix) -> tuple:
    return tuple(None if v is None else struct.pack("<d", v) for v in (fix.t_unix_s, fix.lat_deg, fix.lon_deg, fix.speed_mps, fix.heading_deg, fix.accuracy_m))


def _model(text: str):
    try:
        return fix_from_schema(GpsFixIn.model_validate_json(text))
    except ValidationError:
        return None


def _check(text: str, plain_expected: bool | None = None) -> None:
    plain, model = _plain_fix(text), _model(text)
    if plain is not None:
        assert model is not None and _bits(plain) == _bits(model), text
    if plain_expected is not None:
        assert (plain is not None) == plain_expected, text
    for data in (text, text.encode()):  # the stream's text, a REST body's bytes
        if model is None:
            with pytest.raises(ValidationError):
                parse_fix(data)
        else:
            assert _bits(parse_fix(data)) == _bits(model)


@hsettings(max_examples=600, deadline=None, derandomize=True)
@given(fields=st.dictionaries(st.sampled_from(NAMES), value, max_size=7), base=st.booleans(), repeat=st.sampled_from([None, *PLAIN_FIX_RANGES]))
def test_a_plain_fix_is_read_as_gps_fix_in_reads_it_and_nothing_it_refuses(fields, base, repeat):
    body = {**({"t_unix_s": 1_714_557_600.25, "lat_deg": 48.86675, "lon_deg": 2.31728} if base else {}), **fields}
    text = json.dumps(body)
    if repeat is not None:  # a name twice (the last one counts for the model)
        text = text[:-1] + (", " if body else "") + f'"{repeat}": 91.5' + "}"
    _check(text)


def test_the_phones_fixes_take_the_plain_path_and_its_edges_are_the_models():
    phone = '{"t_unix_s":1714557600.125,"lat_deg":37.8044321,"lon_deg":-122.2711137,"speed_mps":13.4,"accuracy_m":4.0}'
    _check(phone, plain_expected=True)
    _check(' { "t_unix_s" : 1714557600 , "lat_deg" : -90, "lon_deg" : 180, "speed_mps": null, "heading_deg": 360, "altitude_m": -1000 } ', plain_expected=True)
    for bad in ['{"t_unix_s": 1714557600, "lat_deg": 90.0000001, "lon_deg": 2}', '{"t_unix_s": 1e11, "lat_deg": 1, "lon_deg": 2}',
                '{"t_unix_s": 1714557600, "lat_deg": NaN, "lon_deg": 2}', '{"t_unix_s": 1714557600, "lat_deg": 1, "lon_deg": 2, "speed_mps": Infinity}',
                '{"t_unix_s": 1714557600, "lat_deg": 1, "lon_deg": 2, "speed_mps": true}', '{"t_unix_s": null, "timestamp": 1714557600000, "lat_deg": 1, "lon_deg": 2}',
                '{"t_unix_s": 1714557600, "lat_deg": 1e400, "lon_deg": 2}', '{"t_unix_s": 1714557600, "lat_deg": 1, "lon_deg": 2, "lat_deg": 91}',
                '{"t_unix_s": 1714557600, "lat_deg": 1}', '[1, 2]', '{"t_unix_s": 1714557600, "lat_deg": 1, "lon_deg": 2', '"\\ud800"', '']:  # fmt: skip
        _check(bad, plain_expected=False)
