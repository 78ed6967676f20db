"""Node runtime (attach, step, detach) and the node implementations."""
