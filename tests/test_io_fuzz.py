"""Any bytes or text given to a reader: a lineslam error or a documented skip, never a crash."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slam.errors import InputError
from slam.io import CarmenStats, iter_scans, read_g2o, read_relations, read_tum
from slam.io.carmen import CarmenReader

TOKENS = st.sampled_from(
    [
        "FLASER",
        "ODOM",
        "ROBOTLASER1",
        "RAWLASER1",
        "RLASER",
        "PARAM",
        "#",
        "3",
        "0",
        "-1",
        "1.5",
        "nan",
        "inf",
        "abc",
        "nohost",
        "1e308",
        "2",
        "180",
        "\t",
        "é",
    ]
)
LINES = st.lists(st.lists(TOKENS, max_size=25).map(" ".join), max_size=8).map("\n".join)
SETTINGS = settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


@SETTINGS
@given(content=st.one_of(LINES, st.binary(max_size=300)))
def test_carmen_reader_on_arbitrary_input(tmp_path, content):
    path = tmp_path / "f.clf"
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    for lenient in (False, True):
        stats = CarmenStats()
        try:
            for message in CarmenReader(path, lenient=lenient).messages():
                assert message.timestamp == message.timestamp  # not NaN
            list(iter_scans(path, lenient=lenient, stats=stats))
        except InputError as exc:  # LogFormatError included
            assert "f.clf" in str(exc)


@SETTINGS
@given(content=st.one_of(LINES, st.binary(max_size=300)))
@pytest.mark.parametrize("reader", [read_tum, read_relations, read_g2o])
def test_table_readers_on_arbitrary_input(tmp_path, reader, content):
    path = tmp_path / "f.txt"
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    try:
        reader(path)
    except InputError as exc:
        assert "f.txt" in str(exc)
