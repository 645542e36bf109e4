"""Flight-control policies: the paper's baseline controller (and, later, trained agents)."""
