"""docs/scenarios.md is generated from the comments next to the scenario dataclasses' fields: every
key has one, and the committed page is current (``make docs`` rewrites it)."""

from __future__ import annotations

import dataclasses

from sustain_drake.station import reference


@dataclasses.dataclass
class _Example:
    """An example section."""

    # The first line of a block above the field
    # and its second line.
    above: float = 1.0
    trailing: int = 2  # a trailing comment
    spanning: list[float] = dataclasses.field(
        default_factory=lambda: [1.0, 2.0])  # a comment on the field's last line
    bare: str = "#not a comment"


def test_comments_are_read_from_above_and_trailing_a_field():
    assert reference.field_comments(_Example) == {
        "above": "The first line of a block above the field and its second line.",
        "trailing": "a trailing comment",
        "spanning": "a comment on the field's last line",
    }
    assert reference.missing_comments(_Example) == ["(top).bare"]


def test_every_scenario_key_has_its_comment():
    assert reference.missing_comments() == []


def test_the_committed_reference_page_is_current():
    page = reference.reference_page()
    assert reference.PAGE.read_text(encoding="utf-8") == page, "run `make docs`"
    for key in ("hand_eye.depth_noise", "disturbances[] !ToolSlip", "kinesthetic.quasi_static"):
        assert f"## `{key}`" in page
