"""Views of a run: plots of the paper's figures (plots.py), a Meshcat 3D view and HTML replay
(meshcat_view.py), the controller diagram as graphviz (diagram_graph.py).

Nothing is imported here, so importing one view does not pull in matplotlib or Meshcat.
Views only read logs and signals; they never feed back into the control blocks.
"""
