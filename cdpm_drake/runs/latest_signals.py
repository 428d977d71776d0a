"""The latest tick's logged signals while a run goes: what a live view draws (the CLI hands
`latest_signals` to views/meshcat_view.py's live_view_callback, so that the view never reads
the diagram's blocks or the plant itself).

A key is read from a logger of its own (a system named `log_<key>`) where the diagram has one,
else from the block output port that logs it (diagram.logged_source: a real-time run has no
loggers in memory); the dynamic plant's ground truth (p_true, rpy_true, slack) from the
plant's last logged row. Values in the units of docs/LOG_FORMAT.md.
"""

from cdpm_drake.diagram import logged_source
from cdpm_drake.systems.plants.dynamic_plant import latest_ground_truth

# The keys the dynamic plant logs inside itself (its ground truth), not on a port.
TRUTH_KEYS = ("p_true", "rpy_true", "slack")


def latest_signals(diagram, context, keys) -> dict:
    """{key: its value at the latest tick (width,)} for each of `keys` that the diagram
    (built by diagram.build_diagram) logs at `context`; a key it does not log, a logger
    without a row yet and the ground truth of a plant that has none are left out."""
    row = {}
    truth = None
    for key in keys:
        name = f"log_{key}"
        if diagram.HasSubsystemNamed(name):  # a logger of its own
            data = diagram.GetSubsystemByName(name).FindLog(context).data()
            if data.shape[1]:
                row[key] = data[:, -1]
            continue
        if key in TRUTH_KEYS:  # the dynamic plant's, logged inside it
            if truth is None:
                truth = latest_ground_truth(diagram, context) or {}
            if key in truth:
                row[key] = truth[key]
            continue
        port = logged_source(diagram, key)
        if port is not None:
            row[key] = port.Eval(port.get_system().GetMyContextFromRoot(context))
    return row
