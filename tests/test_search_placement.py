"""Valid placements of the searched object: seeded random spots on the floor, tables and shelf, and
clear refusals of spots inside walls, furniture or mid-air (checked against the scene's geometry)."""

import math

import numpy as np
import pytest

from lab.errors import ConfigError
from lab.runs.placement import (
    SURFACES,
    check_placement,
    footprint,
    polygon_inside,
    polygons_overlap,
    random_placement,
    searchable_objects,
    supports,
)
from lab.scene import load_scene

SCENE = load_scene("lab_room")


def test_searchable_objects_are_the_scenes_objects():
    assert searchable_objects() == ["cereal_box", "book", "toy_block", "glossy_cup"]


@pytest.mark.parametrize("name", ["cereal_box", "book", "toy_block", "glossy_cup"])
def test_random_placements_are_valid_and_seeded(name):
    tops = {s.name: s for s in supports(SCENE)}
    for seed in range(8):
        for surface in SURFACES:
            place = random_placement(SCENE, name, np.random.default_rng(seed), surface)
            assert place == random_placement(SCENE, name, np.random.default_rng(seed), surface)
            sup = check_placement(SCENE, name, place)
            assert sup.kind == surface and abs(place[2] - sup.z) < 1e-9
            fp = footprint(SCENE.body(name), pose=place)
            assert polygon_inside(fp, tops[sup.name].polygon)  # wholly on its surface
            if surface == "floor":
                rx, ry, _ = SCENE.robot_start
                assert math.hypot(place[0] - rx, place[1] - ry) >= 1.0
                for b in SCENE.bodies:
                    if b.name != name and b.role != "decor":
                        assert not polygons_overlap(fp, footprint(b, 0.3)), b.name


def test_random_surface_covers_all_three_heights():
    kinds = {
        check_placement(SCENE, "book", random_placement(SCENE, "book", np.random.default_rng(s))).kind
        for s in range(12)
    }
    assert kinds == set(SURFACES)


@pytest.mark.parametrize(
    "place, match",
    [
        ((3.5, 0.0, 0.0, 0.0), "outside the room or inside a wall"),
        ((0.0, 3.99, 0.0, 45.0), "outside the room or inside a wall"),
        ((1.9, 2.6, 0.0, 0.0), "under or inside table_a"),
        ((0.9, -0.8, 0.0, 0.0), "overlaps crate"),
        ((0.9, -0.8, 0.5, 0.0), "does not stand on anything"),
        ((2.48, 2.6, 0.75, 0.0), "does not stand on anything"),  # hangs over the table's edge
        ((-2.6, 2.9, 1.2, 0.0), "overlaps book"),  # the book's own spot, for the cereal box
        ((0.1, -2.9, 0.0, 0.0), "robot's start"),
        ((0.0, 0.0, float("nan"), 0.0), "finite"),
        ((0.0, 0.0, 0.0), "4 numbers"),
    ],
)
def test_bad_placements_are_refused_with_the_reason(place, match):
    with pytest.raises(ConfigError, match=match):
        check_placement(SCENE, "cereal_box", place)


def test_unknown_object_lists_the_names():
    with pytest.raises(ConfigError, match="searchable objects: cereal_box, book, toy_block, glossy_cup"):
        check_placement(SCENE, "fire_extinguisher", (0.0, 0.0, 0.0, 0.0))
