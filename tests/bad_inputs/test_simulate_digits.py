"""``fingerfit simulate --fingers``: the digits to simulate, thumb included."""

from __future__ import annotations

from pathlib import Path

import pytest

from ._cli import listing, refused, run


@pytest.mark.parametrize(
    ("value", "fragments"),
    [
        ("thumb,index,thumb", ("field '--fingers'", "names thumb twice")),
        ("thumbs,index", ("field '--fingers'", "thumb, index, middle, ring, little")),
        (",", ("field '--fingers'", "comma-separated names")),
    ],
)
def test_bad_digit_list_is_refused_before_anything_is_written(
    tmp_path: Path, value: str, fragments: tuple[str, ...]
) -> None:
    before = listing(tmp_path)
    result = run("simulate", tmp_path / "out", "--subjects", "1", "--fingers", value, "-q")
    refused(result, *fragments)
    assert listing(tmp_path) == before
    assert not (tmp_path / "out").exists()
