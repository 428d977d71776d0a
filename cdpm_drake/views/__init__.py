"""Views of a run: plots of the paper's figures (plots.py, drawn by the figures_*.py modules),
a Meshcat 3D view and HTML replay (meshcat_view.py), the controller diagram as graphviz
(diagram_graph.py). Logs are read through runs/log.py.

Nothing is imported here, so importing one view does not pull in matplotlib or Meshcat.
Views only read logs and signals; they never feed back into the control blocks.
"""
