"""The model of the report: pure functions of arrays, no physics, no drawing.

- :mod:`~sandbox.model.dynamics`: the unicycle, eq. (1), and the angle helper;
- :mod:`~sandbox.model.flatness`: the flatness-based controller, eqs. (4)-(6);
- :mod:`~sandbox.model.laws`: the formation laws of sections 3.2-3.5, eqs. (7)-(20);
- :mod:`~sandbox.model.references`, :mod:`~sandbox.model.obstacles`,
  :mod:`~sandbox.model.failures`: the reference paths, obstacle shapes and failure
  kinds a scenario selects by name (each registers into :mod:`sandbox.plugins`);
- :mod:`~sandbox.model.obstacle_field`: the obstacles as geometry for distance queries;
- :mod:`~sandbox.model.tunnelling`: how far a vehicle can move in one physics substep.
"""
