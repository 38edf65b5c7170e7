"""The search's object databases: the training phase of the search paper (Sec. III) for the lab room's
objects, with the viewpoints the search will see them from.

The default training ring (:class:`lab.training.TrainingParams`) looks at an object from 12 degrees above,
1 m away, as the identification robot sees its boxes. The search robot's camera (the lab room's
``[robot] mast_height``, 1.1 m) sees an object on the floor from about 50-60 degrees above at
local-search range (0.6-0.9 m), one on a table (0.75 m) from 10-30 degrees above and one on the shelf
(1.2 m) from about level. Four rings, at -35, 12, 35 and 55 degrees, 0.8 m from the object, every
15 degrees, cover those views (with the one ring, or without the 55 degree ring, the local search
matched a handful of features on the small lab-room objects seen from above and failed there).
(0.8 m because the training object's centre stands 0.49 m above the floor: a camera 1 m away at
-35 degrees would sit under the floor; at 0.8 m it is 3 cm above it.) One point seen from rings far
apart keeps several descriptors in the database: the search's matcher treats database features
within 1.5 cm of each other as one point (``alias_radius``, see
:func:`lab.search.local_search.make_matcher`).

These databases live in their own cache folder (``<cache>/search-databases``), so that they and
``lab train``'s default ones never overwrite each other. Building one takes about 30-40 s on first use.
"""

from __future__ import annotations

from lab.errors import ConfigError
from lab.paths import cache_dir
from lab.scene import load_scene
from lab.training.databases import TrainingParams, get_database
from lab.vision.database import FeatureDatabase

__all__ = ["SEARCH_TRAINING", "search_database"]

#: The search's training: four rings of viewpoints (below, level, above, steeply above), 0.8 m away,
#: every 15 degrees.
SEARCH_TRAINING = TrainingParams(radius=0.8, elevations_deg=(-35.0, 12.0, 35.0, 55.0), step_deg=15.0)


def search_database(name: str, progress: bool = False) -> FeatureDatabase:
    """The database (features and colour model) of the searchable object ``name``, trained with
    :data:`SEARCH_TRAINING` and cached; raises ConfigError for an unknown name (listing the names)."""
    names = load_scene("lab_room").names("object")
    if name not in names:
        raise ConfigError(f"unknown object {name!r}; searchable objects: {', '.join(names)}")
    return get_database(name, cache_dir() / "search-databases", SEARCH_TRAINING, progress=progress)
