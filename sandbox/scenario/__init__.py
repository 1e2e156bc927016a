"""Scenario files: YAML -> validated, frozen dataclasses.

Everything a run needs is checked at load time, and every problem of a document is
reported at once as a :class:`~sandbox.errors.Problem` with the YAML line of the field
(``FILE:LINE: path.to.field: what is wrong (got X; expected Y)``). The simulation never
re-checks configuration.

Each key of the format is declared once, as a :class:`~sandbox.plugins.Param`, beside
the code that reads it: the sections in :mod:`.sections` and :mod:`.vehicles`, the keys
of a law, strategy, failure kind, reference or obstacle type in its plug-in's
registration. The reader, the JSON Schema and the documentation checks derive from
those declarations. The package:

- :mod:`.specs`: the frozen dataclasses (:class:`Scenario` and its sections);
- :mod:`.reader`: typed field access and the limits of the format;
- :mod:`.yamlfile`: bounded YAML reading, line numbers, duplicate keys;
- :mod:`.sections`, :mod:`.vehicles`: the declared sections and their readers;
- :mod:`.checks`: checks across sections;
- :mod:`.needs`: what a run will need (memory, disk), and the bounds that follow;
- :mod:`.inert`: keys that would do nothing, warned of;
- :mod:`.parse`: :func:`load_scenario`, :func:`parse_scenario`, ``--set``.

The format is documented key by key in ``scenarios/reference.yaml``. Lengths may be
written in metres (``0.75``) or as multiples of the default vehicle diameter (``"3d"``,
``1.5d``).
"""

from sandbox.model.obstacles import ObstacleSpec
from sandbox.scenario.checks import overlapping_pairs
from sandbox.scenario.parse import load_scenario, parse_scenario
from sandbox.scenario.platoons import PLATOONS, PLATOONS_KEYS
from sandbox.scenario.reader import (
    BAD_NAME,
    LENGTH,
    MAX_FILE_BYTES,
    MAX_LENGTH,
    MAX_NAME,
    MAX_NUMBER,
    MAX_RECORD_EVERY,
    MAX_SEED,
    MAX_STEPS,
    MAX_SUBSTEPS,
    MAX_VEHICLES,
    MIN_DIAMETER,
    MIN_MASS,
    MIN_POSITIVE,
    NAME_RULE,
    name_problem,
)
from sandbox.scenario.sections import (
    FAILURE,
    FORMATION,
    METRICS,
    OBSTACLE,
    PLUGIN_SECTIONS,
    RECONFIGURE,
    RECOVERY,
    REFERENCE,
    REPORT_DT_BOUND,
    SAFETY,
    SENSING,
    TOP,
    TOP_KEYS,
    read_param,
    read_params,
    read_plugin_section,
)
from sandbox.scenario.sensors import MAX_BEAMS, RANGE, SENSORS
from sandbox.scenario.specs import (
    DRIVE_TYPES,
    PALETTE,
    PLATOON_PATTERNS,
    DetectionSpec,
    DriveSpec,
    FailureSpec,
    FormationSpec,
    FunctionReference,
    MetricsSpec,
    PlatoonSpec,
    RangeSpec,
    ReconfigureSpec,
    RecoverySpec,
    ReferenceSpec,
    SafetySpec,
    Scenario,
    SensingSpec,
    SensorsSpec,
    VehicleSpec,
)
from sandbox.scenario.vehicles import (
    DRIVE,
    GAINS,
    PLATOON,
    VEHICLE,
    VEHICLE_KEYS,
    VEHICLE_PARAM_KEYS,
    VEHICLE_PARAMS,
    platoon_offsets,
)
from sandbox.scenario.yamlfile import YAMLLoader, duplicate_keys, line_map

__all__ = [
    "DRIVE",
    "DRIVE_TYPES",
    "FAILURE",
    "FORMATION",
    "GAINS",
    "MAX_FILE_BYTES",
    "MAX_LENGTH",
    "MAX_NAME",
    "MAX_NUMBER",
    "MAX_RECORD_EVERY",
    "MAX_SEED",
    "MAX_STEPS",
    "MAX_SUBSTEPS",
    "MAX_VEHICLES",
    "METRICS",
    "MIN_DIAMETER",
    "MIN_MASS",
    "MIN_POSITIVE",
    "NAME_RULE",
    "OBSTACLE",
    "PALETTE",
    "PLATOON",
    "PLATOONS",
    "PLATOONS_KEYS",
    "PLATOON_PATTERNS",
    "PLUGIN_SECTIONS",
    "RECOVERY",
    "REFERENCE",
    "REPORT_DT_BOUND",
    "TOP",
    "TOP_KEYS",
    "VEHICLE",
    "VEHICLE_KEYS",
    "VEHICLE_PARAMS",
    "VEHICLE_PARAM_KEYS",
    "DriveSpec",
    "FailureSpec",
    "FormationSpec",
    "FunctionReference",
    "MetricsSpec",
    "SensingSpec",
    "SensorsSpec",
    "RangeSpec",
    "SENSORS",
    "RANGE",
    "MAX_BEAMS",
    "DetectionSpec",
    "SENSING",
    "SafetySpec",
    "SAFETY",
    "RECONFIGURE",
    "ReconfigureSpec",
    "ObstacleSpec",
    "PlatoonSpec",
    "RecoverySpec",
    "ReferenceSpec",
    "Scenario",
    "VehicleSpec",
    "BAD_NAME",
    "LENGTH",
    "YAMLLoader",
    "duplicate_keys",
    "line_map",
    "overlapping_pairs",
    "load_scenario",
    "name_problem",
    "parse_scenario",
    "platoon_offsets",
    "read_param",
    "read_params",
    "read_plugin_section",
]
