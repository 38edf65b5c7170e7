"""Training: what the algorithms load, built offline by rendering, with its caches.

* :mod:`lab.training.databases`: an object's 3D SIFT feature database and colour model from its
  training ring (``lab train``); the identification boxes and the lab room's objects.
* :mod:`lab.training.tables`: the identification planner's probability lookup tables (Table I;
  ``lab tables``).
* :mod:`lab.training.search`: the search's databases, trained from the viewpoints the search robot
  sees its objects from.

Each ``get_*`` function returns what is in the versioned per-user cache (``~/.cache/lab`` or
``$LAB_CACHE``), building it first when it is missing, stale or corrupt, and saying so on stderr.
:mod:`lab.training.cache` holds their one rule for building: under a lock file beside the cached file,
so that processes on one cold cache build each file once. The algorithm packages never call these: a
run loads what they need and hands it to them.
"""

from lab.training.databases import (
    TrainingParams,
    database_path,
    get_database,
    get_databases,
    train_database,
    trainable_objects,
)
from lab.training.search import SEARCH_TRAINING, search_database
from lab.training.tables import (
    TableParams,
    box_model_names,
    build_model_tables,
    get_model_tables,
    get_tables,
    load_tables,
    tables_path,
)

__all__ = [
    "SEARCH_TRAINING",
    "TableParams",
    "TrainingParams",
    "box_model_names",
    "build_model_tables",
    "database_path",
    "get_database",
    "get_databases",
    "get_model_tables",
    "get_tables",
    "load_tables",
    "search_database",
    "tables_path",
    "train_database",
    "trainable_objects",
]
