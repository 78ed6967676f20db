"""The relay server: node registry, macro-step barrier, hybrid coordinator, routing, recording."""
