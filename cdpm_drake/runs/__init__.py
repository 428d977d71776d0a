"""Running the diagram: a simulation (simulate), a real-time run against the reels (realtime), many runs (sweep/), and the log format they all write (log)."""
