"""What a loaded scenario is warned about before a run (not errors): a d_u no translation
reaches, reels slower than the platform's speed limit, a hand force beyond the sensor's
range. Logged to the config package's logger, which a sweep collects."""

import logging

import numpy as np

from cdpm_drake.config.scenario import Sensor

# The package's logger, not this module's: records keep the name they had.
_log = logging.getLogger("cdpm_drake.config")


def warn_unreachable_d_u(robot, params):
    """A pair whose d_u is above the largest distance translation can give it keeps its force
    on everywhere: worth saying before a run, not an error (the paper's own numbers come close)."""
    from cdpm_drake.kernels.interference import translation_distance_bound

    bound = translation_distance_bound(robot)
    for (i, j), d_u, g in zip(robot.pairs, params.d_u, bound):
        if d_u >= g:
            _log.warning(
                "pair (%d,%d): d_u = %.1f mm is not below %.1f mm, the largest distance any "
                "platform translation gives these cables; its interference force never "
                "switches off", i, j, 1000 * d_u, 1000 * g)


def warn_reel_saturation(scenario, robot):
    """Each reel's speed is |u_i . v| <= |v| (J's rows are unit vectors): a platform speed limit
    above the reel speed limit lets the reels saturate, which slows the motion."""
    v_max = scenario.limits.max_velocity or robot.limits.max_velocity
    reel = getattr(scenario.plant, "max_reel_speed", None) or robot.limits.max_reel_speed
    if v_max > reel:
        # Each value says where it comes from: a left-out field takes the robot file's.
        v_from = ("limits.max_velocity" if scenario.limits.max_velocity else
                  "default: the robot file's limits.max_velocity")
        reel_from = ("plant.max_reel_speed" if getattr(scenario.plant, "max_reel_speed", None)
                     else "default: the robot file's limits.max_reel_speed")
        _log.warning("the platform speed limit %g m/s (%s) is above the reel speed limit %g "
                     "m/s (%s): fast motions will be slowed by the reels", v_max, v_from, reel,
                     reel_from)


def sensor_range_text(sensor: Sensor) -> str:
    """"axial 100 N, transverse 80 N": the sensor's range, for messages."""
    return f"axial {sensor.axial_range:g} N, transverse {sensor.transverse_range:g} N"


def warn_sensor_range(resolved) -> None:
    """Once, before a run: a hand force the operator will apply beyond the sensor's range is
    clipped by the sensor model (as the real FSE103 saturates), so the controller never sees
    it. A force table says where; a spring hand, its max_force."""
    from cdpm_drake.kernels.plant.operators import ForceProfile, SpringHand
    from cdpm_drake.kernels.force_sensor import beyond_range

    s = resolved.scenario.sensor
    op = resolved.operator
    if isinstance(op, ForceProfile):
        beyond = beyond_range(op.forces, s.axial_axis, s.axial_range, s.transverse_range)
        if beyond.any():
            k = int(np.argmax(beyond))
            _log.warning("%s: the hand force %s N is beyond the sensor's range (%s): the "
                         "controller sees it clipped (%d of the %d rows are beyond it; the "
                         "summary counts the clipped ticks)", op.rows[k], op.forces[k].tolist(),
                         sensor_range_text(s), int(beyond.sum()), len(beyond))
    elif isinstance(op, SpringHand) and op.F_max > min(s.axial_range, s.transverse_range):
        _log.warning("operator.max_force %g N is above the sensor's range (%s): a larger hand "
                     "force is clipped (the summary counts the clipped ticks)", op.F_max,
                     sensor_range_text(s))
