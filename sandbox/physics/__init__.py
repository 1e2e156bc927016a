"""The physics: a pymunk world behind the interface the loop steps.

:class:`~sandbox.physics.interface.Physics` is what the loop needs of an engine;
:class:`~sandbox.physics.world.World` implements it with pymunk (vehicles driven through
velocity constraints, static obstacles, contacts counted by ``begin`` callbacks), and
:mod:`~sandbox.physics.stepping` steps many worlds with a few calls per substep. The
modules of this folder are the only ones that import pymunk.
"""

from sandbox.physics.interface import Physics

__all__ = ["Physics"]
