"""The simulation loop: its state, its stages, and what it hands out.

- :mod:`~sandbox.loop.simulation`: :class:`~sandbox.loop.simulation.Simulation`, the
  fixed-step loop (sense, plan, act, record, advance) and its step-wise API;
- :mod:`~sandbox.loop.state`: the struct-of-arrays fleet state;
- :mod:`~sandbox.loop.observation`: what the step API shows and accepts;
- :mod:`~sandbox.loop.divergence`: the check that ends a run whose state no physics
  can mean;
- :mod:`~sandbox.loop.run_info`: what a run records of its scenario.
"""
