"""What the vehicles do beyond the formation law, each selected by a scenario section.

- :mod:`~sandbox.behaviour.recovery`: the recovery strategies of section 4
  (``recovery:``) and the tangential term;
- :mod:`~sandbox.behaviour.safety`: safety filters on the commands (``safety:``);
- :mod:`~sandbox.behaviour.detection`: failure detection without an oracle
  (``detection:``);
- :mod:`~sandbox.behaviour.reconfigure`: slot reassignment and leader handover
  (``reconfigure:``);
- :mod:`~sandbox.behaviour.sensing`: what the vehicles see of each other (``sensing:``).
"""
