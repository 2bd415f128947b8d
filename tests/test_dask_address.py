"""A bad or unreachable Dask scheduler address: one line and exit 2, no traceback."""

from __future__ import annotations

import pytest
from conftest import SAMPLES

from i2v_loc.cli import main

pytest.importorskip("distributed")
pytestmark = pytest.mark.timeout(120)


@pytest.mark.parametrize(
    "address, words",
    [
        ("nonsense::address", "invalid address"),
        ("tcp://127.0.0.1:1", "Timed out trying to connect"),
    ],
)
def test_bad_dask_address_is_one_line_and_exit_2(tmp_path, capsys, address, words):
    code = main(
        [
            "eval",
            str(SAMPLES / "twizy_single_turn"),
            "--out",
            str(tmp_path / "report"),
            "--executor",
            "dask",
            "--address",
            address,
            "--quiet",
            "--no-plots",
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.splitlines() == [err] and f"cannot connect to the Dask scheduler at {address!r}" in err and words in err
