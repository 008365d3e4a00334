"""The unit tier's station file: its own, empty until a test allows a library."""

import pytest

from fakes.station import isolated_station


@pytest.fixture(scope="session", autouse=True)
def station_file(tmp_path_factory):
    yield from isolated_station(tmp_path_factory)
