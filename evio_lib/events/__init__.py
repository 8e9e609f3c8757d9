"""Events: the event array layout, ESIM-style simulation, and (later) representations and reconstruction."""
