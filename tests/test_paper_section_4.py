"""Section 4 of the report, Figs. 12-17, measured on ``scenarios/paper/fig1*.yaml``.

Every figure's variants share one set of initial conditions (see the files' headers),
chosen so that the report's ideal kinematics (eq. (1) exactly, no limits, no contacts:
:func:`sandbox.study.ideal.ideal_encounters`) and this product agree that forming
without recovery collides: one encounter (red cuts through the leader) in the ideal
model, on the limited robot and on the unlimited one. Each test states the report's
claim and asserts what is measured; counts are contact episodes (encounters).

- Limited robot (the files: v1 <= 2 m/s, |chi'| <= 5 m/s^2, v2 <= 8 rad/s): beta = 1
  avoids the encounter with the discontinuous approach but not with the continuous one;
  larger beta is rougher and slower; an avoiding leader slows the platoon and costs
  effort; no setting destabilizes it (Figs. 14 right and 16 right do not reproduce).
- Unlimited robot (the report's idealization, with a motor that follows every command):
  beta = 1 does not avoid the encounter (neither in the ideal model), beta = 5 costs
  twice the effort of beta = 2.5, the continuous approach halves the effort at beta = 5,
  the avoiding leader multiplies it; everything converges.

Runs are cut to 10 s (every variant settles within 6.2 s; after that the commands are
constant).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import pytest

from sandbox import load_scenario, simulate
from sandbox.run.metrics import compute_metrics
from sandbox.study.ideal import ideal_encounters

#: Every test of this module takes seconds: the full suite only (not in -m "not slow").
pytestmark = pytest.mark.slow

PAPER = Path(__file__).resolve().parent.parent / "scenarios" / "paper"
#: The report's idealization: vehicles without speed, acceleration or turn-rate limits.
UNBOUNDED = ("vehicle.v1_max=null", "vehicle.max_accel=null", "vehicle.v2_max=null")
DURATION = 10.0  # [s]
FILES = {
    "fig12": "fig12_no_recovery",
    "fig13": "fig13_discontinuous_beta1",
    "fig14_b2.5": "fig14_discontinuous_beta2_5",
    "fig14_b5": "fig14_discontinuous_beta5",
    "fig15_b1": "fig15_continuous_beta1",
    "fig15_b5": "fig15_continuous_beta5",
    "fig16_b1": "fig16_leader_avoids_discontinuous_beta1",
    "fig16_b2": "fig16_leader_avoids_discontinuous_beta2",
    "fig17": "fig17_leader_avoids_continuous_beta5",
}


@cache
def metrics(key: str, overrides: tuple[str, ...] = ()) -> dict:
    path = PAPER / f"{FILES[key]}.yaml"
    run = simulate(load_scenario(path, overrides=[f"duration={DURATION}", *overrides]))
    return compute_metrics(run)


def collisions(key: str, overrides: tuple[str, ...] = ()) -> int:
    return metrics(key, overrides)["collisions"]["total"]


def settling(key: str, overrides: tuple[str, ...] = ()) -> float:
    """Time by which every vehicle has reached its place for good [s]."""
    times = [v["settling_time"] for v in metrics(key, overrides)["vehicles"].values()]
    assert None not in times, times
    return max(times)


def effort(key: str, overrides: tuple[str, ...] = ()) -> float:
    """Control effort summed over the vehicles [m/s]."""
    vehicles = metrics(key, overrides)["vehicles"].values()
    return sum(v["control_effort"] for v in vehicles)


def switches(key: str, overrides: tuple[str, ...] = ()) -> int:
    return sum(v["mode_switches"] for v in metrics(key, overrides)["vehicles"].values())


def test_variants_share_the_initial_conditions():
    scenarios = [load_scenario(PAPER / f"{f}.yaml") for f in FILES.values()]
    first = scenarios[0]
    for sc in scenarios[1:]:
        assert sc.vehicles == first.vehicles
        assert (sc.reference, sc.formation, sc.duration, sc.dt) == (
            first.reference,
            first.formation,
            first.duration,
            first.dt,
        )
        assert sc.recovery.R == pytest.approx(3 * sc.diameter)
        if sc.recovery.strategy == "continuous":
            assert sc.recovery.r == pytest.approx(sc.recovery.R / 2)


def ideal(key: str) -> int:
    """Encounters of a variant in the report's ideal kinematics (unlimited)."""
    sc = load_scenario(PAPER / f"{FILES[key]}.yaml", overrides=list(UNBOUNDED))
    return ideal_encounters(sc)[0]


def test_fig12_without_recovery_the_ideal_model_and_the_product_agree():
    # Report: collisions before the formation is reached (two). Measured: one encounter
    # of red with the leader, in the ideal model, on the limited and the unlimited
    # robot; the platoon then forms.
    assert ideal("fig12") == 1
    assert collisions("fig12") == collisions("fig12", UNBOUNDED) == 1
    events = metrics("fig12")["collisions"]["events"]
    assert [(e["a"], e["b"]) for e in events] == [("leader", "red")]
    assert metrics("fig12")["converged"] is True


def test_fig13_discontinuous_beta1_avoids_only_on_the_limited_robot():
    # Report: no collision. Measured: the limited robot avoids it (closest 0.502 m);
    # unlimited, and in the ideal model, red still goes through the leader.
    assert collisions("fig13") == 0
    assert metrics("fig13")["min_distance"] > 0.5
    assert collisions("fig13", UNBOUNDED) == 1 and ideal("fig13") == 1
    assert metrics("fig13")["converged"] is True


def test_fig14_larger_beta_is_rougher():
    # Report: beta = 2.5 gives less smooth paths than beta = 1. Measured: more control
    # effort and a later settling, no contact (none in the ideal model either).
    assert collisions("fig14_b2.5") == 0 and ideal("fig14_b2.5") == 0
    assert effort("fig13") < effort("fig14_b2.5") < effort("fig14_b5")
    assert settling("fig13") < settling("fig14_b2.5") < settling("fig14_b5")


def test_fig14_beta5_does_not_destabilize_a_follower():
    # Report: beta = 5 destabilizes the red follower. Measured: rougher, but every
    # follower settles, bounded (about 5.5 s) or not (about 1.5 s, twice the effort of
    # beta = 2.5).
    m = metrics("fig14_b5")
    assert m["converged"] is True and settling("fig14_b5") < 7.0
    assert metrics("fig14_b5", UNBOUNDED)["converged"] is True
    assert effort("fig14_b5", UNBOUNDED) > 1.5 * effort("fig14_b2.5", UNBOUNDED)
    assert collisions("fig14_b5") == collisions("fig14_b5", UNBOUNDED) == 0


def test_fig15_continuous_beta5_is_stable_and_smoother_only_without_limits():
    # Report: smoother than the discontinuous approach, and stable with beta = 5.
    # Measured: stable (converges) on both robots; unlimited, half the effort of the
    # discontinuous approach; limited, the same effort, a later settling and one
    # encounter left.
    assert metrics("fig15_b5")["converged"] is True
    assert metrics("fig15_b5", UNBOUNDED)["converged"] is True
    assert effort("fig15_b5", UNBOUNDED) < 0.6 * effort("fig14_b5", UNBOUNDED)
    assert effort("fig15_b5") == pytest.approx(effort("fig14_b5"), rel=0.05)
    assert collisions("fig15_b5") == 1 and collisions("fig15_b5", UNBOUNDED) == 0


def test_fig15_continuous_beta1_does_not_avoid_the_encounter():
    # Report: collisions still avoided at beta = 1. Measured: alpha <= 1 only weakens
    # an already too weak push: the encounter happens on both robots and in the ideal
    # model.
    assert collisions("fig15_b1") == collisions("fig15_b1", UNBOUNDED) == 1
    assert ideal("fig15_b1") == 1


def test_fig16_an_avoiding_leader_makes_the_platoon_slower_and_costlier():
    # Report: with beta = 1 more time and control effort than with a leader that does
    # not avoid. Measured: yes, on both robots; the leader itself is pushed off.
    assert settling("fig16_b1") > 1.4 * settling("fig13")
    assert effort("fig16_b1") > 1.8 * effort("fig13")
    assert metrics("fig16_b1")["vehicles"]["leader"]["mode_switches"] > 0
    assert settling("fig16_b1", UNBOUNDED) > 2 * settling("fig13", UNBOUNDED)
    assert effort("fig16_b1", UNBOUNDED) > 5 * effort("fig13", UNBOUNDED)


def test_fig16_beta2_still_converges():
    # Report: with beta = 2 the platoon no longer converges. Measured: slower again
    # than beta = 1, but it converges within the run, bounded or not.
    assert settling("fig16_b2") > settling("fig16_b1")
    assert metrics("fig16_b2")["converged"] is True
    assert settling("fig16_b2", UNBOUNDED) > settling("fig16_b1", UNBOUNDED)
    assert metrics("fig16_b2", UNBOUNDED)["converged"] is True


def test_fig17_all_continuous_beta5_converges():
    # Report: the platoon still stabilizes. Measured: yes, without any contact.
    m = metrics("fig17")
    assert m["converged"] is True
    assert collisions("fig17") == collisions("fig17", UNBOUNDED) == 0
    assert metrics("fig17", UNBOUNDED)["converged"] is True
