"""The item catalogue: loading (located errors with did-you-mean) and the search order."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.catalogue import (
    CatalogueItem,
    SearchStop,
    UnknownItem,
    load_catalogue,
    search_order,
)

GOOD = """\
items:
  screwdriver:
    detector_class: screwdriver
    places: [tool_shelf, workbench]
    size: [0.20, 0.03, 0.03]
    dangerous: true
  tape:
    places: [workbench]
    size: [0.10, 0.10, 0.05]
  box:
    detector_class: cardboard_box
    size: [0.06, 0.06, 0.06]
"""

PLACES = {"tool_shelf": Pose2D(1.5, 0.5, 0.0), "workbench": Pose2D(0.0, 1.2, math.pi / 2), "home": Pose2D()}
CLASSES = ("screwdriver", "tape", "cardboard_box", "plier")


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "items.yaml"
    path.write_text(text)
    return path


def test_load_good_catalogue(tmp_path: Path) -> None:
    cat = load_catalogue(_write(tmp_path, GOOD), places=PLACES, classes=CLASSES)
    assert list(cat.items) == ["screwdriver", "tape", "box"]
    assert cat.item("screwdriver") == CatalogueItem("screwdriver", "screwdriver", ("tool_shelf", "workbench"),
                                                    (0.20, 0.03, 0.03), True)
    # defaults: the detector class is the item's name; not dangerous; no likely places
    assert cat.item("tape") == CatalogueItem("tape", "tape", ("workbench",), (0.10, 0.10, 0.05), False)
    assert cat.item("box").places == () and cat.item("box").detector_class == "cardboard_box"
    assert cat.classes() == {"screwdriver", "tape", "cardboard_box"}


def test_unknown_item_has_a_hint(tmp_path: Path) -> None:
    cat = load_catalogue(_write(tmp_path, GOOD))
    with pytest.raises(UnknownItem, match=r"no item 'screwdirver' in the catalogue .*items.yaml; did you mean "
                                          r"'screwdriver'\?"):
        cat.item("screwdirver")
    with pytest.raises(UnknownItem, match=r"no item 'hammer' .* \(known: box, screwdriver, tape\)"):
        cat.item("hammer")


def _problems(tmp_path: Path, text: str, **kw: object) -> list[str]:
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as e:
        load_catalogue(path, **kw)  # type: ignore[arg-type]
    return [str(p).replace(str(path), "F") for p in e.value.problems]


def test_every_problem_located_together(tmp_path: Path) -> None:
    text = """\
items:
  screwdriver:
    detector_class: screwdriverr
    places: [tool_shelff, workbench, workbench]
    size: [0.20, -0.03, .nan]
    dangerous: yes please
  tape:
    place: [workbench]
    size: [0.1, 0.1]
  pen:
    places: [workbench]
"""
    assert _problems(tmp_path, text, places=PLACES, classes=CLASSES) == [
        ("F:3:21: items.screwdriver.detector_class: the detector has no class 'screwdriverr'; did you mean "
        "'screwdriver'?"),
        "F:4:14: items.screwdriver.places[0]: unknown place 'tool_shelff'; did you mean 'tool_shelf'?",
        "F:4:38: items.screwdriver.places[2]: place 'workbench' listed twice",
        "F:5:18: items.screwdriver.size[1]: expected > 0 m, got -0.03",
        "F:5:25: items.screwdriver.size[2]: expected a finite number, got .nan",
        "F:6:16: items.screwdriver.dangerous: expected true or false, got 'yes please'",
        "F:8:5: items.tape.place: unknown key; did you mean 'places'?",
        "F:9:11: items.tape.size: expected a list of 3 numbers, got 2 items",
        ("F:10:3: items.pen.detector_class (the item's name): the detector has no class 'pen' "
        "(its classes: cardboard_box, plier, screwdriver, tape)"),
        "F:11:5: items.pen.size: missing required key (expected a list of 3 numbers)",
    ]


def test_unknown_place_without_a_close_name_lists_the_known(tmp_path: Path) -> None:
    text = "items:\n  tape:\n    places: [kitchen]\n    size: [0.1, 0.1, 0.05]\n"
    assert _problems(tmp_path, text, places=PLACES) == [
        "F:3:14: items.tape.places[0]: unknown place 'kitchen' (known: home, tool_shelf, workbench)"]


@pytest.mark.parametrize(("text", "expected"), [
    ("", ["F:1:1: items: missing required key (expected a mapping)"]),
    ("items: {}\n", ["F:1:8: items: the catalogue lists no item"]),
    ("- tape\n", ["F:1:1: expected a mapping, got ['tape']"]),
    ("items:\n  tape: 3\n", ["F:2:9: items.tape: expected a mapping, got 3"]),
    ("itmes:\n  tape: {size: [1, 1, 1]}\n", ["F:1:1: itmes: unknown key; did you mean 'items'?",
                                            "F:1:1: items: missing required key (expected a mapping)"]),
    ("items:\n  tape: {size: [1, 1, 1]}\n  tape: {size: [1, 1, 1]}\n",
     ["F:3:3: duplicate key 'tape' (first at line 2)"]),
])
def test_malformed_files(tmp_path: Path, text: str, expected: list[str]) -> None:
    assert _problems(tmp_path, text) == expected


def test_not_a_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        load_catalogue(tmp_path / "missing.yaml")


# --------------------------------------------------------------------------- search order

LOCATIONS = [Pose2D(3.0, 2.0, 0.0), Pose2D(1.52, 0.49, 0.05), Pose2D(1.5, 0.5, math.pi), Pose2D(0.0, 1.2, -1.5)]


def test_likely_places_first_then_general_locations() -> None:
    item = CatalogueItem("screwdriver", "screwdriver", ("workbench", "tool_shelf"), (0.2, 0.03, 0.03), True)
    stops = search_order(item, PLACES, LOCATIONS)
    assert stops == (
        SearchStop("workbench", PLACES["workbench"], True),
        SearchStop("tool_shelf", PLACES["tool_shelf"], True),
        SearchStop("search_locations[0]", LOCATIONS[0], False),
        # [1] is the tool shelf again (2 cm, 3 degrees off): not searched twice
        SearchStop("search_locations[2]", LOCATIONS[2], False),  # same spot, facing the other way
        SearchStop("search_locations[3]", LOCATIONS[3], False),  # the workbench spot turned by 3.07 rad
    )


def test_item_without_places_searches_the_general_locations() -> None:
    item = CatalogueItem("box", "box", (), (0.06, 0.06, 0.06), False)
    assert [s.name for s in search_order(item, PLACES, LOCATIONS)] == [f"search_locations[{i}]" for i in range(4)]
    # two general locations at one spot are searched once
    twice = [Pose2D(1.0, 1.0, 0.0), Pose2D(1.0, 1.0, math.tau)]
    assert [s.name for s in search_order(item, PLACES, twice)] == ["search_locations[0]"]


def test_missing_place_is_a_clear_error() -> None:
    item = CatalogueItem("tape", "tape", ("workbnch",), (0.1, 0.1, 0.05), False)
    with pytest.raises(ValueError, match=r"item 'tape': no place named 'workbnch'; did you mean 'workbench'\?"):
        search_order(item, PLACES, LOCATIONS)


def test_grasp_mode_per_item(tmp_path: Path) -> None:
    text = GOOD.replace("    dangerous: true\n", "    dangerous: true\n    grasp: top\n")
    cat = load_catalogue(_write(tmp_path, text), places=PLACES, classes=CLASSES)
    assert cat.item("screwdriver").grasp == "top"
    assert cat.item("tape").grasp is None  # the robot profile's default
    bad = GOOD.replace("    dangerous: true\n", "    dangerous: true\n    grasp: sideways\n")
    with pytest.raises(InputError) as e:
        load_catalogue(_write(tmp_path, bad), places=PLACES, classes=CLASSES)
    assert "items.screwdriver.grasp" in str(e.value) and "sideways" in str(e.value)
