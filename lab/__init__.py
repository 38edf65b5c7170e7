"""lab: active stereo perception on a mobile robot, in PyBullet and on a real robot.

Modules follow the data flow of the two papers (see README.md and docs/conventions.md):
``geometry`` (SE(3), z-y-x Euler, frames), ``robot`` (the Robot interface), ``sim`` (PyBullet worlds
and the simulated robot), ``vision``, ``estimation``, ``identification``, ``search`` and ``hardware``.
"""

__version__ = "0.1.0"
