"""The committed train / validation / test split of the thesis's numbers."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from nlcx.errors import ConfigError
from nlcx.thesis import catalog, split

SPEC = Path(__file__).resolve().parents[1] / "configs" / "identify" / "split.yaml"


def test_every_thesis_number_is_in_exactly_one_part() -> None:
    s = split.load(SPEC)
    tables = [t for part in split.PARTS for t in s.pendulum.model_dump()[part]]
    methods = [m for part in split.PARTS for m in s.cstr.model_dump()[part]]
    assert sorted(tables) == sorted(set(catalog.thesis_metrics().table))
    assert sorted(methods) == sorted(set(catalog.cstr_table().method))
    assert len(tables) == len(set(tables)) and len(methods) == len(set(methods))


def test_the_split_is_the_one_the_issue_fixed_before_any_fit() -> None:
    s = split.load(SPEC)
    assert s.pendulum.train == ["2.3", "2.5", "3.7"] and s.cstr.train == ["ZN"]
    assert s.pendulum.validation == ["2.4", "2.6", "3.9"]
    assert set(s.cstr.test) == {"Fuzzy", "ANN", "ANFIS", "GA"}


def test_cells_hand_out_one_part_only() -> None:
    s = split.load(SPEC)
    seen = set()
    for part in split.PARTS:
        pend, cstr = split.cells(s, part)
        assert set(pend.table) == set(s.pendulum.model_dump()[part])
        assert set(pend.metric) <= set(s.metrics)
        assert set(cstr.method) == set(s.cstr.model_dump()[part])
        keys = {tuple(r) for r in pend[["table", "signal", "controller", "metric"]].itertuples(index=False)}
        assert not keys & seen
        seen |= keys
    zn = split.cells(s, "train")[1].set_index("metric").value
    assert zn["tr"] == 1.78 and zn["ts"] == 3.74 and zn["Mp"] == 20.05  # Table 5.8's ZN row


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"pendulum": {"train": ["2.3"], "test": ["2.3"]}}, "2.3 is in both train and test"),
        ({"pendulum": {"train": ["9.9"]}}, "config error: pendulum.train = '9.9': not in the thesis"),
    ],
)
def test_a_bad_split_is_refused(tmp_path: Path, change: dict, message: str) -> None:
    raw = yaml.safe_load(SPEC.read_text()) | change
    path = tmp_path / "split.yaml"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=message):
        split.load(path)
