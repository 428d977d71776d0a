"""The 3D views a command opens: the Meshcat window that follows a run live, and the
self-contained HTML replay of a log (views hang off the command line, not the blocks)."""

import sys


def save_replay(log, path):
    """The self-contained HTML replay. The Meshcat server it records with is private to it, so
    Drake's "listening at http://..." line would only mislead: silenced."""
    import logging

    from cdpm_drake.views.meshcat_view import save_replay_html

    drake_log = logging.getLogger("drake")
    previous = drake_log.level
    drake_log.setLevel(logging.WARNING)
    try:
        return save_replay_html(log, path)
    finally:
        drake_log.setLevel(previous)


def live_meshcat(scenario):
    """A Meshcat window that follows the simulation (views hang off the CLI, not the blocks)."""
    from cdpm_drake.config import resolve_scenario
    from cdpm_drake.runs.latest_signals import latest_signals
    from cdpm_drake.views.meshcat_view import CdpmMeshcatView, live_view_callback, make_meshcat

    resolved = resolve_scenario(scenario)
    robot, params = resolved.robot, resolved.interference
    meshcat = make_meshcat()
    kwargs = {} if params is None else dict(d_l=params.d_l, d_u=params.d_u)
    view = CdpmMeshcatView(meshcat, robot.reels, robot.attachments, robot.workspace.lower,
                           robot.workspace.upper, robot.pairs, **kwargs)
    print(f"Meshcat: open {meshcat.web_url()} in a browser", file=sys.stderr)
    return live_view_callback(view, latest_signals)
