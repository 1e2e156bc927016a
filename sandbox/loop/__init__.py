"""The simulation loop: K worlds of one structure at once, a single run a loop of one.

- :mod:`~sandbox.loop.simulation`: :class:`~sandbox.loop.simulation.Simulation`, the
  fixed-step loop (sense, plan, act, record, advance) and its step-wise API, the one
  face of the values below;
- its values, each changed by one module: :mod:`~sandbox.loop.layout` (the worlds
  and the clock, fixed at build), :mod:`~sandbox.loop.state` (the struct-of-arrays
  fleet), :mod:`~sandbox.loop.plan` (the plan of a period, and which runs may share
  a loop), :mod:`~sandbox.loop.liveness` (the worlds' liveness, statuses and
  descriptions), :mod:`~sandbox.loop.recording` and :mod:`~sandbox.loop.tally` (the
  record and the loop metrics);
- its stages, built by :mod:`~sandbox.loop.building`: :mod:`~sandbox.loop.formation`,
  :mod:`~sandbox.loop.perception`, :mod:`~sandbox.loop.detecting`,
  :mod:`~sandbox.loop.avoidance`, :mod:`~sandbox.loop.safety`,
  :mod:`~sandbox.loop.acting`;
- :mod:`~sandbox.loop.observation`: what the step API shows and accepts;
- :mod:`~sandbox.loop.divergence`: the check that ends a run whose state no physics
  can mean;
- :mod:`~sandbox.loop.run_info`: what a run records of its scenario.
"""
